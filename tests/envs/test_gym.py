"""The Gymnasium adapter: one registered id per map, passing Gymnasium's checker."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from skillchain_torch.envs.pinball import GYM_IDS

EXPECTED_IDS = {
    "skillchain_torch/Pinball-SimpleSingle-v0",
    "skillchain_torch/Pinball-HardSingle-v0",
    "skillchain_torch/Pinball-HardTwoStarts-v0",
    "skillchain_torch/Pinball-Medium-v0",
    "skillchain_torch/Pinball-Box-v0",
    "skillchain_torch/Pinball-Empty-v0",
}


def test_one_id_per_map():
    assert set(GYM_IDS) == EXPECTED_IDS


@pytest.mark.parametrize("env_id", sorted(EXPECTED_IDS))
def test_check_env_passes(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the checker reports problems as warnings
        env = gym.make(env_id, render_mode="rgb_array")
        check_env(env.unwrapped)
    assert env.observation_space == gym.spaces.Box(0.0, 1.0, (4,), np.float64)
    assert env.action_space == gym.spaces.Discrete(5)
    env.reset(seed=0)
    assert env.render().shape == (400, 400, 3)


def test_seeded_episodes_repeat_and_observations_stay_in_space():
    env = gym.make("skillchain_torch/Pinball-HardTwoStarts-v0", max_episode_steps=300)
    runs = []
    for _ in range(2):
        obs, _ = env.reset(seed=5)
        env.action_space.seed(5)
        trace = [obs]
        done = False
        while not done:
            obs, reward, term, trunc, info = env.step(env.action_space.sample())
            assert env.observation_space.contains(obs)
            assert reward in (-1.0, -5.0, 10000.0)
            trace.append(obs)
            done = term or trunc
        runs.append(np.array(trace))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_invalid_action_raises():
    env = gym.make("skillchain_torch/Pinball-SimpleSingle-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="0..4"):
        env.unwrapped.step(7)
