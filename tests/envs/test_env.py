"""PinballEnv: TorchRL contract, seeding, partial resets, truncation, errors."""

import pytest
import torch
from torchrl.envs.utils import check_env_specs

from skillchain_torch.envs.pinball import PinballEnv, load_map, pinball_step


@pytest.mark.parametrize("batch_size", [(), [1], [64]])
def test_check_env_specs(batch_size):
    check_env_specs(PinballEnv(batch_size=batch_size, seed=0, max_episode_steps=30))


def test_keys_shapes_and_dtypes():
    env = PinballEnv(batch_size=[3], seed=0)
    td = env.rollout(4)
    assert td["state"].dtype == torch.float64 and td["state"].shape == (3, 4, 4)
    assert td["action"].dtype == torch.int64 and td["action"].shape == (3, 4)
    for key in ("reward", "done", "terminated", "truncated"):
        assert td["next", key].shape == (3, 4, 1)
    state = td["next", "state"]
    obs = td["next", "observation"]
    assert torch.equal(obs[..., :2], state[..., :2])
    assert torch.equal(obs[..., 2:], (state[..., 2:] + 1.0) / 2.0)


def test_step_matches_pure_function():
    env = PinballEnv("pinball_hard_single", batch_size=[5], seed=3)
    env.reset_raw()
    state = env.state
    action = torch.tensor([0, 1, 2, 3, 4])
    _, reward, terminated, _ = env.step_raw(action)
    expected = pinball_step(state, action, load_map("pinball_hard_single"))
    assert torch.equal(env.state, expected[0]) and torch.equal(reward, expected[1])


def test_environment_i_equals_single_env_with_seed_plus_i():
    batch = PinballEnv("pinball_hard_two_starts", batch_size=[6], seed=10, max_episode_steps=3)
    singles = [
        PinballEnv("pinball_hard_two_starts", batch_size=[1], seed=10 + i, max_episode_steps=3)
        for i in range(6)
    ]
    batch.reset_raw()
    for s in singles:
        s.reset_raw()
    gen = torch.Generator().manual_seed(0)
    for _ in range(20):  # several truncations and resets
        action = torch.randint(0, 5, (6,), generator=gen)
        _, _, term, trunc = batch.step_raw(action)
        for i, s in enumerate(singles):
            s.step_raw(action[i : i + 1])
            assert torch.equal(batch.state[i], s.state[0])
        batch.reset_raw(term | trunc)
        for i, s in enumerate(singles):
            if bool(term[i] | trunc[i]):
                s.reset_raw()


def test_starts_drawn_uniformly():
    env = PinballEnv("pinball_hard_two_starts", batch_size=[2000], seed=0)
    x = env.reset()["state"][:, 0]
    left = (x == 0.055).double().mean().item()
    assert set(x.tolist()) == {0.055, 0.945}
    assert 0.45 < left < 0.55
    assert torch.equal(env.reset()["state"][:, 1], torch.full((2000,), 0.95, dtype=torch.float64))


def test_same_seed_same_starts_different_seed_differs():
    a = PinballEnv("pinball_hard_two_starts", batch_size=[64], seed=1).reset()["state"]
    b = PinballEnv("pinball_hard_two_starts", batch_size=[64], seed=1).reset()["state"]
    c = PinballEnv("pinball_hard_two_starts", batch_size=[64], seed=2).reset()["state"]
    assert torch.equal(a, b) and not torch.equal(a, c)


def test_partial_reset_only_touches_masked_envs():
    env = PinballEnv(batch_size=[4], seed=0)
    td = env.reset()
    for _ in range(5):
        td["action"] = torch.tensor([0, 1, 2, 3])
        td = env.step(td)["next"]
    before = env.state
    mask = torch.tensor([True, False, True, False])
    td["_reset"] = mask[:, None]
    after = env.reset(td)["state"]
    assert torch.equal(after[~mask], before[~mask])
    assert torch.equal(after[mask][:, 2:], torch.zeros(2, 2, dtype=torch.float64))
    assert torch.equal(after[mask][:, :2], torch.tensor([[0.2, 0.9]] * 2, dtype=torch.float64))
    assert env.step_count.tolist() == [0, 5, 0, 5]


def test_truncation_after_max_episode_steps():
    env = PinballEnv(batch_size=[2], seed=0, max_episode_steps=3)
    env.reset_raw()
    truncated = [env.step_raw(torch.tensor([4, 4]))[3].tolist() for _ in range(3)]
    assert truncated == [[False, False], [False, False], [True, True]]
    td = PinballEnv(batch_size=[2], seed=0, max_episode_steps=3).rollout(10)
    assert td.shape == (2, 3) and td["next", "done"][:, -1].all()


def test_goal_terminates_and_pays():
    env = PinballEnv(batch_size=[1], seed=0)
    env.set_state(torch.tensor([[0.9 - 0.045, 0.2, 1.0, 0.0]], dtype=torch.float64))
    _, reward, terminated, truncated = env.step_raw(torch.tensor([0]))
    assert terminated.item() and reward.item() == 10000.0 and not truncated.item()


@pytest.mark.parametrize(
    "action, error",
    [
        (torch.tensor([5, 0]), r"action\[0\] = 5 is out of range"),
        (torch.tensor([0, -2]), r"action\[1\] = -2 is out of range"),
        (torch.tensor([0.0, 1.0]), "integer"),
        (torch.tensor([0, 1, 2]), "shape"),
    ],
)
def test_bad_actions_raise(action, error):
    env = PinballEnv(batch_size=[2], seed=0)
    env.reset_raw()
    with pytest.raises(ValueError, match=error):
        env.step_raw(action)


def test_bad_state_and_arguments_raise():
    env = PinballEnv(batch_size=[1], seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.set_state(torch.tensor([[0.5, float("inf"), 0.0, 0.0]]))
    with pytest.raises(ValueError, match="shape"):
        env.set_state(torch.zeros(2, 4))
    with pytest.raises(ValueError, match="max_episode_steps"):
        PinballEnv(max_episode_steps=0)
    with pytest.raises(ValueError, match="unknown map|known"):
        PinballEnv("pinball_nowhere")


def test_float32_and_device_arguments():
    env = PinballEnv(batch_size=[2], seed=0, dtype=torch.float32, device="cpu")
    td = env.rollout(3)
    assert td["state"].dtype == torch.float32 and td.device == torch.device("cpu")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_cuda_matches_cpu():
    cpu = PinballEnv(batch_size=[16], seed=0)
    gpu = PinballEnv(batch_size=[16], seed=0, device="cuda")
    cpu.reset_raw()
    gpu.reset_raw()
    gen = torch.Generator().manual_seed(0)
    for _ in range(200):
        a = torch.randint(0, 5, (16,), generator=gen)
        cpu.step_raw(a)
        gpu.step_raw(a.cuda())
    torch.testing.assert_close(gpu.state.cpu(), cpu.state, rtol=0, atol=1e-9)


def test_render_frame_shape():
    env = PinballEnv(batch_size=[2], seed=0)
    env.reset_raw()
    frame = env.render(1, size=64)
    assert frame.shape == (64, 64, 3) and frame.dtype.name == "uint8"
