"""ActiveEnvStepper steps a subset of environments exactly as PinballEnv.step_raw does."""

import doctest

import pytest
import torch

from skillchain_torch.envs.pinball import PinballEnv, physics
from skillchain_torch.envs.pinball import native as native_module
from skillchain_torch.envs.pinball import stepper as stepper_module
from skillchain_torch.envs.pinball.stepper import ActiveEnvStepper


def test_doctests():
    assert doctest.testmod(stepper_module).failed == 0


@pytest.mark.parametrize("native", sorted({False, native_module.AVAILABLE}))
@pytest.mark.parametrize("limit", [None, 25])
def test_matches_step_raw_with_resets_and_compaction(native, limit, monkeypatch):
    """A reference env stepped in full with step_raw; the stepper drops rows as it goes.

    The reference steps through the tensor physics, so each stepper path is compared with it.
    """
    monkeypatch.setattr(physics, "NATIVE", False)
    P, map_name = 6, "pinball_box"
    ref = PinballEnv(map_name, batch_size=[P], seed=4, max_episode_steps=limit)
    env = PinballEnv(map_name, batch_size=[P], seed=4, max_episode_steps=limit)
    stepper = ActiveEnvStepper(env, native=native)
    gen = torch.Generator().manual_seed(0)
    assert torch.equal(stepper.start(), ref.reset_raw())
    for t in range(300):
        action = torch.randint(0, 5, (P,), generator=gen)
        obs_r, reward_r, term_r, trunc_r = ref.step_raw(action)
        index = stepper.index
        obs, reward, ends = stepper.step(action[index])
        assert torch.equal(obs, obs_r[index]) and torch.equal(reward, reward_r[index])
        ended_r = (term_r | trunc_r)[index]
        if ends is None:
            assert not ended_r.any()
        else:
            assert torch.equal(ends[0], term_r[index]) and torch.equal(ends[1], trunc_r[index])
        # restart ended rows in both; every 40 steps retire the first active env
        if ended_r.any():
            rows = ended_r.nonzero().flatten()
            mask = torch.zeros(P, dtype=torch.bool)
            mask[index[rows]] = True
            start_r = ref.reset_raw(mask)
            assert torch.equal(stepper.reset(rows), start_r[index[rows]])
        if t % 40 == 39 and stepper.num_active > 1:
            keep = torch.ones(stepper.num_active, dtype=torch.bool)
            keep[0] = False
            stepper.compact(keep)
    stepper.sync()
    index = stepper.index
    assert torch.equal(env.state[index], ref.state[index])
    assert torch.equal(env.step_count[index], ref.step_count[index])


def test_state_dict_round_trip_restores_env():
    env = PinballEnv("pinball_simple_single", batch_size=[3], seed=1, max_episode_steps=50)
    stepper = ActiveEnvStepper(env)
    stepper.start()
    for _ in range(7):
        stepper.step(torch.tensor([0, 1, 4]))
    stepper.compact(torch.tensor([True, False, True]))
    state = stepper.state_dict()
    env2 = PinballEnv("pinball_simple_single", batch_size=[3], seed=99, max_episode_steps=50)
    other = ActiveEnvStepper(env2)
    other.load_state_dict(state)
    assert env2.seed == 1 and other.index.tolist() == [0, 2]
    assert torch.equal(env2.state, env.state)
    assert torch.equal(env2.step_count, env.step_count)
    a = torch.tensor([2, 3])
    first, second = stepper.step(a), other.step(a)
    assert torch.equal(first[0], second[0]) and torch.equal(first[1], second[1])
