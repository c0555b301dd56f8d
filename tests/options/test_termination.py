"""Termination predicates fire exactly in their regions."""

import doctest
import importlib

import pytest
import torch

from skillchain_torch.options import (
    GoalEvent,
    InitiationClassifier,
    InitiationSetEvent,
    LambdaEvent,
    RegionEvent,
    TerminationPredicate,
)

F64 = torch.float64


def grid(n=400, seed=0):
    return torch.rand(n, 4, dtype=F64, generator=torch.Generator().manual_seed(seed))


def test_doctest():
    module = importlib.import_module("skillchain_torch.options.termination")
    assert doctest.testmod(module).failed == 0


def test_all_are_named_predicates():
    clf = InitiationClassifier(1, 2)
    events = [GoalEvent(), RegionEvent((0.5, 0.5), 0.1), InitiationSetEvent(clf, 1),
              LambdaEvent(lambda o: o[:, 0] > 0, "right")]  # fmt: skip
    for event in events:
        assert isinstance(event, TerminationPredicate) and isinstance(event.name, str)
        assert event.name in repr(event)
    assert [e.name for e in events] == ["goal", "region", "initiation[1]", "right"]


def test_goal_event_is_the_terminated_flag():
    obs = grid(5)
    terminated = torch.tensor([True, False, False, True, False])
    assert torch.equal(GoalEvent()(obs, terminated), terminated)
    assert torch.equal(GoalEvent()(obs, terminated[:, None]), terminated)
    with pytest.raises(ValueError, match="terminated"):
        GoalEvent()(obs)
    with pytest.raises(ValueError, match="terminated"):
        GoalEvent()(obs, terminated[:3])


def test_region_event_is_a_closed_ball_in_its_dims():
    obs = grid()
    event = RegionEvent(center=(0.3, 0.6), radius=0.2)
    inside = ((obs[:, 0] - 0.3) ** 2 + (obs[:, 1] - 0.6) ** 2).sqrt() <= 0.2
    assert torch.equal(event(obs), inside) and 0 < int(inside.sum()) < len(obs)
    on_edge = torch.tensor([[0.5, 0.5, 0.0, 0.0]], dtype=F64)
    assert RegionEvent((0.5, 0.0), 0.5, dims=(0, 1))(on_edge).tolist() == [True]
    velocity = RegionEvent((1.0,), 0.25, dims=(3,))
    assert torch.equal(velocity(obs), obs[:, 3] >= 0.75)
    per_agent = RegionEvent(torch.tensor([[0.0, 0.0], [1.0, 1.0]]), 0.1)
    assert per_agent(torch.tensor([[0.0, 0.05, 0, 0], [0.0, 0.05, 0, 0]], dtype=F64)).tolist() == [
        True, False]  # fmt: skip
    with pytest.raises(ValueError, match="coordinates"):
        RegionEvent((0.1, 0.2, 0.3), 0.1)
    with pytest.raises(ValueError, match="dims"):
        RegionEvent((0.1,), 0.1, dims=(-1,))
    with pytest.raises(ValueError, match=r"dims \(4,\) do not index a 4-d observation"):
        RegionEvent((0.1,), 0.1, dims=(4,))(obs)


def test_initiation_set_event_follows_the_classifier():
    clf = InitiationClassifier(population=3, slots=2)
    x = grid(60, seed=1)
    for p in range(3):
        clf.add_examples(p, 0, x, x[:, 1] < 0.5)
    clf.fit()
    obs = torch.tensor([[0.5, 0.1, 0.5, 0.5], [0.5, 0.9, 0.5, 0.5], [0.5, 0.9, 0.5, 0.5]],
                       dtype=F64)  # fmt: skip
    assert InitiationSetEvent(clf, 0)(obs).tolist() == [True, False, False]
    assert InitiationSetEvent(clf, 1)(obs).tolist() == [True, True, True]  # untrained: all
    per_agent = InitiationSetEvent(clf, torch.tensor([0, 1, -1]))
    assert per_agent(obs).tolist() == [True, True, False]
    contains = torch.tensor([[False, True], [True, False], [True, True]])
    assert per_agent(obs, contains=contains).tolist() == [False, False, False]
    with pytest.raises(ValueError, match="out of range"):
        InitiationSetEvent(clf, 2)


def test_lambda_event_checks_its_output():
    obs = grid(10)
    assert torch.equal(LambdaEvent(lambda o: o[:, 2] < 0.5, "slow")(obs), obs[:, 2] < 0.5)
    with pytest.raises(ValueError, match="returned shape"):
        LambdaEvent(lambda o: o[:, :2] < 0.5, "bad")(obs)


def test_population_invariance():
    clf = InitiationClassifier(population=4, slots=2, capacity=20)
    x = grid(40, seed=3)
    clf.add_examples(torch.arange(40) % 4, 0, x, x[:, 0] < 0.4)
    clf.fit()
    clf.constrain(torch.tensor([[True, False]] * 4))
    obs = grid(4, seed=4)
    events = [RegionEvent((0.5, 0.5), 0.3), InitiationSetEvent(clf, torch.tensor([0, 1, 0, 0]))]
    together = [event(obs) for event in events]
    for p in range(4):
        alone = clf.select_agents([p])
        mine = [RegionEvent((0.5, 0.5), 0.3), InitiationSetEvent(alone, events[1].slot[p])]
        for event, value in zip(mine, together):
            assert torch.equal(event(obs[p : p + 1])[0], value[p])
