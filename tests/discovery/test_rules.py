"""Skill chaining's rules on the corridor (issue 5, "Tests"), up to an option's learned set:
creation, the covered start, gestation and the initiation-set examples (``corridor.py``)."""

from __future__ import annotations

import doctest

import corridor
import pytest
import torch
from corridor import (
    CORRIDOR,
    END,
    F64,
    R,
    add_option,
    episode,
    half_plane,
    make_agent,
    point,
    prefer_option,
)

from skillchain_torch.options import GoalEvent, OptionStatus


def test_corridor_doctest():
    assert doctest.testmod(corridor).failed == 0


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
