"""Skill chaining's rules on crafted situations (issue 5, "Tests").

The agent is driven by hand along a one-dimensional *corridor*: observations ``(x, 0.5, 0.5,
0.5)`` with ``x`` chosen by the test, whatever the agent does, so every rule is checked where
it should fire and where it should not. Initiation sets are set by hand as half-planes in ``x``
(feature 1 of the polynomial features is ``x``); the goal is the environment's ``terminated``
flag and ``END`` is a hand-set region event near ``x = 0.9``.
"""

from __future__ import annotations

import logging

import pytest
import torch

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.discovery import event_list
from skillchain_torch.options import GoalEvent, OptionStatus, RegionEvent

F64 = torch.float64
END = RegionEvent(center=(0.9, 0.5), radius=0.05, name="end")
YES, NO = torch.tensor([True]), torch.tensor([False])
R = torch.tensor([-1.0], dtype=F64)


def point(x: float) -> torch.Tensor:
    return torch.tensor([[x, 0.5, 0.5, 0.5]], dtype=F64)


GOAL_ONLY = (GoalEvent(),)


def make_agent(slots=3, events=GOAL_ONLY, **kwargs) -> SkillChainingAgent:
    """One agent of the paper's preset (the rules under test are the paper's), order-1
    features, no exploration and a frozen top level (alpha 0)."""
    kwargs = {"order": 1, "option_order": 1, "alpha": 0.0, "epsilon": 0.0,
              "option_epsilon": 0.0, "events": events, **kwargs}
    return SkillChainingAgent.build(population=1, preset="paper", slots=slots, **kwargs)


def episode(agent, xs, terminated=True, first=False, next_start=0.1):
    """Walk the corridor through ``xs``; the last step terminates (goal) or truncates."""
    if first:
        agent.begin(point(xs[0]))
    for x in xs[1:-1]:
        agent.observe(point(x), R)
    end = YES if terminated else NO
    agent.observe_ends(point(xs[-1]), R, end, ~end, torch.tensor([0]), point(next_start))


def half_plane(agent, slot, threshold, above=True):
    """Slot ``slot``'s classifier says ``x > threshold`` (or ``<``), trained."""
    clf = agent.bank.classifier
    sign = 1.0 if above else -1.0
    with torch.no_grad():
        clf.weight[:, slot] = 0.0
        clf.weight[:, slot, 1] = sign
        clf.bias[:, slot] = -threshold * sign
        clf.trained[:, slot] = True


def add_option(agent, target_event=-1, parent=-1, status=OptionStatus.LEARNING, episode=0):
    slot = agent.bank.allocate(YES, target_event=target_event, parent=parent, episode=episode)
    agent.bank.set_status(torch.nn.functional.one_hot(slot, agent.bank.slots).bool(), status)
    agent.discovery._exclusion = None  # the bank changed behind the agent's back
    return int(slot)


def prefer_option(agent, slot, value=1e6):
    agent.q_head.weight[:, 5 + slot, :] = 0.0
    agent.q_head.weight[:, 5 + slot, 0] = value


CORRIDOR = [0.1, 0.3, 0.5, 0.7, 0.9]


# ------------------------------------------------------------------ creation
def test_reaching_the_goal_creates_a_gestating_goal_option():
    agent = make_agent()
    episode(agent, CORRIDOR, terminated=True, first=True)
    bank = agent.bank
    assert bank.status[0].tolist() == [OptionStatus.GESTATING, 0, 0]
    assert bank.target_event[0, 0] == 0 and bank.parent[0, 0] == -1
    assert bank.created_episode[0, 0] == 0
    assert [e.kind for e in agent.discovery.log] == ["created"]


def test_no_goal_no_option():
    agent = make_agent()
    episode(agent, CORRIDOR, terminated=False, first=True)  # truncated: not the goal
    assert not agent.bank.live().any()


def test_user_event_creates_on_entry_only():
    agent = make_agent(events=(GoalEvent(), END))
    agent.begin(point(0.1))
    agent.observe(point(0.5), R)
    assert not agent.bank.live().any()
    agent.observe(point(0.9), R)  # enters END
    assert agent.bank.live()[0].tolist() == [True, False, False]
    assert agent.bank.target_event[0, 0] == 1
    # Staying in the region is not triggering it again, even from an uncovered state.
    half_plane(agent, 0, 0.95)
    agent.observe(point(0.91), R)  # memberships at 0.91 now say "uncovered"
    agent.observe(point(0.92), R)
    assert agent.bank.live()[0].sum() == 1


# ------------------------------------------------------------------ covered start
def test_goal_from_a_covered_state_creates_nothing():
    agent = make_agent()
    k = add_option(agent, target_event=0)
    half_plane(agent, k, 0.6)  # the goal option covers x > 0.6
    episode(agent, [0.1, 0.3, 0.7, 0.9], terminated=True, first=True)  # came from 0.9
    assert agent.bank.live()[0].sum() == 1


def test_goal_from_an_uncovered_state_creates_a_sibling():
    agent = make_agent()
    k = add_option(agent, target_event=0)
    half_plane(agent, k, 0.6)
    episode(agent, [0.1, 0.3, 0.4, 0.5], terminated=True, first=True)  # came from 0.4
    assert agent.bank.live()[0].tolist() == [True, True, False]
    assert agent.bank.target_event[0, 1] == 0


def test_untrained_option_covers_everything():
    agent = make_agent()
    add_option(agent, target_event=0, status=OptionStatus.GESTATING)
    episode(agent, CORRIDOR, terminated=True, first=True)
    assert agent.bank.live()[0].sum() == 1


def test_executing_option_reaching_its_target_creates_nothing():
    for executing in (True, False):
        agent = make_agent()
        k = add_option(agent, target_event=0)
        half_plane(agent, k, 0.2, above=False)  # covers x < 0.2 only
        prefer_option(agent, k, 1e6 if executing else -1e6)
        agent.begin(point(0.1))
        assert agent.options.tolist() == ([k] if executing else [-1])
        episode(agent, CORRIDOR[1:], terminated=True)  # the goal is reached from x = 0.9
        assert agent.bank.live()[0].sum() == (1 if executing else 2)


# ------------------------------------------------------------------ gestation
def test_gestation_lasts_ten_whole_episodes_and_the_option_cannot_run():
    agent = make_agent(epsilon=1.0)  # random top-level choices among what is available
    episode(agent, CORRIDOR, terminated=True, first=True)  # created in episode 0
    prefer_option(agent, 0)
    head_before = agent.bank.q_head.weight.clone()
    for e in range(1, 11):
        assert agent.bank.status[0, 0] == OptionStatus.GESTATING, e
        for x in CORRIDOR[:-1]:
            agent.observe(point(x + 0.01), R)
            assert agent.decisions.item() < 5  # never executed
        episode(agent, [0.5, 0.6], terminated=False)
    assert agent.bank.status[0, 0] == OptionStatus.LEARNING  # joined at the end of episode 10
    assert [e.kind for e in agent.discovery.log] == ["created", "joined"]
    # It learned off-policy meanwhile (its untrained set holds every state).
    assert not torch.equal(agent.bank.q_head.weight, head_before)


def test_q_value_initialised_to_the_largest_sampled_value():
    agent = make_agent(gestation=2)
    values = torch.tensor([1.0, 2.0, 3.0, 4.0, 5.0], dtype=F64)
    agent.q_head.weight[0, :5, 0] = values  # Q(s, a) = a + 1 everywhere; greedy picks 4
    episode(agent, CORRIDOR, terminated=True, first=True)  # created: samples Q = 5
    agent.q_head.weight[0, 4, 0] = 7.0
    episode(agent, CORRIDOR, terminated=True)  # triggers its target again: samples 7
    agent.q_head.weight[0, 4, 0] = 6.0
    episode(agent, CORRIDOR, terminated=False)  # no trigger, no sample
    assert agent.bank.status[0, 0] == OptionStatus.LEARNING
    q = agent.q_head(agent.features(point(0.42)))
    assert q[0, 5].item() == 7.0
    assert agent.discovery.log[-1].kind == "joined" and agent.discovery.log[-1].value == 7.0


# ------------------------------------------------------------------ examples
@pytest.mark.parametrize("wait", [False, True])
def test_success_gives_positive_examples(wait):
    agent = make_agent(events=(GoalEvent(), END), wait_for_both_classes=wait)
    k = add_option(agent, target_event=1)  # reach END
    prefer_option(agent, k)
    agent.begin(point(0.1))
    for x in (0.3, 0.5, 0.7):
        agent.observe(point(x), R)
    assert agent.options.tolist() == [k]
    agent.observe(point(0.9), R)  # END: success after 4 steps
    clf = agent.bank.classifier
    assert clf.count[0, k] == 4 and clf.labels[0, k, :4].all()
    assert torch.equal(clf.examples[0, k, :4, 0], torch.tensor([0.1, 0.3, 0.5, 0.7], dtype=F64))
    assert clf.trained[0, k] != wait  # refitted after the new data, unless waiting
    assert clf.contains_points(0, k, point(0.2)).item()  # successes alone: still inside


def test_failure_gives_a_negative_start_and_drops_the_updates():
    agent = make_agent(events=(GoalEvent(), END), max_option_steps=3)
    k = add_option(agent, target_event=1)
    prefer_option(agent, k)
    agent.begin(point(0.1))
    start = agent.bank.q_head.weight[0, k].clone()
    agent.observe(point(0.2), R)
    agent.observe(point(0.3), R)
    assert not torch.equal(agent.bank.q_head.weight[0, k], start)  # it learned on the way
    agent.observe(point(0.4), R)  # third step: timeout without reaching END
    clf = agent.bank.classifier
    assert clf.count[0, k] == 1 and not clf.labels[0, k, 0]
    assert clf.examples[0, k, 0, 0] == 0.1
    assert torch.equal(agent.bank.q_head.weight[0, k], start)  # the failed updates are gone


@pytest.mark.parametrize("wait", [False, True])
def test_both_classes_fit_the_classifier(wait):
    agent = make_agent(events=(GoalEvent(), END), max_option_steps=3, wait_for_both_classes=wait)
    k = add_option(agent, target_event=1)
    prefer_option(agent, k)
    agent.begin(point(0.1))
    for x in (0.2, 0.3, 0.4):  # fails from 0.1
        agent.observe(point(x), R)
    for x in (0.8, 0.9):  # a new execution from 0.4 ... 0.8 reaches END
        agent.observe(point(x), R)
    clf = agent.bank.classifier
    assert clf.trained[0, k] and clf.sweeps_done[0, k] == (100 if wait else 200)
    assert clf.logit(point(0.85))[0, k] > clf.logit(point(0.1))[0, k]


def test_an_option_that_only_failed_leaves_the_repertoire():
    for wait in (False, True):
        agent = make_agent(events=(GoalEvent(), END), max_option_steps=2,
                           wait_for_both_classes=wait)  # fmt: skip
        k = add_option(agent, target_event=1)
        prefer_option(agent, k)
        agent.begin(point(0.1))
        for x in (0.2, 0.3):  # fails after 2 steps
            agent.observe(point(x), R)
        available = agent.bank.available(point(0.5))[0, k].item()
        assert available == wait  # the paper's fit empties the set; waiting keeps it


# ------------------------------------------------------------------ convergence, chaining
def learned_goal_option(agent, threshold=0.6):
    """A goal option whose set (x > threshold) has converged, via the convergence test."""
    k = add_option(agent, target_event=0)
    clf = agent.bank.classifier
    clf.add_examples(0, k, torch.cat([point(0.9), point(0.1)]), torch.tensor([True, False]))
    half_plane(agent, k, threshold)
    sc = agent.discovery
    sc.episode_weights = clf.snapshot()
    for _ in range(2):
        sc.fitted[0, k] = True
        sc.end_episodes(YES, agent.q_head)
    assert agent.bank.status[0, k] == OptionStatus.LEARNED
    return k


def test_convergence_needs_two_counted_small_changes():
    agent = make_agent()
    k = add_option(agent, target_event=0)
    clf, sc = agent.bank.classifier, agent.discovery
    clf.add_examples(0, k, point(0.9), torch.tensor([True]))
    sc.episode_weights = clf.snapshot()

    def one_episode(change, fitted=True):
        with torch.no_grad():
            clf.weight[0, k] += change
        sc.fitted[0, k] = fitted
        sc.end_episodes(YES, agent.q_head)
        return int(agent.bank.status[0, k])

    assert one_episode(0.1) == OptionStatus.LEARNING  # 0.1 * 15/16 < 0.15: streak 1
    assert one_episode(1.0) == OptionStatus.LEARNING  # big change: streak 0
    assert one_episode(0.1) == OptionStatus.LEARNING  # streak 1
    assert one_episode(0.0, fitted=False) == OptionStatus.LEARNING  # not counted
    assert one_episode(0.1) == OptionStatus.LEARNED  # streak 2
    assert clf.constrained[0, k]  # the distance constraint is on
    assert agent.discovery.log[-1].kind == "learned"


def test_convergence_needs_a_positive_example():
    agent = make_agent()
    k = add_option(agent, target_event=0)
    clf, sc = agent.bank.classifier, agent.discovery
    clf.add_examples(0, k, point(0.1), torch.tensor([False]))
    for _ in range(3):
        sc.fitted[0, k] = True
        sc.end_episodes(YES, agent.q_head)
    assert agent.bank.status[0, k] == OptionStatus.LEARNING


def test_learned_set_is_a_target_event_chaining():
    agent = make_agent()
    k = learned_goal_option(agent)
    agent.begin(point(0.1))
    agent.observe(point(0.5), R)
    assert agent.bank.live()[0].sum() == 1
    # Entering x > 0.6 (within 0.1 of the positive example at 0.9) creates its child.
    agent.observe(point(0.85), R)
    assert agent.bank.live()[0].sum() == 2 and agent.bank.parent[0, 1] == k
    assert agent.discovery.target_name(0, 1) == f"slot {k}"
    assert agent.discovery.depth()[0].tolist()[:2] == [1, 2]


def test_leaving_the_parents_set_into_the_childs_does_not_trigger_the_child():
    # Goal option 0 holds [0.8, 1] (x > 0.6 within 0.1 of its positive at 0.9); its learned
    # child 1 holds x > 0.2 by its own classifier, (0.2, 0.8) once the no-overlap rule removes
    # the parent's set. Moving from 0.85 to 0.5 enters the child's effective set but not its
    # own set: no grandchild is created (issue 15: such triggers spawned options leading away
    # from the goal). Entering its own set from 0.1 does create one.
    for start, created in ((0.85, False), (0.1, True)):
        agent = make_agent(slots=4)
        k = learned_goal_option(agent)
        child = add_option(agent, parent=k, status=OptionStatus.LEARNED)
        half_plane(agent, child, 0.2)
        agent.begin(point(start))
        agent.observe(point(0.5), R)
        assert agent.bank.live()[0].sum() == (3 if created else 2), start
        if created:
            assert agent.bank.parent[0, 2] == child


def test_event_list_holds_learned_sets_until_three_children():
    agent = make_agent(slots=6)
    k = add_option(agent, target_event=0)
    base_on, slot_on = event_list(agent.bank, num_base=1)
    assert base_on.tolist() == [[True]] and not slot_on.any()  # LEARNING: not listed
    agent.bank.set_status(torch.nn.functional.one_hot(torch.tensor([k]), 6).bool(),
                          OptionStatus.LEARNED)
    for children in range(4):
        assert event_list(agent.bank, num_base=1)[1][0, k] == (children < 3)
        add_option(agent, parent=k)


def test_unlearned_set_is_not_a_target_event():
    agent = make_agent()
    k = add_option(agent, target_event=0)  # LEARNING
    half_plane(agent, k, 0.6)
    agent.begin(point(0.1))
    agent.observe(point(0.85), R)
    assert agent.bank.live()[0].sum() == 1


def test_child_option_terminates_in_its_parents_set():
    agent = make_agent()
    k = learned_goal_option(agent)
    child = add_option(agent, parent=k)
    prefer_option(agent, child)
    agent.begin(point(0.1))
    assert agent.options.tolist() == [child]
    agent.observe(point(0.4), R)
    assert agent.options.tolist() == [child]
    agent.observe(point(0.85), R)  # inside the parent's set: the child's target
    assert agent.options.tolist() != [child]
    assert agent.bank.classifier.count[0, child] == 2  # two positive examples


# ------------------------------------------------------------------ overlap, branching
def test_child_and_younger_sibling_stay_out_of_older_sets():
    agent = make_agent(slots=4)
    k = learned_goal_option(agent)  # x > 0.6
    child = add_option(agent, parent=k)  # untrained: everything but the parent's set
    sibling = add_option(agent, target_event=0)  # a younger goal sibling
    half_plane(agent, sibling, 0.3)  # x > 0.3, overlapping the older one above 0.6
    inside = agent.membership(point(0.85))[0]
    middle = agent.membership(point(0.45))[0]
    assert inside[[k, child, sibling]].tolist() == [True, False, False]
    assert middle[[k, child, sibling]].tolist() == [False, True, True]
    off = make_agent(slots=4, overlap=False)
    learned_goal_option(off)
    add_option(off, parent=0)
    assert off.membership(point(0.85))[0, :2].tolist() == [True, True]


def test_branching_limit_removes_the_event():
    for existing, created in ((2, True), (3, False)):
        agent = make_agent(slots=4)
        for _ in range(existing):
            k = add_option(agent, target_event=0)
            half_plane(agent, k, 0.95)  # none covers the corridor
        episode(agent, CORRIDOR, terminated=True, first=True)
        assert (agent.bank.live()[0].sum() == existing + 1) == created


def test_slots_full_logged_once(caplog):
    agent = make_agent(slots=1, events=(GoalEvent(), END))
    k = add_option(agent, target_event=0)
    half_plane(agent, k, 0.95)
    with caplog.at_level(logging.INFO, logger="skillchain_torch.discovery"):
        episode(agent, CORRIDOR, terminated=True, first=True)
        episode(agent, CORRIDOR, terminated=True)
    kinds = [e.kind for e in agent.discovery.log]
    assert kinds == ["slots_full"]
    assert sum("option slots are used" in r.message for r in caplog.records) == 1
    assert agent.bank.live()[0].sum() == 1


def test_full_agent_stops_creating_work_once_logged(monkeypatch):
    """Late in a run every agent is full and some trigger fires at nearly every step: after
    the one ``slots_full`` record, triggers of a full agent must not reach ``allocate``."""
    agent = make_agent(slots=1, events=(GoalEvent(), END))
    k = add_option(agent, target_event=0)
    half_plane(agent, k, 0.95)
    calls = []
    allocate = agent.bank.allocate
    monkeypatch.setattr(agent.bank, "allocate",
                        lambda *a, **kw: calls.append(1) or allocate(*a, **kw))
    episode(agent, CORRIDOR, terminated=True, first=True)  # blocked: logged, still no allocate
    assert calls == [] and agent.discovery.slots_full_logged.tolist() == [True]
    for _ in range(3):
        episode(agent, CORRIDOR, terminated=True)
    assert calls == []
    assert [e.kind for e in agent.discovery.log] == ["slots_full"]


@pytest.mark.parametrize("overlap", [True, False])
def test_state_dict_round_trip(overlap):
    agent = make_agent(overlap=overlap, events=(GoalEvent(), END))
    episode(agent, CORRIDOR, terminated=True, first=True)
    clone = make_agent(overlap=overlap, events=(GoalEvent(), END))
    clone.load_state_dict(agent.state_dict())
    for a in (agent, clone):
        for x in (0.2, 0.4, 0.9):
            a.observe(point(x), R)
    assert torch.equal(agent.bank.status, clone.bank.status)
    assert torch.equal(agent.q_head.weight, clone.q_head.weight)
    assert torch.equal(agent.bank.q_head.weight, clone.bank.q_head.weight)
    assert torch.equal(agent.discovery.base_now, clone.discovery.base_now)
