"""Which options learn from a transition (issue 30; paper section 5.1), crafted cases on both
paths: the executing option learns on-policy wherever it goes, other options off-policy only
inside their own initiation sets, and the no-overlap rule narrows choosing, never learning."""

from __future__ import annotations

import pytest
import torch
from hand_built import F64, make_agent, make_bank, prefer_option

from skillchain_torch.backends import hierarchical as native_hierarchical
from skillchain_torch.objectives import option_update_mask

PATHS = [False] + ([True] if native_hierarchical.AVAILABLE else [])


def obs(x: float) -> torch.Tensor:
    return torch.tensor([[x, 0.5, 0.5, 0.5]], dtype=F64)


def bank_of(signs: tuple[float, ...]):
    """Slot k's own set: ``x > 0.5`` (sign +1) or ``x < 0.5`` (-1); all target event 0, so
    the slots are siblings (the lower one the elder)."""
    return make_bank(slots=len(signs), signs=signs)


def agent_of(bank, native: bool, **kwargs):
    return make_agent(bank, native=native, **kwargs)


def moved(agent, before: torch.Tensor) -> list[bool]:
    """Which slots' weights changed since ``before``."""
    return (agent.bank.q_head.weight != before).flatten(2).any(-1)[0].tolist()


def test_mask_rule():
    own = torch.tensor([[True, False, False], [False, False, False]])
    executing = torch.tensor([1, -1])
    assert option_update_mask(own, executing).tolist() == [[True, True, False],
                                                           [False, False, False]]
    learnable = torch.tensor([[True, False, True], [True, True, True]])
    assert option_update_mask(own, executing, learnable).tolist() == [[True, False, False],
                                                                      [False, False, False]]
    assert option_update_mask(own).tolist() == own.tolist()


@pytest.mark.parametrize("native", PATHS)
def test_executing_option_learns_outside_its_set(native):
    agent = agent_of(bank_of((1.0,)), native)
    prefer_option(agent, 0)  # the top level prefers the option everywhere
    agent.begin(obs(0.7))
    assert agent.options.tolist() == [0]
    agent.observe(obs(0.3), torch.tensor([-1.0], dtype=F64))  # leaves its set, goes on
    assert agent.options.tolist() == [0] and not bool(agent.own_contains[0, 0])
    before = agent.bank.q_head.weight.clone()
    agent.observe(obs(0.32), torch.tensor([-1.0], dtype=F64))  # s = 0.3: outside its set
    assert moved(agent, before) == [True]  # on-policy: learns wherever it executes


@pytest.mark.parametrize("native", PATHS)
def test_other_options_learn_only_in_their_own_sets(native):
    agent = agent_of(bank_of((1.0, -1.0)), native)
    prefer_option(agent, 0)  # slot 0 executes from x = 0.7
    agent.begin(obs(0.7))
    assert agent.options.tolist() == [0]
    before = agent.bank.q_head.weight.clone()
    agent.observe(obs(0.72), torch.tensor([-1.0], dtype=F64))
    assert moved(agent, before) == [True, False]  # slot 1's set (x < 0.5) does not hold s


@pytest.mark.parametrize("native", PATHS)
def test_overlap_narrows_choosing_not_learning(native):
    # Two siblings over x > 0.5: the younger (slot 1) may not be chosen where the elder holds
    # s, but it learns there off-policy.
    agent = agent_of(bank_of((1.0, 1.0)), native, overlap=True)
    prefer_option(agent, 1)  # the top level would take slot 1 if available
    agent.begin(obs(0.7))
    assert agent.contains[0].tolist() == [True, False]
    assert agent.own_contains[0].tolist() == [True, True]
    assert agent.options.tolist() == [-1]  # slot 1 is not available to choose
    before = agent.bank.q_head.weight.clone()
    agent.observe(obs(0.72), torch.tensor([-1.0], dtype=F64))
    assert moved(agent, before) == [True, True]


def test_paths_agree_with_learning_options():
    if not native_hierarchical.AVAILABLE:
        pytest.skip("the compiled kernels are not built")
    weights = []
    for native in (False, True):
        agent = agent_of(bank_of((1.0, 1.0)), native, overlap=True)
        prefer_option(agent, 0)
        agent.begin(obs(0.7))
        for x in (0.6, 0.45, 0.3, 0.55, 0.75):
            agent.observe(obs(x), torch.tensor([-1.0], dtype=F64))
        weights.append(agent.bank.q_head.weight.clone())
    torch.testing.assert_close(weights[0], weights[1], rtol=0, atol=1e-9)
