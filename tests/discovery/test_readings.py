"""The initiation-set readings (issue 15) on crafted corridor walks (see ``corridor.py``).

Each reading's rule is checked where it should act and where it should not: gestation
positives, the set when gestation ends (everything / fitted), when the distance constraint
applies (learned / start), and fits that wait for both classes.
"""

from __future__ import annotations

import pytest
import torch
from corridor import CORRIDOR, YES, R, episode, make_agent, point

from skillchain_torch.discovery import InitiationReading, RecentStates
from skillchain_torch.options import OptionStatus
from skillchain_torch.trainers import TrainConfig

F64 = torch.float64


def reading_agent(gestation=1, max_option_steps=250, **reading):
    return make_agent(gestation=gestation, max_option_steps=max_option_steps,
                      reading=InitiationReading(**reading))


def stored(agent, k=0):
    clf = agent.bank.classifier
    n = int(clf.count[0, k])
    return clf.examples[0, k, :n, 0].tolist(), clf.labels[0, k, :n].tolist()


# ------------------------------------------------------------------ recent states
def test_recent_states_wrap_around_and_forget_at_episode_start():
    recent = RecentStates(population=1, length=3)
    for t in range(5):
        recent.record(YES, torch.full((1, 4), float(t), dtype=F64))
    _, obs = recent.window(YES, 3)
    assert obs[:, 0].tolist() == [2.0, 3.0, 4.0]  # oldest first after wrapping
    _, obs = recent.window(YES, 2)
    assert obs[:, 0].tolist() == [3.0, 4.0]
    recent.start_episodes(YES)
    assert recent.window(YES, 3)[0].numel() == 0
    recent.record(YES, torch.full((1, 4), 9.0, dtype=F64))
    assert recent.window(YES, 3)[1][:, 0].tolist() == [9.0]


# ------------------------------------------------------------------ gestation positives
def test_gestation_positives_are_the_states_before_each_hit():
    agent = reading_agent(gestation=2, gestation_positives=3)
    episode(agent, CORRIDOR, terminated=True, first=True)  # creates: 0.3, 0.5, 0.7 (not 0.9)
    assert agent.bank.status[0, 0] == OptionStatus.GESTATING
    assert stored(agent) == ([0.3, 0.5, 0.7], [True] * 3)
    episode(agent, [0.1, 0.2, 0.8], terminated=True)  # hit again in gestation: 2 states
    assert stored(agent) == ([0.3, 0.5, 0.7, 0.1, 0.2], [True] * 5)
    assert not agent.bank.classifier.trained[0, 0]  # not fitted during gestation


def test_no_gestation_positives_in_the_first_reading():
    agent = reading_agent(gestation=2)
    episode(agent, CORRIDOR, terminated=True, first=True)
    episode(agent, CORRIDOR, terminated=True)
    assert stored(agent) == ([], [])
    assert agent.discovery.recent is None


def test_hits_after_gestation_give_no_gestation_positives():
    # Constrained from the start, the set is near 0.5 and 0.7 only: the walk below never
    # starts the option, so no execution adds examples either.
    agent = reading_agent(gestation=1, gestation_positives=2, constrain="start")
    episode(agent, CORRIDOR, terminated=True, first=True)  # 0.5, 0.7
    episode(agent, [0.1, 0.2, 0.3], terminated=False)  # gestation ends (episode 1)
    assert agent.bank.status[0, 0] == OptionStatus.LEARNING
    episode(agent, [0.1, 0.2, 0.9], terminated=True)  # goal, but gestation is over
    assert agent.options.tolist() == [-1]
    assert stored(agent)[0] == [0.5, 0.7]


# ------------------------------------------------------------------ the set when gestation ends
def join(agent, positives=3):
    """Create a goal option from the corridor, then end its one episode of gestation."""
    episode(agent, CORRIDOR, terminated=True, first=True)
    episode(agent, [0.1, 0.2, 0.3], terminated=False)
    assert agent.bank.status[0, 0] == OptionStatus.LEARNING
    return agent.bank.classifier


def test_everything_start_leaves_the_set_untrained():
    clf = join(reading_agent(gestation_positives=3, start="everything"))
    assert not clf.trained[0, 0] and not clf.constrained[0, 0]
    assert clf.contains_points(0, 0, point(0.02)).item()  # true everywhere


def test_fitted_start_fits_the_gestation_positives():
    clf = join(reading_agent(gestation_positives=3, start="fitted"))
    assert clf.trained[0, 0] and clf.sweeps_done[0, 0] == 100
    assert not clf.constrained[0, 0]
    assert clf.contains_points(0, 0, point(0.5)).item()  # positives alone: inside


def test_fitted_start_waits_for_both_classes_when_told():
    clf = join(reading_agent(gestation_positives=3, start="fitted", one_class_fits=False))
    assert not clf.trained[0, 0]


def test_constraint_from_the_start_makes_the_set_local():
    clf = join(reading_agent(gestation_positives=3, start="fitted", constrain="start"))
    assert clf.constrained[0, 0]
    inside = torch.cat([point(0.3), point(0.38), point(0.7)])
    outside = torch.cat([point(0.1), point(0.15), point(0.85)])
    assert clf.contains_points(0, 0, inside).all()  # within 0.1 of 0.3, 0.5, 0.7
    assert not clf.contains_points(0, 0, outside).any()
    agent_contains = clf.contains(point(0.1))[0, 0].item()
    assert not agent_contains  # the agent's own query agrees


def test_constraint_once_learned_is_not_on_at_the_start():
    clf = join(reading_agent(gestation_positives=3, start="fitted", constrain="learned"))
    assert not clf.constrained[0, 0]
    assert clf.contains_points(0, 0, point(0.1)).item()


def test_a_constrained_set_without_positives_is_empty():
    clf = join(reading_agent(gestation_positives=0, constrain="start"))
    assert clf.constrained[0, 0]
    assert not clf.contains_points(0, 0, torch.cat([point(x) for x in CORRIDOR])).any()


def test_a_failure_after_fitted_start_keeps_the_positives():
    agent = reading_agent(gestation_positives=3, start="fitted", constrain="start",
                          max_option_steps=2)  # fmt: skip
    clf = join(agent)
    agent.q_head.weight[0, 5] = 0.0
    agent.q_head.weight[0, 5, 0] = 1e6  # prefer the option where it is available
    agent.observe_ends(point(0.3), R, torch.tensor([False]), YES, torch.tensor([0]), point(0.5))
    assert agent.options.tolist() == [0]  # started at 0.5, inside the set
    for x in (0.52, 0.54):  # two steps without the goal: timeout
        agent.observe(point(x), R)
    xs, labels = stored(agent)
    assert xs[-1] == 0.5 and labels == [True, True, True, False]
    assert clf.contains_points(0, 0, point(0.7)).item()  # a failure did not empty the set


# ------------------------------------------------------------------ state and config
def test_state_dict_round_trip_keeps_the_recent_states():
    agent = reading_agent(gestation=3, gestation_positives=4)
    episode(agent, CORRIDOR, terminated=True, first=True)
    agent.observe(point(0.2), R)
    state = agent.state_dict()
    other = reading_agent(gestation=3, gestation_positives=4)
    other.load_state_dict(state)
    for a in (agent, other):
        episode(a, [0.3, 0.9], terminated=True)
    assert stored(agent) == stored(other)
    with pytest.raises(ValueError, match="recent states"):
        first = make_agent(gestation=3)
        state["discovery"].pop("recent")
        reading_agent(gestation=3, gestation_positives=4).load_state_dict(state)
        del first


def test_reading_names_round_trip_and_bad_values_are_named():
    for r in (InitiationReading(), InitiationReading(20, "biased", "start", False)):
        assert InitiationReading.parse(r.name) == r
    with pytest.raises(ValueError, match="pos<N>"):
        InitiationReading.parse("fitted-start")
    with pytest.raises(ValueError, match="gestation_positives"):
        InitiationReading(gestation_positives=-1)


def test_train_config_checks_the_reading():
    with pytest.raises(ValueError, match="initiation_start must be one of"):
        TrainConfig(agent="skill-chaining", initiation_start="half").validate()
    with pytest.raises(ValueError, match="initiation_start 'biased' needs initiation_bias > 0"):
        TrainConfig(agent="skill-chaining", initiation_start="biased").validate()
    cfg = TrainConfig(agent="skill-chaining", gestation_positives=20, initiation_start="biased",
                      initiation_bias=4.0, one_class_fits=False).validate()  # fmt: skip
    assert cfg.reading.name == "pos20-biased-c" + cfg.initiation_constrain + "-wait"
