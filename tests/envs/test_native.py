"""The compiled Pinball step against the tensor path it transcribes, bit for bit."""

import doctest
import os

import pytest
import torch

from skillchain_torch.envs.pinball import MAP_NAMES, load_map, native, physics

needs_native = pytest.mark.skipif(
    not native.AVAILABLE, reason="the compiled step was not built (no C compiler at install time)"
)


def test_built_in_ci():
    """CI installs with gcc: a silent fallback to the slow paths there would be a regression."""
    if os.environ.get("CI"):
        assert native.AVAILABLE, "skillchain_torch.envs.pinball._native failed to build"


def test_doctests():
    assert doctest.testmod(native).failed == 0


@needs_native
@pytest.mark.parametrize("map_name", MAP_NAMES)
def test_random_rollouts_match_the_tensor_path(map_name):
    """64 balls anywhere on the board, 600 random actions; every bit and event count agrees
    with the tensor path (the definition)."""
    m = load_map(map_name)
    nb = native.native_board(m)
    gen = torch.Generator().manual_seed(3)
    state = torch.rand(64, 4, generator=gen, dtype=torch.float64)
    state[:, 2:] = state[:, 2:] * 2.0 - 1.0
    ref = state.clone()
    start = torch.tensor([0.2, 0.9, 0.0, 0.0], dtype=torch.float64)
    total = torch.zeros(4, dtype=torch.long)
    for _ in range(600):
        action = torch.randint(0, 5, (64,), generator=gen)
        events = torch.empty(64, 4, dtype=torch.long)
        reward, terminated, n_goal = nb.step(state, action, events=events)
        ref, ref_reward, ref_terminated, ref_events = physics._step(ref, action, m, True,
                                                                    compiled=False)
        assert torch.equal(state, ref) and torch.equal(reward, ref_reward)
        assert torch.equal(terminated, ref_terminated) and torch.equal(events, ref_events)
        assert n_goal == int(terminated.sum())
        state[terminated] = start
        ref = state.clone()
        total += events.sum(0)
    assert total[0] > 100  # the rollouts bounced


@needs_native
def test_observation_output_and_errors():
    nb = native.native_board(load_map("pinball_empty"))
    state = torch.tensor([[0.5, 0.5, 0.3, -0.4], [0.5, 0.5, 0.0, 0.0]], dtype=torch.float64)
    obs = torch.empty(2, 4, dtype=torch.float64)
    reward = torch.empty(2, dtype=torch.float64)
    term = torch.empty(2, dtype=torch.bool)
    nb.step_into(state, torch.tensor([4, 1]), reward, term, obs=obs)
    assert torch.equal(obs[:, :2], state[:, :2])
    assert torch.equal(obs[:, 2:], (state[:, 2:] + 1.0) / 2.0)
    with pytest.raises(ValueError, match=r"action\[1\] = 7 is out of range"):
        nb.step_into(state, torch.tensor([0, 7]), reward, term)
    state[1, 3] = float("inf")
    with pytest.raises(ValueError, match=r"state\[1\].*not finite"):
        nb.step_into(state, torch.tensor([0, 0]), reward, term)


@needs_native
def test_wrong_layout_is_refused_before_the_c_code_reads_it():
    nb = native.native_board(load_map("pinball_empty"))
    reward = torch.empty(2, dtype=torch.float64)
    term = torch.empty(2, dtype=torch.bool)
    state32 = torch.full((2, 4), 0.5)
    with pytest.raises(ValueError, match=r"state must be a contiguous CPU torch.float64"):
        nb.step_into(state32, torch.tensor([0, 1]), reward, term)
    state = torch.full((4, 4), 0.5, dtype=torch.float64)[::2]
    with pytest.raises(ValueError, match="not contiguous"):
        nb.step_into(state, torch.tensor([0, 1]), reward, term)
    with pytest.raises(ValueError, match=r"action must be .*torch.int64 tensor of shape \[2\]"):
        nb.step_into(state.contiguous(), torch.tensor([0, 1], dtype=torch.int32), reward, term)
