"""The physics against the original Java implementation, and its own invariants."""

import doctest

import numpy as np
import pytest
import torch

from skillchain_torch.envs.pinball import (
    collisions,
    load_map,
    native,
    physics,
    pinball_step,
    pinball_step_events,
)

VECTOR_FILES = [
    "pinball_simple_single_uniform_s0_k0_stop.npz",
    "pinball_simple_single_uniform_s1_k0_stop.npz",
    "pinball_simple_single_uniform_s2_k0_stop.npz",
    "pinball_hard_single_uniform_s0_k0_stop.npz",
    "pinball_simple_single_goal_mpc_k0_stop.npz",
]


def test_doctests():
    for module in (physics, collisions):
        assert doctest.testmod(module).failed == 0


@pytest.fixture(params=["native", "tensor"])
def path(request, monkeypatch):
    """Run a test through the compiled step and the tensor path."""
    if request.param == "native" and not native.AVAILABLE:
        pytest.skip("the compiled step was not built (no C compiler at install time)")
    monkeypatch.setattr(physics, "NATIVE", request.param == "native")
    return request.param


@pytest.mark.parametrize("name", VECTOR_FILES)
def test_reproduces_java_trajectory(name, vectors_dir, path):
    """One ball through each path."""
    ref = np.load(vectors_dir / name)
    m = load_map(str(ref["config"]))
    state = torch.tensor(ref["states"][:1])
    for t, a in enumerate(ref["actions"]):
        state, reward, terminated, events = pinball_step_events(state, torch.tensor([a]), m)
        np.testing.assert_allclose(
            state[0].numpy(),
            ref["states"][t + 1],
            rtol=0,
            atol=1e-9,
            err_msg=f"{name}: state after step {t}",
        )
        assert reward.item() == ref["rewards"][t], f"{name}: reward at step {t}"
        assert terminated.item() == ref["terminal"][t], f"{name}: terminal at step {t}"
        assert events[0].tolist() == ref["events"][t].tolist(), f"{name}: events at step {t}"


@pytest.mark.parametrize("config", ["pinball_simple_single", "pinball_hard_single"])
def test_reproduces_java_trajectories_as_one_batch(config, vectors_dir, monkeypatch):
    """The tensor path: a map's files stepped together (each ball idles once its file ends)."""
    monkeypatch.setattr(physics, "NATIVE", False)
    refs = [np.load(vectors_dir / n) for n in VECTOR_FILES if n.startswith(config + "_")]
    m = load_map(config)
    state = torch.tensor(np.stack([r["states"][0] for r in refs]))
    for t in range(max(len(r["actions"]) for r in refs)):
        live = [t < len(r["actions"]) for r in refs]
        action = torch.tensor([r["actions"][t] if ok else 4 for r, ok in zip(refs, live)])
        state = pinball_step(state, action, m)[0]
        for i, r in enumerate(refs):
            if live[i]:
                np.testing.assert_allclose(state[i].numpy(), r["states"][t + 1], atol=1e-9)


@pytest.mark.parametrize(
    "map_name",
    ["pinball_simple_single", "pinball_hard_two_starts", "pinball_medium", "pinball_box"],
)
def test_native_and_tensor_paths_are_bit_identical(map_name):
    """A ball's trajectory does not depend on the batch it is in (population contract)."""
    m = load_map(map_name)
    gen = torch.Generator().manual_seed(7)
    batch = 32
    state = torch.cat(
        [
            m.starts[torch.randint(0, m.starts.shape[0], (batch,), generator=gen)],
            torch.zeros(batch, 2, dtype=torch.float64),
        ],
        dim=-1,
    )
    state[:, :2] += (torch.rand(batch, 2, generator=gen, dtype=torch.float64) - 0.5) * 0.02
    total_events = torch.zeros(4, dtype=torch.long)
    for _ in range(200):
        action = torch.randint(0, 5, (batch,), generator=gen)
        batched = physics._step(state, action, m, True, compiled=False)
        alone = [
            physics._step(state[i : i + 1], action[i : i + 1], m, True, compiled=False)
            for i in range(0, batch, 13)
        ]
        if native.AVAILABLE:  # the compiled step, whole batch and one ball
            for x, y in zip(batched, physics._step_native(state, action, m)):
                assert torch.equal(x, y)
            for x, y in zip(batched, physics._step_native(state[5:6], action[5:6], m)):
                assert torch.equal(x[5:6], y)
        for k, i in enumerate(range(0, batch, 13)):
            for x, y in zip(batched, alone[k]):
                assert torch.equal(x[i : i + 1], y)
        total_events += batched[3].sum(0)
        state = batched[0].clone()
        done = batched[2]
        state[done] = torch.cat([m.starts[0], torch.zeros(2, dtype=torch.float64)])
    assert total_events[0] > 100 and total_events[1] > 0  # the test exercised bounces


def _one(state, action, map_name):
    m = load_map(map_name)
    s = torch.tensor([state], dtype=torch.float64)
    return pinball_step_events(s, torch.tensor([action]), m)


def test_single_edge_reflection(path):
    # Box obstacle [0.45, 0.55]^2; ball moving +x at y = 0.5 bounces off its left edge.
    state, _, _, events = _one([0.45 - 0.02 - 0.001, 0.5, 1.0, 0.0], 4, "pinball_box")
    assert events[0].tolist() == [1, 0, 0, 0]
    assert state[0, 2].item() == pytest.approx(-0.995)
    assert state[0, 3].item() == pytest.approx(0.0, abs=1e-15)


def test_vertex_contact_reverses_velocity(path):
    # Heading diagonally into the obstacle's corner (0.45, 0.45): both edges touch at once.
    off = 0.02 / np.sqrt(2) + 0.0005
    state, _, _, events = _one([0.45 - off, 0.45 - off, 1.0, 1.0], 4, "pinball_box")
    assert events[0, 1].item() == 1
    assert state[0, 2].item() == pytest.approx(-0.995) and state[0, 3].item() == pytest.approx(
        -0.995
    )


def test_goal_ends_step_without_drag(path):
    # The target of the simple map is (0.9, 0.2), radius 0.04 (ball radius not added).
    state, reward, terminated, _ = _one(
        [0.9 - 0.04 - 0.001, 0.2, 0.8, 0.0], 0, "pinball_simple_single"
    )
    assert terminated.item() and reward.item() == 10000.0
    assert state[0, 2].item() == 1.0  # 0.8 + 0.2, clipped, and no drag on the goal step
    assert state[0, 0].item() < 0.9 - 0.04 + 0.02  # stopped mid-step, at the first substep inside


def test_goal_radius_excludes_ball_radius(path):
    # Centre passes within 0.05 of the target (inside R + r) but never within R = 0.04.
    state, reward, terminated, _ = _one([0.8, 0.2 + 0.05, 1.0, 0.0], 4, "pinball_simple_single")
    assert not terminated.item() and reward.item() == -1.0


def test_out_of_bounds_fallback(path):
    state, reward, _, events = _one([1.2, -0.3, 0.5, 0.5], 4, "pinball_empty")
    assert state[0].tolist() == [0.95, 0.05, 0.0, 0.0]
    assert events[0, 3].item() == 1 and reward.item() == -1.0


def test_rewards_and_clip(path):
    m = load_map("pinball_empty")
    s = torch.tensor([[0.5, 0.5, 0.95, -0.95]] * 5, dtype=torch.float64)
    s1, r, _ = pinball_step(s, torch.arange(5), m)
    assert r.tolist() == [-5.0, -5.0, -5.0, -5.0, -1.0]
    assert s1[0, 2].item() == 0.995  # 0.95 + 0.2 clipped to 1, then drag
    assert s1[3, 3].item() == -0.995


@pytest.mark.parametrize(
    "state, action, match",
    [
        ([[0.5, 0.5, 0.0, 0.0]], [5], r"action\[0\] = 5 is out of range"),
        ([[0.5, 0.5, 0.0, 0.0]], [-1], "out of range"),
        ([[0.5, float("nan"), 0.0, 0.0]], [0], r"state\[0\].*not finite"),
        ([[0.5, 0.5, 0.0]], [0], r"shape \[B, 4\]"),
    ],
)
def test_bad_input_raises(state, action, match, path):
    with pytest.raises(ValueError, match=match):
        pinball_step(
            torch.tensor(state, dtype=torch.float64),
            torch.tensor(action),
            load_map("pinball_empty"),
        )


def test_float_action_raises():
    with pytest.raises(ValueError, match="integer"):
        pinball_step(
            torch.zeros(1, 4, dtype=torch.float64) + 0.5,
            torch.tensor([1.0]),
            load_map("pinball_empty"),
        )


def test_float32_runs_and_stays_close(vectors_dir):
    ref = np.load(vectors_dir / VECTOR_FILES[0])
    m32 = load_map("pinball_simple_single", dtype=torch.float32)
    state = torch.tensor(ref["states"][:1], dtype=torch.float32)
    for a in ref["actions"][:20]:
        state = pinball_step(state, torch.tensor([a]), m32)[0]
    assert state.dtype == torch.float32
    np.testing.assert_allclose(state[0].numpy(), ref["states"][20], atol=1e-4)
