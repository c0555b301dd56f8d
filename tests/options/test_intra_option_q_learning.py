"""Intra-option Q-learning: initiation-set gating, bootstrap cuts, completion reward, off-policy."""

import doctest
import importlib

import pytest
import torch

from skillchain_torch.features import FourierBasis
from skillchain_torch.objectives import IntraOptionQLearning, option_td_target
from skillchain_torch.options import FourierOptionQHead, MLPOptionQHead

F64 = torch.float64


def rand(shape, seed):
    return torch.rand(shape, dtype=F64, generator=torch.Generator().manual_seed(seed))


def random_head(population, slots, seed=0, alpha=0.001):
    head = FourierOptionQHead(population, slots, order=2, alpha=alpha)
    gen = torch.Generator().manual_seed(seed)
    head.weight.copy_(torch.randn(head.weight.shape, dtype=F64, generator=gen))
    return head


def bools(values):
    return torch.tensor(values, dtype=torch.bool)


def test_doctest():
    module = importlib.import_module("skillchain_torch.objectives.q_learning")
    assert doctest.testmod(module).failed == 0


def test_target_formula_cuts_bootstrap_at_target_and_termination():
    next_q_max = torch.tensor([[10.0, 20.0, float("inf")], [1.0, 2.0, 3.0]], dtype=F64)
    reached = bools([[False, True, True], [False, False, False]])
    terminated = bools([False, True])
    target = option_td_target(torch.tensor([-1.0, -5.0]), next_q_max, reached, terminated,
                              gamma=0.5, completion_reward=100.0)  # fmt: skip
    assert target.tolist() == [[-1.0 + 5.0, 99.0, 99.0], [-5.0, -5.0, -5.0]]


def test_update_matches_hand_computation_and_gates_on_the_initiation_set():
    head = random_head(2, 3, alpha=0.01)
    before = head.weight.clone()
    obs, next_obs = rand((2, 4), 1), rand((2, 4), 2)
    action, reward = torch.tensor([3, 0]), torch.tensor([-5.0, -1.0], dtype=F64)
    in_init = bools([[True, False, True], [True, True, False]])
    reached = bools([[False, False, True], [False, False, False]])
    learnable = bools([[True, True, True], [False, True, True]])
    update = IntraOptionQLearning(gamma=1.0, completion_reward=1000.0)
    delta = update(head, obs, action, reward, next_obs, bools([False, False]), in_init, reached,
                   learnable)  # fmt: skip
    basis = FourierBasis(4, 2)
    phi, next_phi = basis(obs), basis(next_obs)
    for p in range(2):
        for k in range(3):
            if not (in_init[p, k] and learnable[p, k]):
                assert delta[p, k] == 0.0
                assert torch.equal(head.weight[p, k], before[p, k])
                continue
            q_next = max(float(before[p, k, a] @ next_phi[p]) for a in range(5))
            target = float(reward[p]) + (1000.0 if reached[p, k] else q_next)
            expected = target - float(before[p, k, action[p]] @ phi[p])
            assert delta[p, k].item() == pytest.approx(expected, rel=1e-12)
            step = head.weight[p, k, action[p]] - before[p, k, action[p]]
            assert torch.allclose(step, 0.01 * delta[p, k] * phi[p], rtol=1e-12, atol=1e-15)


def test_env_termination_cuts_bootstrap_for_every_slot():
    head = random_head(1, 2)
    update = IntraOptionQLearning(completion_reward=50.0)
    obs = rand((1, 4), 3)
    args = dict(obs=obs, action=torch.tensor([1]), reward=torch.tensor([10_000.0], dtype=F64),
                next_obs=rand((1, 4), 4), in_initiation=bools([[True, True]]))  # fmt: skip
    q_sa = head.q_value(obs, torch.tensor([1]))
    delta = update(head, env_terminated=bools([True]), target_reached=bools([[True, False]]),
                   **args)  # fmt: skip
    # Slot 0 targets the goal: env reward plus the completion reward; slot 1: env reward only.
    assert delta[0].tolist() == (torch.tensor([10_050.0, 10_000.0], dtype=F64) - q_sa[0]).tolist()


def test_completion_reward_per_slot_tensor():
    head = FourierOptionQHead(1, 2, order=1, alpha=0.0)
    obs = torch.zeros(1, 4, dtype=F64)
    update = IntraOptionQLearning(completion_reward=torch.tensor([[0.0, 10_000.0]], dtype=F64))
    delta = update(
        head,
        obs,
        torch.tensor([4]),
        torch.tensor([[10_000.0]], dtype=F64),
        obs,
        torch.tensor([[True]]),
        bools([[True, True]]),
        bools([[True, True]]),
    )
    assert delta.tolist() == [[10_000.0, 20_000.0]]


def test_off_policy_any_action_updates_that_action_row():
    for action in range(5):
        head = FourierOptionQHead(1, 1, order=1, alpha=0.1)
        obs = rand((1, 4), action)
        IntraOptionQLearning()(
            head,
            obs,
            torch.tensor([action]),
            torch.tensor([-1.0]),
            obs,
            bools([False]),
            bools([[True]]),
            bools([[False]]),
        )
        moved = head.weight[0, 0].abs().sum(-1) > 0
        assert moved.tolist() == [a == action for a in range(5)]


def test_nothing_to_learn_is_a_no_op():
    head = random_head(2, 2)
    before = head.weight.clone()
    delta = IntraOptionQLearning()(head, rand((2, 4), 0), torch.tensor([0, 1]),
                                   torch.zeros(2, dtype=F64), rand((2, 4), 1), bools([0, 0]),
                                   torch.zeros(2, 2, dtype=torch.bool),
                                   torch.zeros(2, 2, dtype=torch.bool))  # fmt: skip
    assert not bool(delta.any()) and torch.equal(head.weight, before)


def test_works_with_the_mlp_head():
    head = MLPOptionQHead(2, 3, hidden=8, lr=0.01)
    obs = rand((2, 4), 0)
    in_init = bools([[True, False, True], [True, True, True]])
    args = (head, obs, torch.tensor([0, 4]), torch.tensor([-1.0, -1.0], dtype=F64), obs,
            bools([False, False]), in_init, torch.ones(2, 3, dtype=torch.bool))  # fmt: skip
    first = IntraOptionQLearning(completion_reward=5.0)(*args)
    assert not bool(first[~in_init].any()) and bool((first[in_init] == 4.0).all())
    for _ in range(30):
        delta = IntraOptionQLearning(completion_reward=5.0)(*args)
    assert bool((delta[in_init].abs() < 4.0).all())


def test_bad_shapes_raise():
    head = FourierOptionQHead(2, 3, order=1)
    obs = rand((2, 4), 0)
    with pytest.raises(ValueError, match="in_initiation"):
        IntraOptionQLearning()(head, obs, torch.tensor([0, 0]), torch.zeros(2), obs,
                               bools([0, 0]), bools([[1, 1]]), torch.ones(2, 3))  # fmt: skip
    with pytest.raises(ValueError, match="reward"):
        IntraOptionQLearning()(head, obs, torch.tensor([0, 0]), torch.zeros(3), obs,
                               bools([0, 0]), torch.ones(2, 3), torch.ones(2, 3))  # fmt: skip


def test_population_invariance():
    population, slots = 4, 8
    together = random_head(population, slots, seed=7)
    alone = [together.select_agents([p]) for p in range(population)]
    update = IntraOptionQLearning()
    gen = torch.Generator().manual_seed(11)
    for _ in range(6):
        obs = torch.rand(population, 4, dtype=F64, generator=gen)
        next_obs = torch.rand(population, 4, dtype=F64, generator=gen)
        action = torch.randint(0, 5, (population,), generator=gen)
        reward = -torch.randint(1, 6, (population,), generator=gen).to(F64)
        terminated = torch.rand(population, generator=gen) < 0.2
        in_init = torch.rand(population, slots, generator=gen) < 0.7
        reached = torch.rand(population, slots, generator=gen) < 0.3
        delta = update(together, obs, action, reward, next_obs, terminated, in_init, reached)
        for p, head in enumerate(alone):
            s = slice(p, p + 1)
            d = update(head, obs[s], action[s], reward[s], next_obs[s], terminated[s],
                       in_init[s], reached[s])  # fmt: skip
            assert torch.equal(d[0], delta[p])
    for p, head in enumerate(alone):
        assert torch.equal(head.weight[0], together.weight[p])
