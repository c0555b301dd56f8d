"""The discovery pieces as pure functions: doctests, shapes and edge cases."""

from __future__ import annotations

import doctest
import importlib

import pytest
import torch

from skillchain_torch.discovery import (
    ConvergenceTest,
    choose_creation,
    covered_start,
    exclude_overlap,
    execution_outcome,
    overlap_exclusion,
    target_indicator,
)
from skillchain_torch.options import OptionBank

MODULES = ["convergence", "gestation", "readings", "skill_chaining"]


@pytest.mark.parametrize("name", MODULES)
def test_doctests(name):
    module = importlib.import_module(f"skillchain_torch.discovery.{name}")
    assert doctest.testmod(module, optionflags=doctest.ELLIPSIS).failed == 0


def test_agent_doctests():
    for name in ("skillchain_torch.agents.hierarchical",
                 "skillchain_torch.agents.skill_chaining_run"):
        assert doctest.testmod(importlib.import_module(name)).failed == 0


def bank_with(targets, population=1, slots=4):
    """A bank whose slots target ``("goal" | slot index)`` in order."""
    bank = OptionBank.build(population=population, slots=slots, order=1, capacity=8)
    for target in targets:
        if target == "goal":
            bank.allocate(torch.ones(population, dtype=torch.bool), target_event=0)
        else:
            bank.allocate(torch.ones(population, dtype=torch.bool), parent=target)
    return bank


def test_choose_creation_prefers_base_events_then_low_slots():
    base = torch.tensor([[False, True], [False, False], [True, True]])
    slot = torch.tensor([[True, False, False], [False, True, True], [False, False, False]])
    none = torch.zeros(3, 3, dtype=torch.bool)
    create, event, parent = choose_creation(base, slot, torch.zeros_like(base), none)
    assert create.tolist() == [True, True, True]
    assert event.tolist() == [1, -1, 0] and parent.tolist() == [-1, 1, -1]
    # Covered events are skipped, and nothing left means no creation.
    cover = torch.tensor([[True, False, False], [False, True, False], [False, False, False]])
    create, event, parent = choose_creation(base, slot, torch.ones_like(base), cover)
    assert create.tolist() == [False, True, False] and parent.tolist() == [-1, 2, -1]


def test_covered_start_reads_only_options_targeting_the_event():
    bank = bank_with(["goal", 0])  # slot 0 -> goal, slot 1 -> I(0)
    contains = torch.tensor([[False, True, False, False]])  # s in I(1) only
    base_cov, slot_cov = covered_start(bank, 1, contains, torch.tensor([-1]))
    assert base_cov.tolist() == [[False]]  # the goal option does not hold s
    assert slot_cov.tolist() == [[True, False, False, False]]  # I(0)'s child holds s
    base_cov, _ = covered_start(bank, 1, torch.zeros(1, 4, dtype=torch.bool), torch.tensor([0]))
    assert base_cov.tolist() == [[True]]  # the executing goal option covers the goal


def test_target_indicator_matches_the_bank():
    bank = bank_with(["goal", 0, "goal"], population=2)
    contains = torch.tensor([[True, False, True, True], [False, True, True, False]])
    obs = torch.rand(2, 4, dtype=torch.float64)
    terminated = torch.tensor([True, False])
    from skillchain_torch.options import GoalEvent

    expected = bank.target_reached(obs, terminated, (GoalEvent(),), contains=contains)
    got = target_indicator(bank, terminated[:, None], contains)
    assert torch.equal(got, expected)


def test_overlap_exclusion_parent_and_older_siblings_only():
    bank = bank_with(["goal", 0, 0, "goal"])
    x = overlap_exclusion(bank)[0].int().tolist()
    assert x[0] == [0, 0, 0, 0]  # the oldest goal option avoids nobody
    assert x[1] == [1, 0, 0, 0]  # child of 0: avoids its parent
    assert x[2] == [1, 1, 0, 0]  # younger sibling of 1: avoids parent 0 and sibling 1
    assert x[3] == [1, 0, 0, 0]  # younger goal sibling of 0
    everything = torch.ones(1, 4, dtype=torch.bool)
    untrained = torch.zeros(1, 4, dtype=torch.bool)
    assert exclude_overlap(everything, overlap_exclusion(bank), untrained).all()


def test_execution_outcome_target_beats_timeout():
    success, failure = execution_outcome(torch.tensor([True]), torch.tensor([250]),
                                         torch.tensor([True]), 250)  # fmt: skip
    assert success.tolist() == [True] and failure.tolist() == [False]


def test_convergence_reset_and_state():
    test = ConvergenceTest(1, 2, threshold=0.5, episodes=1)
    counted = torch.tensor([[True, False]])
    assert test.update(torch.tensor([[0.1, 0.1]]), counted).tolist() == [[True, False]]
    clone = ConvergenceTest(1, 2)
    clone.load_state_dict(test.state_dict())
    assert clone.streak.tolist() == [[1, 0]]
    test.reset(torch.tensor([[True, False]]))
    assert test.streak.tolist() == [[0, 0]]
    with pytest.raises(ValueError):
        ConvergenceTest(1, 1, threshold=0.0)
