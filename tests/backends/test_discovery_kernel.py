"""The compiled skill-chaining bookkeeping (backends/discovery.py) gives the torch path's bits."""

import doctest

import pytest
import torch

from skillchain_torch.backends import discovery as native_discovery
from skillchain_torch.backends.compiled_discovery import (
    CompiledExecutionTrace,
    CompiledRecentStates,
    CompiledSkillChaining,
    compiled_event_list,
    compiled_exclude_overlap,
    compiled_target_indicator,
)
from skillchain_torch.discovery import InitiationReading, RecentStates, SkillChaining
from skillchain_torch.discovery.skill_chaining import (
    ExecutionTrace,
    event_list,
    exclude_overlap,
    overlap_exclusion,
    target_indicator,
)
from skillchain_torch.options import OptionBank, OptionStatus

# Each test runs the compiled twin (backends/compiled_discovery.py) beside the torch path's
# class and compares: the twins are what backends.select.discovery_rules picks for a compiled
# agent.
needs_native = pytest.mark.skipif(
    not native_discovery.AVAILABLE,
    reason="the compiled bookkeeping was not built (no C compiler at install time)")


def test_doctest():
    assert doctest.testmod(native_discovery).failed == 0


def random_bank(P, K, E, seed) -> OptionBank:
    """A bank with random trees: empty, base-event and chained slots of every status."""
    g = torch.Generator().manual_seed(seed)
    bank = OptionBank.build(P, K, order=1, capacity=8)
    bank.status.copy_(torch.randint(0, 4, (P, K), generator=g))
    bank.target_event.copy_(torch.randint(-1, E + 1, (P, K), generator=g))  # E: past the list
    chained = torch.rand(P, K, generator=g) < 0.4
    bank.parent.copy_(torch.where(chained, torch.randint(0, K, (P, K), generator=g), -1))
    bank.classifier.trained.copy_(torch.rand(P, K, generator=g) < 0.7)
    return bank


def flags(shape, seed, p=0.5):
    return torch.rand(shape, generator=torch.Generator().manual_seed(seed)) < p


@needs_native
@pytest.mark.parametrize("E", [0, 1, 3])
def test_target_indicator_event_list_and_overlap_equal_torch(E):
    bank = random_bank(50, 6, E, seed=E)
    base, contains = flags((50, E), 1), flags((50, 6), 2)
    exclusion = overlap_exclusion(bank)
    got = (compiled_target_indicator(bank, base, contains),
           compiled_exclude_overlap(contains, exclusion, bank.classifier.trained),
           *compiled_event_list(bank, E, max_branching=2))
    expected = (target_indicator(bank, base, contains),
                exclude_overlap(contains, exclusion, bank.classifier.trained),
                *event_list(bank, E, max_branching=2))
    for a, b in zip(got, expected):
        assert torch.equal(a, b)
    assert bool(expected[0].any()) and bool((contains & ~expected[1]).any())  # exercised
    assert bool(expected[3].any()) and not bool(expected[3].all())  # listed and full slots


@needs_native
def test_record_equals_torch():
    head = OptionBank.build(20, 2, order=1).q_head
    traces = [CompiledExecutionTrace(20, 7, head), ExecutionTrace(20, 7, head)]
    g = torch.Generator().manual_seed(3)
    for t in range(12):
        rows, step = flags(20, t), torch.randint(0, 10, (20,), generator=g)  # past T too
        obs = torch.rand(20, 4, dtype=torch.float64, generator=g)
        for trace in traces:
            trace.record(rows, step, obs)
    assert torch.equal(traces[0].states, traces[1].states)
    assert bool((traces[0].states != 0).any())


@needs_native
def test_recent_states_ring_equals_torch():
    rings = [CompiledRecentStates(20, 3), RecentStates(20, 3)]
    g = torch.Generator().manual_seed(4)
    for t in range(11):  # past the ring's length, with episode restarts between
        rows, restart = flags(20, t), flags(20, 100 + t, p=0.1)
        obs = torch.rand(20, 4, dtype=torch.float64, generator=g)
        for ring in rings:
            ring.record(rows, obs)
            ring.start_episodes(restart)
    assert torch.equal(rings[0].states, rings[1].states)
    assert torch.equal(rings[0].steps, rings[1].steps) and int(rings[0].steps.max()) > 3
    assert all(torch.equal(a, b) for a, b in zip(rings[0].window(flags(20, 7), 3),
                                                 rings[1].window(flags(20, 7), 3)))


@needs_native
@pytest.mark.parametrize("head_kind", ["fourier", "mlp"])
def test_snapshots_and_dropped_updates_equal_torch(head_kind):
    """ExecutionTrace.start keeps, and drop_updates puts back, the same weights either way."""
    from skillchain_torch.options import MLPOptionQHead

    P, K = 12, 3
    g = torch.Generator().manual_seed(5)
    heads, traces = [], []
    for trace_class in (CompiledExecutionTrace, ExecutionTrace):
        head = (OptionBank.build(P, K, order=1).q_head if head_kind == "fourier"
                else MLPOptionQHead(P, K, hidden=4, layers=1, seed=0))  # fmt: skip
        for t in head.slot_tensors().values():
            t.copy_(torch.rand(t.shape, dtype=t.dtype, generator=torch.Generator().manual_seed(1)))
        heads.append(head)
        traces.append(trace_class(P, 5, head))
    for t in range(6):
        rows, failure = flags(P, 10 + t), flags(P, 20 + t, p=0.3)
        slot = torch.randint(-1, K, (P,), generator=g)  # -1: reads slot 0, as torch does
        noise = torch.rand(heads[0].slot_tensors()[next(iter(heads[0].slot_tensors()))].shape,
                           dtype=torch.float64, generator=g)
        for head, trace in zip(heads, traces):
            trace.start(rows, slot)
            next(iter(head.slot_tensors().values())).add_(noise)  # the execution's updates
            trace.drop_updates(slot.clamp(min=0), failure)
    for name in traces[0].snapshot:
        assert torch.equal(traces[0].snapshot[name], traces[1].snapshot[name])
    for a, b in zip(heads[0].slot_tensors().values(), heads[1].slot_tensors().values()):
        assert torch.equal(a, b)
    assert bool((traces[0].snapshot[name] != 0).any())
    # A copy really happened: compiled, the put-back slots equal their snapshots.
    rows = torch.ones(P, dtype=torch.bool)
    slot = torch.zeros(P, dtype=torch.int64)
    traces[0].start(rows, slot)
    for t in heads[0].slot_tensors().values():
        t.mul_(2.0)
    traces[0].drop_updates(slot, rows)
    for name, t in heads[0].slot_tensors().items():
        assert torch.equal(t[:, 0], traces[0].snapshot[name])


@needs_native
@pytest.mark.parametrize(("positives", "full_logged"), [(0, False), (3, False), (0, True)])
def test_after_transition_equals_torch(positives, full_logged):
    """Triggers, gestation samples and base events of a step, with the same creations (and
    with a reading's gestation positives, the same examples)."""
    P, K = 40, 5
    results = []
    for rules in (CompiledSkillChaining, SkillChaining):
        bank = random_bank(P, K, 1, seed=9)
        bank.status[:, -1] = int(OptionStatus.EMPTY)  # room to create
        sc = rules(bank, max_option_steps=5,
                   reading=InitiationReading(gestation_positives=positives))
        if full_logged:  # every other agent's slots are full and logged: it creates nothing
            bank.status[::2, -1] = int(OptionStatus.LEARNING)
            sc.slots_full_logged[::2] = True
        if positives:  # a few states of this episode behind each agent
            for t in range(4):
                sc.recent.record(torch.ones(P, dtype=torch.bool),
                                 torch.full((P, 4), 0.1 * t, dtype=torch.float64))
        sc.base_now = flags((P, 1), 4, 0.2)
        sc.raw_now, sc.last_raw = flags((P, K), 7), flags((P, K), 8)  # own sets at s, s'
        sc.gestation_q = torch.randn(P, K, dtype=torch.float64,
                                     generator=torch.Generator().manual_seed(6))
        no = torch.zeros(P, dtype=torch.bool)
        created = sc.after_transition(
            obs=torch.full((P, 4), 0.5, dtype=torch.float64), executing=no,
            step=torch.zeros(P, dtype=torch.int64), events=flags((P, 1), 5, 0.3),
            contains=flags((P, K), 7), option=torch.full((P,), -1), value=torch.linspace(
                -1, 1, P, dtype=torch.float64),
            reached=flags((P, K), 10), duration=torch.ones(P, dtype=torch.int64),
            decision_ended=flags(P, 11), terminated=flags(P, 12, 0.1), stepped=flags(P, 13, 0.8))
        clf = bank.classifier
        results.append((created, sc.gestation_q, sc.base_now, bank.status.clone(),
                        bank.parent.clone(), bank.target_event.clone(), clf.count.clone(),
                        clf.examples.clone(), clf.labels.clone()))
    for a, b in zip(*results):
        assert torch.equal(a, b)
    assert bool(results[0][0].any())  # options were created
    if positives:  # gestating options' targets were hit: their positives were stored
        assert int(results[0][6].sum()) > 3 * int(results[0][0].sum())
    assert not torch.equal(results[0][1], torch.randn(P, K, dtype=torch.float64,
                                                      generator=torch.Generator().manual_seed(6)))


@needs_native
def test_triggers_report_only_events_on_the_list():
    """A base event firing after its branching limit is not on the list: nothing can be
    created, so the step skips creation; the same event with room left is reported."""
    P, K = 2, 4
    bank = OptionBank.build(P, K, order=1, capacity=8)
    bank.status[0, :3] = int(OptionStatus.LEARNING)  # agent 0: three options target the goal
    bank.target_event[0, :3] = 0
    zeros, goal = torch.zeros(P, 1, dtype=torch.bool), torch.ones(P, 1, dtype=torch.bool)
    no = torch.zeros(P, K, dtype=torch.bool)
    for stepped, expected in (([True, False], False), ([True, True], True)):
        *_, any_listed, _ = native_discovery.triggers(
            bank.parent, bank.target_event, bank.status, zeros, goal, no, no, no,
            torch.tensor(stepped), torch.zeros(P, dtype=torch.float64),
            torch.zeros(P, K, dtype=torch.float64), max_branching=3)  # fmt: skip
        assert any_listed is expected


@needs_native
@pytest.mark.parametrize("replacement", ["reservoir", "ring"])
def test_store_examples_compiled_equals_torch(replacement):
    """Examples of ended executions go straight from the trace into the compiled stores: the
    same stores as ExecutionTrace.examples + add_examples (capacity 6 overflows)."""
    P, K, T = 5, 3, 8
    g = torch.Generator().manual_seed(3)
    banks = [OptionBank.build(P, K, order=1, capacity=6, replacement=replacement)
             for _ in range(2)]  # fmt: skip
    banks[0].classifier.set_native(True)
    traces = [CompiledExecutionTrace(P, T, banks[0].q_head),
              ExecutionTrace(P, T, banks[1].q_head)]
    for _ in range(6):
        states = torch.rand(P, T, 4, dtype=torch.float64, generator=g)
        slot = torch.randint(0, K, (P,), generator=g)
        duration = torch.randint(1, T + 3, (P,), generator=g)
        success = torch.rand(P, generator=g) < 0.4
        failure = ~success & (torch.rand(P, generator=g) < 0.5)
        touched = []
        for bank, trace in zip(banks, traces):
            trace.states = states.clone()
            touched.append(trace.store_examples(bank.classifier, slot, duration, success,
                                                failure))  # fmt: skip
        assert torch.equal(*touched)
        for name in ("examples", "labels", "count", "seen", "dirty"):
            assert torch.equal(*(getattr(b.classifier, name) for b in banks)), name
    assert int(banks[0].classifier.seen.max()) > 6


@needs_native
def test_triggers_skip_agents_that_create_nothing_more():
    """An agent whose slots are all live and whose full slots are logged creates nothing, so
    its triggers do not call for a creation; full but not yet logged, or logged with a slot
    freed since, they do (as SkillChaining._create decides)."""
    K = 3
    zeros, goal = torch.zeros(1, 1, dtype=torch.bool), torch.ones(1, 1, dtype=torch.bool)
    no = torch.zeros(1, K, dtype=torch.bool)
    for free_slot, logged, expected in ((False, True, False), (False, False, True),
                                        (True, True, True)):  # fmt: skip
        bank = OptionBank.build(1, K, order=1, capacity=8)
        bank.status[0] = int(OptionStatus.LEARNING)
        bank.target_event[0] = -1  # none targets the goal: the goal is on the list
        if free_slot:
            bank.status[0, 2] = int(OptionStatus.EMPTY)
        *_, any_listed, _ = native_discovery.triggers(
            bank.parent, bank.target_event, bank.status, zeros, goal, no, no, no,
            torch.ones(1, dtype=torch.bool), torch.zeros(1, dtype=torch.float64),
            torch.zeros(1, K, dtype=torch.float64), max_branching=3,
            blocked=torch.tensor([logged]))  # fmt: skip
        assert any_listed is expected, (free_slot, logged)


@needs_native
def test_agents_that_create_nothing_more_never_reach_creation(monkeypatch):
    """Every agent full, its full slots logged, every one entering the goal: the compiled
    rules do not call _create at all (the torch rules call it and create nothing)."""
    P, K = 6, 3
    results = []
    for rules in (CompiledSkillChaining, SkillChaining):
        bank = random_bank(P, K, 1, seed=2)
        bank.status.fill_(int(OptionStatus.LEARNING))
        bank.target_event.fill_(-1)  # the goal is on every agent's list
        sc = rules(bank, max_option_steps=5)
        sc.slots_full_logged.fill_(True)
        sc.base_now = torch.zeros(P, 1, dtype=torch.bool)
        calls = []

        def counted(*args, calls=calls, original=sc._create):
            calls.append(1)
            return original(*args)

        monkeypatch.setattr(sc, "_create", counted)
        no, ones = torch.zeros(P, dtype=torch.bool), torch.ones(P, dtype=torch.bool)
        created = sc.after_transition(
            obs=torch.full((P, 4), 0.5, dtype=torch.float64), executing=no,
            step=torch.zeros(P, dtype=torch.int64), events=torch.ones(P, 1, dtype=torch.bool),
            contains=torch.zeros(P, K, dtype=torch.bool), option=torch.full((P,), -1),
            value=torch.zeros(P, dtype=torch.float64),
            reached=torch.zeros(P, K, dtype=torch.bool), duration=torch.ones(P, dtype=torch.int64),
            decision_ended=no, terminated=no, stepped=ones)  # fmt: skip
        results.append((len(calls), created, bank.status.clone()))
    assert results[0][0] == 0 and results[1][0] == 1
    assert torch.equal(results[0][1], results[1][1]) and not bool(results[0][1].any())
    assert torch.equal(results[0][2], results[1][2])
