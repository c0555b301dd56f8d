"""PopulationTrainer: the reproducibility contract, the shrinking active set, hooks, learning."""

import doctest
import importlib

import numpy as np
import pytest
import torch

from skillchain_torch.envs.pinball import physics
from skillchain_torch.trainers import PopulationTrainer, TrainConfig


def _run(runs, seed, native=None, **kwargs):
    cfg = TrainConfig(map="pinball_box", runs=runs, seed=seed, **kwargs)
    return PopulationTrainer(cfg, native=native).train()


def test_doctests():
    for name in ("loop.population", "study", "study.summary", "outputs.plots", "config.registry"):
        module = importlib.import_module(f"skillchain_torch.trainers.{name}")
        assert doctest.testmod(module, optionflags=doctest.ELLIPSIS).failed == 0


@pytest.mark.parametrize(
    ("kwargs", "native", "tensor_physics"),
    [
        (dict(episodes=3, max_episode_steps=500), None, False),  # goals and truncations
        (dict(episodes=3, max_episode_steps=500), False, False),  # the torch agent
        (dict(episodes=3, max_episode_steps=500), False, True),  # ... and the tensor physics
        (dict(episodes=2), None, False),  # terminations only
        (dict(episodes=2, gamma=0.99, epsilon=0.2, order=3, scale_step_size=True), None, False),
    ],
)
def test_agent_p_equals_single_run_with_seed_s_plus_p(kwargs, native, tensor_physics,
                                                       monkeypatch):
    if tensor_physics:
        monkeypatch.setattr(physics, "NATIVE", False)
    together = _run(3, seed=10, native=native, **kwargs)
    for p in range(3):
        alone = _run(1, seed=10 + p, native=native, **kwargs)
        assert np.array_equal(together.returns[p], alone.returns[0])
        assert np.array_equal(together.lengths[p], alone.lengths[0])
        assert torch.equal(together.weights[p], alone.weights[0])
    # the agents did not all finish at the same step, so the active set shrank on the way
    assert len(set(together.lengths.sum(1).tolist())) > 1


def test_large_population_rows_equal_single_runs():
    """A larger population than the others here: its rows must not change either."""
    together = _run(18, seed=0, episodes=2, max_episode_steps=60)
    for p in (0, 9, 17):
        alone = _run(1, seed=p, episodes=2, max_episode_steps=60)
        assert np.array_equal(together.returns[p], alone.returns[0])
        assert torch.equal(together.weights[p], alone.weights[0])


def test_same_seed_twice_is_identical_and_other_seed_differs():
    a = _run(2, seed=3, episodes=2, max_episode_steps=300)
    b = _run(2, seed=3, episodes=2, max_episode_steps=300)
    c = _run(2, seed=4, episodes=2, max_episode_steps=300)
    assert np.array_equal(a.returns, b.returns) and torch.equal(a.weights, b.weights)
    assert not torch.equal(a.weights, c.weights)


def test_finished_agents_stop_acting_and_learning():
    trainer = PopulationTrainer(TrainConfig(map="pinball_box", runs=4, episodes=3, seed=1))
    seen = []

    def record(tr, batch):
        assert all(e < 3 for e in batch.episodes)
        seen.append((tr.num_active, tr.episodes_done.copy()))

    trainer.register_op("post_episodes", record)
    trainer.train()
    assert trainer.finished and (trainer.episodes_done == 3).all()
    actives = [n for n, _ in seen]
    assert actives[-1] == 0 and any(0 < n < 4 for n in actives)
    assert actives == sorted(actives, reverse=True)
    # no agent took a step after its last episode
    assert trainer.agent_steps == int(trainer.lengths.sum())
    assert not np.isnan(trainer.returns).any() and trainer.lengths.min() >= 1
    # an episode ends at the goal (+10000) unless truncated
    goal = trainer.returns > 0
    assert goal.any()


def test_hooks_registration_rules():
    trainer = PopulationTrainer(TrainConfig(runs=1, episodes=1, max_episode_steps=2))
    with pytest.raises(ValueError, match="unknown hook stage 'post_step'"):
        trainer.register_op("post_step", lambda tr: None)
    trainer.register_op("post_train", lambda tr: None, name="a")
    with pytest.raises(ValueError, match="already registered"):
        trainer.register_op("post_train", lambda tr: None, name="a")
    calls = []
    trainer.register_op("pre_train", lambda tr: calls.append("pre"))
    trainer.register_op("post_train", lambda tr: calls.append("post"), name="b")
    trainer.train()
    assert calls == ["pre", "post"]


def test_train_in_slices_equals_one_call():
    cfg = TrainConfig(map="pinball_box", runs=2, episodes=2, seed=7, max_episode_steps=400)
    whole = PopulationTrainer(cfg).train()
    sliced = PopulationTrainer(cfg)
    while not sliced.finished:
        sliced.train(max_agent_steps=sliced.agent_steps + 333)
    assert np.array_equal(whole.returns, sliced.returns)
    assert torch.equal(whole.weights, sliced.weights)


def test_learning_improves_returns_on_the_box():
    """Cheap and deterministic: on pinball_box later episodes beat the first ones."""
    trainer = _run(4, seed=0, episodes=20, max_episode_steps=1000)
    first, last = trainer.returns[:, :5].mean(), trainer.returns[:, -5:].mean()
    assert last > first + 1000, (first, last)
