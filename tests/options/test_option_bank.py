"""OptionBank: slots, statuses, targets, agent export, population invariance."""

import doctest
import importlib

import bank_examples
import pytest
import torch
from bank_examples import F64, trained_bank

from skillchain_torch.options import (
    FourierOptionQHead,
    GoalEvent,
    InitiationClassifier,
    OptionBank,
    OptionStatus,
    RegionEvent,
)


def test_doctest():
    module = importlib.import_module("skillchain_torch.options.bank")
    assert doctest.testmod(module).failed == 0


def test_bank_examples_doctest():
    assert doctest.testmod(bank_examples).failed == 0


def test_allocate_fills_first_empty_slot_and_returns_minus_one_when_full():
    bank = OptionBank.build(population=2, slots=3, order=1)
    both = torch.tensor([True, True])
    assert bank.allocate(both, episode=torch.tensor([4, 7])).tolist() == [0, 0]
    assert bank.allocate(torch.tensor([True, False])).tolist() == [1, -1]
    bank.free(torch.tensor([[True, False, False], [False, False, False]]))
    assert bank.status.tolist() == [[0, 1, 0], [1, 0, 0]]
    assert bank.allocate(both, target_event=2).tolist() == [0, 1]  # reuses the freed slot 0
    assert bank.allocate(both).tolist() == [2, 2]
    assert bank.allocate(both).tolist() == [-1, -1] and bank.full().tolist() == [True, True]
    assert bank.created_episode.tolist() == [[-1, -1, -1], [7, -1, -1]]
    assert bank.target_event.tolist() == [[2, -1, -1], [-1, 2, -1]]


def test_allocate_resets_the_slot_parts():
    bank = trained_bank()
    bank.free(torch.tensor([[False] * 4, [True, False, False, False], [False] * 4]))
    assert bank.status[:, 0].tolist() == [2, 0, 2]
    assert bank.allocate(torch.tensor([True, True, False])).tolist() == [2, 0, -1]
    assert not bool(bank.q_head.weight[1, 0].any()) and bool(bank.q_head.weight[0, 0].any())
    assert bank.classifier.count[:, 0].tolist() == [20, 0, 20]
    assert bank.classifier.trained[:, 0].tolist() == [True, False, True]
    assert bank.status[:, 0].tolist() == [2, 1, 2] and bank.parent[1, 0] == -1


def test_live_executable_available():
    bank = trained_bank()
    bank.set_status(torch.tensor([[False, True, False, False]] * 3), OptionStatus.LEARNED)
    assert bank.live()[0].tolist() == [True, True, False, False]
    assert bank.executable()[0].tolist() == [True, True, False, False]
    bank.set_status(torch.tensor([[False, True, False, False]] * 3), OptionStatus.GESTATING)
    assert bank.executable()[0].tolist() == [True, False, False, False]
    obs = torch.tensor([[0.1, 0.5, 0.5, 0.5], [0.95, 0.5, 0.5, 0.5], [0.1, 0.5, 0.5, 0.5]],
                       dtype=F64)  # fmt: skip
    member = bank.classifier.contains(obs)
    assert torch.equal(bank.available(obs), member & bank.executable())
    assert bank.available(obs)[:, 0].tolist() == [True, False, True]
    assert torch.equal(bank.available(obs, contains=torch.zeros_like(member)),
                       torch.zeros_like(member))  # fmt: skip


def test_target_reached_uses_parent_sets_and_base_events():
    bank = trained_bank()  # slot 0 targets event 0, slot 1 targets slot 0's set
    bank.allocate(torch.tensor([True, True, True]), target_event=1)
    events = [GoalEvent(), RegionEvent((0.9, 0.9), 0.05)]
    obs = torch.tensor([[0.1, 0.5, 0.5, 0.5], [0.9, 0.9, 0.5, 0.5], [0.99, 0.5, 0.5, 0.5]],
                       dtype=F64)  # fmt: skip
    terminated = torch.tensor([False, False, True])
    reached = bank.target_reached(obs, terminated, events)
    contains = bank.classifier.contains(obs)
    assert reached[:, 0].tolist() == [False, False, True]
    assert torch.equal(reached[:, 1], contains[:, 0])
    assert reached[:, 2].tolist() == [False, True, False]
    assert not bool(reached[:, 3].any())  # empty slots never fire
    with pytest.raises(ValueError, match="target event 1"):
        bank.target_reached(obs, terminated, events[:1])


def test_select_agents_and_from_agent_replicate_one_agent(tmp_path):
    bank = trained_bank(population=3)
    path = tmp_path / "population.pt"
    bank.save(path)
    copies = OptionBank.from_agent(path, agent=2, population=5)
    assert copies.population == 5 and copies.q_head.population == 5
    for key, value in copies.state_dict().items():
        if key.startswith(("q_head.basis", "classifier.features")):
            continue
        for p in range(5):
            assert torch.equal(value[p], bank.state_dict()[key][2]), key
    reseeded = bank.select_agents([0, 0], seeds=torch.tensor([10, 11]))
    assert reseeded.classifier.seeds.tolist() == [10, 11]
    with pytest.raises(ValueError, match="out of range"):
        bank.select_agents([3])


def test_mismatched_parts_raise():
    with pytest.raises(ValueError, match="q_head is for"):
        OptionBank(2, 3, FourierOptionQHead(2, 4, order=1), InitiationClassifier(2, 3))
    bank = OptionBank.build(1, 2, order=1)
    with pytest.raises(ValueError, match="mask must be"):
        bank.set_status(torch.ones(2, 2, dtype=torch.bool), OptionStatus.LEARNED)


def test_population_invariance():
    together = trained_bank(population=4)
    alone = [together.select_agents([p]) for p in range(4)]
    events = [GoalEvent(), RegionEvent((0.5, 0.5), 0.3)]
    gen = torch.Generator().manual_seed(1)
    for _ in range(5):
        obs = torch.rand(4, 4, dtype=F64, generator=gen)
        terminated = torch.rand(4, generator=gen) < 0.3
        available = together.available(obs)
        reached = together.target_reached(obs, terminated, events)
        q = together.q_head(obs)
        for p, bank in enumerate(alone):
            s = slice(p, p + 1)
            assert torch.equal(bank.available(obs[s])[0], available[p])
            assert torch.equal(bank.target_reached(obs[s], terminated[s], events)[0], reached[p])
            assert torch.equal(bank.q_head(obs[s])[0], q[p])
    slot = together.allocate(torch.tensor([True, False, True, True]))
    for p, bank in enumerate(alone):
        mine = bank.allocate(torch.tensor([p != 1]))
        assert mine.item() == slot[p].item()


def test_learning_loop_is_population_invariant():
    """Targets, intra-option Q-learning and classifier fits together: P=4 vs each alone."""
    from skillchain_torch.objectives import IntraOptionQLearning

    together = trained_bank(population=4)
    alone = [together.select_agents([p]) for p in range(4)]
    events = [GoalEvent()]
    update = IntraOptionQLearning()
    gen = torch.Generator().manual_seed(8)

    def step(bank, obs, action, reward, next_obs, terminated):
        contains = bank.classifier.contains(obs)
        reached = bank.target_reached(next_obs, terminated, events)
        delta = update(bank.q_head, obs, action, reward, next_obs, terminated, contains, reached,
                       bank.live())  # fmt: skip
        agents = torch.arange(bank.population)
        bank.classifier.add_examples(agents, 1, obs, reached[:, 1])
        bank.classifier.fit()
        return delta

    for _ in range(4):
        obs, next_obs = (
            torch.rand(4, 4, dtype=F64, generator=gen),
            torch.rand(4, 4, dtype=F64, generator=gen),
        )
        action = torch.randint(0, 5, (4,), generator=gen)
        reward = torch.full((4,), -1.0, dtype=F64)
        terminated = torch.rand(4, generator=gen) < 0.3
        delta = step(together, obs, action, reward, next_obs, terminated)
        assert bool(delta.any())
        for p, bank in enumerate(alone):
            s = slice(p, p + 1)
            mine = step(bank, obs[s], action[s], reward[s], next_obs[s], terminated[s])
            assert torch.equal(mine[0], delta[p])
    for p, bank in enumerate(alone):
        for key, value in bank.state_dict().items():
            if not key.startswith(("q_head.basis", "classifier.features")):
                assert torch.equal(value[0], together.state_dict()[key][p]), key


def test_allocate_wants_an_agent_mask():
    bank = OptionBank.build(2, 2, order=1)
    with pytest.raises(ValueError, match="BoolTensor"):
        bank.allocate(torch.tensor([0, 1]))
