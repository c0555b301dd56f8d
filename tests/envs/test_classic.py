"""The batched MountainCar and Acrobot (issue 53): the same observations, rewards, ends and
restarts as one TorchRL ``GymEnv`` per agent, step for step; the trainer picks them and gets the
same run bit for bit; agent p alone equals agent p in a population; a run on them resumes from a
checkpoint."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
import torch

from skillchain_torch.envs import classic
from skillchain_torch.envs.classic import (
    AcrobotStepper,
    CartPoleStepper,
    MountainCarStepper,
    batched_stepper,
)
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


def same_as_gym(env_id, kind, policy, extra, steps, max_episode_steps, P=6, seed=11,
                sizes=None):
    """Step ``kind`` and one ``GymEnv`` per agent together with ``policy(stepper, generator)``
    for ``steps`` steps (half the agents retire at 5/6 of them): every observation, reward,
    end and restart is the same. Returns how often the episodes terminated, were truncated,
    and ``extra(stepper, before)`` counted (a branch of the step: the car at the wall, an
    angle wrapped)."""
    sizes = read_specs(make_env(env_id)) if sizes is None else sizes
    gym = EnvStepper([make_env(env_id) for _ in range(P)], sizes, seed=seed,
                     max_episode_steps=max_episode_steps)  # fmt: skip
    batched = kind(P, sizes, seed=seed, max_episode_steps=max_episode_steps)
    assert torch.equal(gym.start(), batched.start())
    generator = torch.Generator().manual_seed(0)
    counts = {"terminated": 0, "truncated": 0, "branch": 0}
    for step in range(steps):
        action = policy(batched, generator)
        before = batched.state_dict()
        a, b = gym.step(action), batched.step(action)
        assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1]), step
        assert (a[2] is None) == (b[2] is None), step
        counts["branch"] += extra(batched, before)
        if a[2] is not None:
            assert torch.equal(a[2][0], b[2][0]) and torch.equal(a[2][1], b[2][1]), step
            counts["terminated"] += int(a[2][0].sum())
            counts["truncated"] += int(a[2][1].sum())
            rows = (a[2][0] | a[2][1]).nonzero().flatten()
            assert torch.equal(gym.reset(rows), batched.reset(rows)), step
        if step == steps * 5 // 6:  # some agents finish: both steppers drop the same rows
            keep = torch.arange(gym.num_active) % 2 == 0
            gym.compact(keep)
            batched.compact(keep)
    return counts


def pumping(cars: MountainCarStepper, generator) -> torch.Tensor:
    """Push along the velocity (reaches the flag), with some random actions (hits the wall)."""
    v = torch.from_numpy(cars.velocity[cars.index.numpy()])
    push = torch.where(v >= 0, 2, 0)
    random = torch.randint(0, 3, push.shape, generator=generator)
    return torch.where(torch.rand(push.shape, generator=generator) < 0.3, random, push)


def at_the_wall(cars: MountainCarStepper, before) -> int:
    return int((cars.position == cars.MIN_POSITION).sum())


@pytest.mark.parametrize("max_episode_steps", [None, 150])
def test_step_for_step_the_same_as_one_gym_env_per_agent(max_episode_steps):
    counts = same_as_gym(ID, MountainCarStepper, pumping, at_the_wall, 2400, max_episode_steps)
    assert all(n > 0 for n in counts.values()), counts  # every branch of the step was taken


ACROBOT = "gymnasium:Acrobot-v1"


def swinging(arms: AcrobotStepper, generator) -> torch.Tensor:
    """The torque along the second joint's velocity (reaches the line), with some random
    actions; agents 0 and 3 act at random only (they run into the time limit)."""
    push = torch.where(torch.from_numpy(arms.state[arms.index.numpy(), 3]) >= 0, 2, 0)
    random = torch.randint(0, 3, push.shape, generator=generator)
    share = torch.where(arms.index % 3 == 0, 1.0, 0.3)
    return torch.where(torch.rand(push.shape, generator=generator) < share, random, push)


def wrapped(arms: AcrobotStepper, before) -> int:
    """Angles that crossed +-pi this step (wrapped into [-pi, pi])."""
    rows = arms.index.numpy()
    jump = np.abs(arms.state[rows, :2] - before["state"].numpy()[rows, :2])
    return int((jump > np.pi).sum())


@pytest.mark.parametrize("max_episode_steps", [None, 300])
def test_acrobot_step_for_step_the_same_as_one_gym_env_per_agent(max_episode_steps):
    counts = same_as_gym(ACROBOT, AcrobotStepper, swinging, wrapped, 3000, max_episode_steps)
    assert all(n > 0 for n in counts.values()), counts


CARTPOLE = "gymnasium:CartPole-v1"
CART_BOUNDS = "-2.4:2.4,-3:3,-0.21:0.21,-3:3"


def balancing(carts: CartPoleStepper, generator) -> torch.Tensor:
    """Push towards the pole's lean and fall (it stays up until the time limit), with random
    actions (it falls); agents 0 and 3 act at random only."""
    s = carts.state[carts.index.numpy()]
    push = torch.from_numpy((s[:, 2] + 0.5 * s[:, 3] > 0).astype(np.int64))
    random = torch.randint(0, 2, push.shape, generator=generator)
    share = torch.where(carts.index % 3 == 0, 1.0, 0.05)
    return torch.where(torch.rand(push.shape, generator=generator) < share, random, push)


def leaning(carts: CartPoleStepper, before) -> int:
    """Poles that lean further than 0.1 rad (the angle branch of the step, before a fall)."""
    return int((np.abs(carts.state[carts.index.numpy(), 2]) > 0.1).sum())


@pytest.mark.parametrize("max_episode_steps", [None, 200])
def test_cartpole_step_for_step_the_same_as_one_gym_env_per_agent(max_episode_steps):
    sizes = read_specs(make_env(CARTPOLE), obs_bounds=CART_BOUNDS)
    counts = same_as_gym(CARTPOLE, CartPoleStepper, balancing, leaning, 3000,
                         max_episode_steps, sizes=sizes)  # fmt: skip
    assert all(n > 0 for n in counts.values()), counts


def test_acrobot_starts_are_gymnasiums():
    """A reset's state is float32 in Gymnasium, and so is its first observation's
    trigonometry (seed 103's start differs in the last bit from float64 maths)."""
    sizes = read_specs(make_env(ACROBOT))
    for seed in range(100, 110):
        gym = EnvStepper([make_env(ACROBOT)], sizes, seed=seed)
        assert torch.equal(gym.start(), AcrobotStepper(1, sizes, seed=seed).start()), seed


def test_which_envs_get_a_batched_stepper(sizes):
    assert isinstance(batched_stepper(ID, 2, sizes), MountainCarStepper)
    acrobot = read_specs(make_env(ACROBOT))
    assert isinstance(batched_stepper(ACROBOT, 2, acrobot), AcrobotStepper)
    assert batched_stepper("gymnasium:LunarLander-v3", 2, sizes) is None
    assert batched_stepper("gymnasium:my_module:MountainCar-v0", 2, sizes) is None


@pytest.mark.parametrize("env, kind, bounds", [
    (ID, MountainCarStepper, None), (ACROBOT, AcrobotStepper, None),
    (CARTPOLE, CartPoleStepper, CART_BOUNDS)])
def test_the_trainer_picks_it_and_gets_the_gym_run_bit_for_bit(env, kind, bounds):
    config = TrainConfig(agent="flat", env=env, runs=4, episodes=4, seed=3, obs_bounds=bounds)
    batched = PopulationTrainer(config)
    assert isinstance(batched.stepper, kind)
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


@pytest.mark.parametrize("env", [ID, ACROBOT])
def test_a_run_on_it_resumes_bit_for_bit(tmp_path, env):
    # (Acrobot's episodes are cut at 150 steps: 500 each took most of a minute, and a restart
    # on a time limit is resumed the same way)
    config = TrainConfig(agent="skill-chaining", env=env, runs=3, episodes=6, seed=2,
                         checkpoint_every=3, max_episode_steps=150)  # fmt: skip
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
