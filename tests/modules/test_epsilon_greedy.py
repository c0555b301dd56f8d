"""Epsilon-greedy over available decisions: masks, ties, exploration, fixed stream use."""

import doctest
import importlib

import pytest
import torch
from tensordict import TensorDict

from skillchain_torch.policies import EpsilonGreedy, EpsilonGreedyModule, epsilon_greedy
from skillchain_torch.rng import CounterRNG

F64 = torch.float64


def test_doctest():
    module = importlib.import_module("skillchain_torch.policies.epsilon_greedy")
    assert doctest.testmod(module).failed == 0


@pytest.mark.parametrize("epsilon", [0.0, 0.3, 1.0])
def test_never_picks_unavailable(epsilon):
    gen = torch.Generator().manual_seed(0)
    population, decisions = 2000, 7
    q = torch.randn(population, decisions, dtype=F64, generator=gen)
    q[:, 3] = 100.0  # the best value is often unavailable
    available = torch.rand(population, decisions, generator=gen) < 0.4
    available[torch.arange(population), torch.randint(decisions, (population,), generator=gen)] = (
        True
    )
    uniforms = CounterRNG.from_seed(1, population).uniform(2)
    decision = epsilon_greedy(q, available, epsilon, uniforms)
    assert decision.dtype == torch.int64
    assert bool(available[torch.arange(population), decision].all())


def test_epsilon_zero_is_argmax_among_available():
    gen = torch.Generator().manual_seed(1)
    q = torch.randn(500, 6, dtype=F64, generator=gen)
    available = torch.ones(500, 6, dtype=torch.bool)
    available[:, 0] = False
    uniforms = CounterRNG.from_seed(2, 500).uniform(2)
    decision = epsilon_greedy(q, available, 0.0, uniforms)
    assert torch.equal(decision, q[:, 1:].argmax(-1) + 1)


def test_ties_are_split_evenly_and_by_u1():
    population = 3000
    q = torch.tensor([[1.0, 5.0, 0.0, 5.0, 5.0]], dtype=F64).expand(population, 5)
    available = torch.ones(population, 5, dtype=torch.bool)
    uniforms = CounterRNG.from_seed(3, population).uniform(2)
    decision = epsilon_greedy(q, available, 0.0, uniforms)
    counts = torch.bincount(decision, minlength=5)
    assert counts[0] == 0 and counts[2] == 0
    assert bool(((counts[[1, 3, 4]] - 1000).abs() < 100).all())
    # Deterministic rule: the k-th maximiser with k = floor(3 * u1).
    k = torch.floor(3 * uniforms[:, 1]).long()
    assert torch.equal(decision, torch.tensor([1, 3, 4])[k])


def test_epsilon_one_is_uniform_over_available():
    population = 4000
    q = torch.arange(6, dtype=F64).expand(population, 6)
    available = torch.tensor([True, False, True, True, False, True]).expand(population, 6)
    decision = epsilon_greedy(q, available, 1.0, CounterRNG.from_seed(4, population).uniform(2))
    counts = torch.bincount(decision, minlength=6)
    assert counts[1] == 0 and counts[4] == 0
    assert bool(((counts[[0, 2, 3, 5]] - 1000).abs() < 100).all())


def test_exploration_rate_and_per_agent_epsilon():
    population = 4000
    q = torch.tensor([[0.0, 1.0]], dtype=F64).expand(population, 2)
    available = torch.ones(population, 2, dtype=torch.bool)
    uniforms = CounterRNG.from_seed(5, population).uniform(2)
    epsilon = torch.where(torch.arange(population) < population // 2, 0.0, 0.5).to(F64)
    decision = epsilon_greedy(q, available, epsilon, uniforms)
    assert bool((decision[: population // 2] == 1).all())
    # Exploring picks the worse decision half of the time: rate 0.5 * 0.5.
    worse = (decision[population // 2 :] == 0).double().mean().item()
    assert abs(worse - 0.25) < 0.03


def test_errors():
    q = torch.zeros(2, 3, dtype=F64)
    uniforms = torch.full((2, 2), 0.5, dtype=F64)
    available = torch.tensor([[True, False, False], [False, False, False]])
    with pytest.raises(ValueError, match=r"agents \[1\]"):
        epsilon_greedy(q, available, 0.1, uniforms)
    q[0, 0] = torch.nan
    with pytest.raises(ValueError, match="NaN"):
        epsilon_greedy(q, torch.ones(2, 3, dtype=torch.bool), 0.1, uniforms)
    with pytest.raises(ValueError):
        epsilon_greedy(q, torch.ones(2, 3, dtype=torch.bool), 0.1, uniforms[:, :1])


def test_population_invariance_and_fixed_stream_use():
    population, decisions = 5, 9
    gen = torch.Generator().manual_seed(6)
    policy = EpsilonGreedy(epsilon=0.3)
    together = CounterRNG.from_seed(10, population)
    alone = [CounterRNG(torch.tensor([10 + p])) for p in range(population)]
    for _ in range(50):
        q = torch.randint(0, 3, (population, decisions), generator=gen).to(F64)  # many ties
        available = torch.rand(population, decisions, generator=gen) < 0.7
        available[:, 4] = True
        decision = policy.sample(q, available, together)
        for p, rng in enumerate(alone):
            mine = policy.sample(q[p : p + 1], available[p : p + 1], rng)
            assert torch.equal(mine[0], decision[p])
    assert together.counter.tolist() == [100] * population


def test_tensordict_module():
    module = EpsilonGreedyModule(epsilon=0.0)
    td = TensorDict(
        {
            "q_value": torch.tensor([[0.0, 2.0, 1.0], [3.0, 2.0, 1.0]], dtype=F64),
            "mask": torch.tensor([[True, False, True], [True, True, True]]),
            "uniforms": torch.full((2, 2), 0.5, dtype=F64),
        },
        batch_size=[2],
    )
    assert module(td)["decision"].tolist() == [2, 0]
    assert module.in_keys == ["q_value", "mask", "uniforms"] and module.out_keys == ["decision"]
