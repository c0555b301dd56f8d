"""The readings of option execution the paper leaves open, each against updates computed by
hand: what a timed-out option bootstraps on (``failure_bootstrap``), primitives learning from
the options' steps (``intra_option_primitives``), interruption (``interruption``) and an
execution's end where it leaves its option's set (``end_outside_set``)."""

from __future__ import annotations

import pytest
import torch
from hand_built import F64, NO, make_agent, make_bank, obs, prefer_option

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.options import OptionStatus


@pytest.mark.parametrize("native", [False, True])
@pytest.mark.parametrize("rule", ["decision", "primitives"])
def test_timed_out_option_bootstraps_by_failure_bootstrap(rule, native):
    """A timeout's SMDP target: Q(s', d') (Sarsa) or the best primitive at s' ("primitives"),
    while a success (the option's target reached) bootstraps on d' under both rules."""
    if native and not HierarchicalAgent(make_bank(), order=1, native=None).native:
        pytest.skip("compiled agent kernels not built")
    agent = make_agent(make_bank(), failure_bootstrap=rule, max_option_steps=3, native=native)
    prefer_option(agent, value=100.0)  # the option is re-chosen at s' (d' = 5)
    agent.q_head.weight[:, 2, 0] = 7.0  # the best primitive: Q(s, 2) = 7 everywhere
    s = obs((0.7, 0.5, 0.5, 0.5))  # in the set, never at the target region
    agent.begin(s)
    yes = torch.tensor([True])
    for _ in range(2):
        agent.transition(s, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    w = agent.q_head.weight.clone()
    info = agent.transition(s, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    assert info["decision_ended"].tolist() == [True] and info["duration"].tolist() == [3]
    assert agent.decisions.tolist() == [5]  # d' is the option again
    q_sa = (w[0, 5] * agent.features(s)[0]).sum().item()
    boot = 100.0 if rule == "decision" else 7.0
    assert info["smdp_delta"].item() == pytest.approx(-3.0 + boot - q_sa, rel=1e-12)
    # a success bootstraps on d' whatever the rule
    agent2 = make_agent(make_bank(), failure_bootstrap=rule, native=native)
    prefer_option(agent2, value=100.0)
    agent2.q_head.weight[:, 2, 0] = 7.0
    agent2.begin(s)
    goal = obs((0.9, 0.2, 0.5, 0.5))  # in the set and at the target region
    w = agent2.q_head.weight.clone()
    info = agent2.transition(goal, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    q_sa = (w[0, 5] * agent2.features(s)[0]).sum().item()
    d_next = int(agent2.decision[0])
    q_next = (w[0, d_next] * agent2.features(goal)[0]).sum().item()
    assert d_next == 5
    assert info["smdp_delta"].item() == pytest.approx(-1.0 + q_next - q_sa, rel=1e-12)


def test_failure_bootstrap_is_checked():
    with pytest.raises(ValueError, match="failure_bootstrap must be one of"):
        make_agent(make_bank(), failure_bootstrap="optimistic")


@pytest.mark.parametrize("native", [False, True])
@pytest.mark.parametrize("intra", [False, True])
def test_intra_option_primitives_learn_the_options_steps(intra, native):
    """With ``intra_option_primitives`` each step an option takes moves the top level's
    Q(s, a) of that primitive toward r + max over the decisions available at s' (the option
    where s' is in its set, the primitives only where it is not, nothing at a termination);
    without it the primitives' values learn nothing while the option runs."""
    if native and not HierarchicalAgent(make_bank(), order=1, native=None).native:
        pytest.skip("compiled agent kernels not built")
    agent = make_agent(make_bank(), intra_option_primitives=intra, native=native)
    prefer_option(agent, value=100.0)
    agent.q_head.weight[:, 2, 0] = 7.0  # the best primitive: 7 everywhere
    agent.q_head.weight[:, 1, 1] = -3.0  # and one that varies with s
    s = obs((0.7, 0.5, 0.5, 0.5))
    agent.begin(s)
    yes = torch.tensor([True])
    # s' in the option's set (the option is available there), outside it, then a termination
    path = [(obs((0.6, 0.4, 0.5, 0.5)), NO, 100.0), (obs((0.3, 0.4, 0.5, 0.5)), NO, None),
            (obs((0.35, 0.4, 0.5, 0.5)), yes, 0.0)]
    for s1, terminated, best in path:
        assert agent.options.tolist() == [0]  # the option runs (its target is elsewhere)
        w, a, phi = agent.q_head.weight.clone(), int(agent.action[0]), agent.features(s)[0]
        agent.transition(s1, torch.tensor([-1.0], dtype=F64), terminated, NO, yes)
        if not intra:
            assert torch.equal(agent.q_head.weight[:, :5], w[:, :5])
            s = s1
            continue
        if best is None:  # outside the set: the best primitive at s1
            best = max(float(w[0, d] @ agent.features(s1)[0]) for d in range(5))
        delta = -1.0 + best - float(w[0, a] @ phi)
        expected = w.clone()
        expected[0, a] += 0.01 * delta * phi
        torch.testing.assert_close(agent.q_head.weight[:, :5], expected[:, :5], rtol=0,
                                   atol=1e-12)  # (the termination also ends the decision)
        s = s1


@pytest.mark.parametrize("native", [False, True])
def test_intra_option_target_primitives_leaves_the_options_value_out(native):
    """With ``intra_option_target="primitives"`` the option's steps bootstrap on the best
    primitive at s' even where the option (worth 100 there) is available: the option's
    optimistic value is not copied into the primitives' values along its route."""
    if native and not HierarchicalAgent(make_bank(), order=1, native=None).native:
        pytest.skip("compiled agent kernels not built")
    agent = make_agent(make_bank(), intra_option_primitives=True,
                       intra_option_target="primitives", native=native)
    prefer_option(agent, value=100.0)
    agent.q_head.weight[:, 2, 0] = 7.0
    agent.q_head.weight[:, 1, 1] = -3.0
    s = obs((0.7, 0.5, 0.5, 0.5))
    agent.begin(s)
    s1 = obs((0.6, 0.4, 0.5, 0.5))  # in the option's set: max_d would be the option's 100
    w, a, phi = agent.q_head.weight.clone(), int(agent.action[0]), agent.features(s)[0]
    agent.transition(s1, torch.tensor([-1.0], dtype=F64), NO, NO, torch.tensor([True]))
    assert agent.options.tolist() == [0]  # the option goes on
    best = max(float(w[0, d] @ agent.features(s1)[0]) for d in range(5))
    assert best < 100.0
    expected = w.clone()
    expected[0, a] += 0.01 * (-1.0 + best - float(w[0, a] @ phi)) * phi
    torch.testing.assert_close(agent.q_head.weight[:, :5], expected[:, :5], rtol=0, atol=1e-12)


def test_intra_option_target_is_checked():
    with pytest.raises(ValueError, match="intra_option_target must be one of"):
        make_agent(make_bank(), intra_option_primitives=True, intra_option_target="options")


def test_intra_option_primitives_state_survives_a_checkpoint():
    """phi(s) of the current state is rebuilt from s on load: a resumed agent takes the same
    updates as one that never stopped."""
    bank_a, bank_b = make_bank(), make_bank()
    a, b = (make_agent(bank, intra_option_primitives=True, epsilon=0.2, option_epsilon=0.2)
            for bank in (bank_a, bank_b))  # fmt: skip
    for agent in (a, b):
        prefer_option(agent, value=100.0)
    g = torch.Generator().manual_seed(0)
    start = obs((0.7, 0.5, 0.5, 0.5))
    a.begin(start)
    yes = torch.tensor([True])
    steps = [torch.rand(1, 4, dtype=F64, generator=g) for _ in range(12)]
    for s1 in steps[:6]:
        a.transition(s1, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    b.load_state_dict(a.state_dict())
    for s1 in steps[6:]:
        for agent in (a, b):
            agent.transition(s1, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    assert torch.equal(a.q_head.weight, b.q_head.weight)


@pytest.mark.parametrize("native", [False, True])
@pytest.mark.parametrize("interruption", [False, True])
def test_interruption_stops_an_option_where_it_is_no_longer_greedy(interruption, native):
    """Q(s, o) = 10 + 20 cos(pi x) falls as x grows, the best primitive is worth 12: the
    option is chosen at x = 0.2 and, with interruption, stops at x = 0.48 (11.26 < 12, still in
    its set x < 0.5), where the SMDP update closes it on the primitive d' = 2; without, it runs
    on."""
    if native and not HierarchicalAgent(make_bank(), order=1, native=None).native:
        pytest.skip("compiled agent kernels not built")
    agent = make_agent(make_bank(signs=(-1.0,)), interruption=interruption, native=native)
    agent.q_head.weight[:, 5, 0] = 10.0
    agent.q_head.weight[:, 5, 8] = 20.0  # feature 8 is cos(pi x) (coefficients (1, 0, 0, 0))
    agent.q_head.weight[:, 2, 0] = 12.0
    s0 = obs((0.2, 0.5, 0.5, 0.5))
    assert float(agent.features(s0)[0, 8]) == pytest.approx(0.809017, abs=1e-6)  # cos(0.2 pi)
    agent.begin(s0)
    assert agent.decisions.tolist() == [5]
    yes = torch.tensor([True])
    w = agent.q_head.weight.clone()
    for x in (0.3, 0.45):
        info = agent.transition(obs((x, 0.5, 0.5, 0.5)), torch.tensor([-1.0], dtype=F64), NO,
                                NO, yes)  # fmt: skip
        assert info["decision_ended"].tolist() == [False] and agent.options.tolist() == [0]
    s3 = obs((0.48, 0.5, 0.5, 0.5))
    info = agent.transition(s3, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    if not interruption:
        assert info["decision_ended"].tolist() == [False] and agent.options.tolist() == [0]
        assert torch.equal(agent.q_head.weight, w)
        return
    assert info["decision_ended"].tolist() == [True] and info["duration"].tolist() == [3]
    assert agent.decisions.tolist() == [2] and agent.options.tolist() == [-1]
    q_s0 = float(w[0, 5] @ agent.features(s0)[0])
    assert info["smdp_delta"].item() == pytest.approx(-3.0 + 12.0 - q_s0, rel=1e-12)


@pytest.mark.parametrize("native", [False, True])
@pytest.mark.parametrize(("leave", "status", "ends"), [
    ("off", OptionStatus.LEARNED, False), ("always", OptionStatus.LEARNED, True),
    ("always", OptionStatus.LEARNING, True), ("learned", OptionStatus.LEARNED, True),
    ("learned", OptionStatus.LEARNING, False)])
def test_end_outside_set_ends_an_execution_where_it_leaves_its_set(leave, status, ends, native):
    """The option's set is x > 0.5, the best primitive is worth 12: the option is chosen at
    x = 0.7, goes on at x = 0.6 and, where end_outside_set applies to its status, ends at
    x = 0.4 (outside its own set, target not reached), where the SMDP update closes it on the
    primitive d' = 2 (the option is not available there); otherwise it runs on outside."""
    if native and not HierarchicalAgent(make_bank(), order=1, native=None).native:
        pytest.skip("compiled agent kernels not built")
    bank = make_bank()
    bank.status[:] = int(status)
    agent = make_agent(bank, end_outside_set=leave, native=native)
    prefer_option(agent, value=100.0)
    agent.q_head.weight[:, 2, 0] = 12.0
    s0 = obs((0.7, 0.5, 0.5, 0.5))
    agent.begin(s0)
    assert agent.decisions.tolist() == [5]
    yes, minus_one = torch.tensor([True]), torch.tensor([-1.0], dtype=F64)
    info = agent.transition(obs((0.6, 0.5, 0.5, 0.5)), minus_one, NO, NO, yes)
    assert info["decision_ended"].tolist() == [False] and agent.options.tolist() == [0]
    w = agent.q_head.weight.clone()
    info = agent.transition(obs((0.4, 0.5, 0.5, 0.5)), minus_one, NO, NO, yes)
    assert not bool(info["reached"].any())
    if not ends:
        assert info["decision_ended"].tolist() == [False] and agent.options.tolist() == [0]
        assert torch.equal(agent.q_head.weight, w)
        return
    assert info["decision_ended"].tolist() == [True] and info["duration"].tolist() == [2]
    assert agent.decisions.tolist() == [2] and agent.options.tolist() == [-1]
    q_s0 = float(w[0, 5] @ agent.features(s0)[0])
    assert info["smdp_delta"].item() == pytest.approx(-2.0 + 12.0 - q_s0, rel=1e-12)


def test_end_outside_set_names_its_choices():
    with pytest.raises(ValueError, match="end_outside_set must be one of off, learned, always"):
        make_agent(make_bank(), end_outside_set=True)
