"""The batched MountainCar (issue 53): the same observations, rewards, ends and restarts as one
TorchRL ``GymEnv`` per agent, step for step; the trainer picks it and gets the same run bit for
bit; agent p alone equals agent p in a population; a run on it resumes from a checkpoint."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
import torch

from skillchain_torch.envs import classic
from skillchain_torch.envs.classic import MountainCarStepper, batched_stepper
from skillchain_torch.envs.external import make_env, read_specs
from skillchain_torch.trainers import TrainConfig
from skillchain_torch.trainers.loop.env_stepper import EnvStepper
from skillchain_torch.trainers.loop.population import PopulationTrainer
from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint, load_checkpoint

ID = "gymnasium:MountainCar-v0"


def test_doctests():
    assert doctest.testmod(classic).failed == 0


@pytest.fixture(scope="module")
def sizes():
    return read_specs(make_env(ID))


def pumping(cars: MountainCarStepper, generator) -> torch.Tensor:
    """Push along the velocity (reaches the flag), with some random actions (hits the wall)."""
    v = torch.from_numpy(cars.velocity[cars.index.numpy()])
    push = torch.where(v >= 0, 2, 0)
    random = torch.randint(0, 3, push.shape, generator=generator)
    return torch.where(torch.rand(push.shape, generator=generator) < 0.3, random, push)


@pytest.mark.parametrize("max_episode_steps", [None, 150])
def test_step_for_step_the_same_as_one_gym_env_per_agent(sizes, max_episode_steps):
    P, seed = 6, 11
    gym = EnvStepper([make_env(ID) for _ in range(P)], sizes, seed=seed,
                     max_episode_steps=max_episode_steps)  # fmt: skip
    cars = MountainCarStepper(P, sizes, seed=seed, max_episode_steps=max_episode_steps)
    assert torch.equal(gym.start(), cars.start())
    generator = torch.Generator().manual_seed(0)
    counts = {"terminated": 0, "truncated": 0, "wall": 0}
    for step in range(2500):
        action = pumping(cars, generator)
        a, b = gym.step(action), cars.step(action)
        assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1]), step
        assert (a[2] is None) == (b[2] is None), step
        counts["wall"] += int((cars.position == cars.MIN_POSITION).sum())
        if a[2] is not None:
            assert torch.equal(a[2][0], b[2][0]) and torch.equal(a[2][1], b[2][1]), step
            counts["terminated"] += int(a[2][0].sum())
            counts["truncated"] += int(a[2][1].sum())
            rows = (a[2][0] | a[2][1]).nonzero().flatten()
            assert torch.equal(gym.reset(rows), cars.reset(rows)), step
        if step == 2000:  # some agents finish: both steppers drop the same rows
            keep = torch.arange(gym.num_active) % 2 == 0
            gym.compact(keep)
            cars.compact(keep)
    assert all(n > 0 for n in counts.values()), counts  # every branch of the step was taken


def test_only_mountain_car_gets_the_batched_stepper(sizes):
    assert isinstance(batched_stepper(ID, 2, sizes), MountainCarStepper)
    assert batched_stepper("gymnasium:Acrobot-v1", 2, sizes) is None
    assert batched_stepper("gymnasium:my_module:MountainCar-v0", 2, sizes) is None


def test_the_trainer_picks_it_and_gets_the_gym_run_bit_for_bit():
    config = TrainConfig(agent="flat", env=ID, runs=4, episodes=4, seed=3)
    batched = PopulationTrainer(config)
    assert isinstance(batched.stepper, MountainCarStepper)
    batched.train()
    gym = PopulationTrainer(config, batched_envs=False)
    assert isinstance(gym.stepper, EnvStepper)
    gym.train()
    assert np.array_equal(batched.returns, gym.returns)
    assert np.array_equal(batched.lengths, gym.lengths)


def test_agent_p_alone_equals_agent_p_in_a_population():
    population = PopulationTrainer(TrainConfig(agent="flat", env=ID, runs=3, episodes=3,
                                               seed=5)).train()  # fmt: skip
    alone = PopulationTrainer(TrainConfig(agent="flat", env=ID, runs=1, episodes=3,
                                          seed=7)).train()  # fmt: skip
    assert np.array_equal(population.returns[2], alone.returns[0])


class InterruptAt:
    def __init__(self):
        self.calls = 0

    def __call__(self, trainer, path):
        self.calls += 1
        if self.calls == 1:
            raise KeyboardInterrupt


def test_a_run_on_it_resumes_bit_for_bit(tmp_path):
    config = TrainConfig(agent="skill-chaining", env=ID, runs=3, episodes=6, seed=2,
                         checkpoint_every=3)  # fmt: skip
    reference = PopulationTrainer(config).train()
    interrupted = PopulationTrainer(config, out_dir=tmp_path)
    interrupted.register_op("post_checkpoint", InterruptAt())
    with pytest.raises(KeyboardInterrupt):
        interrupted.train()
    resumed = PopulationTrainer(config, out_dir=tmp_path)
    load_checkpoint(latest_checkpoint(tmp_path), resumed)
    resumed.train()
    assert np.array_equal(resumed.returns, reference.returns)
    assert np.array_equal(resumed.lengths, reference.lengths)
