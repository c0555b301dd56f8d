"""Checkpoints: an interrupted and resumed run is bit-identical; bad files fail clearly."""

import doctest

import numpy as np
import pytest
import torch

from skillchain_torch.trainers import (
    PopulationTrainer,
    TrainConfig,
    latest_checkpoint,
    load_checkpoint,
)
from skillchain_torch.trainers import checkpoint as checkpoint_module

# Goals and truncations; agent 2 has finished when the slowest completes episode 4.
CFG = TrainConfig(map="pinball_empty", runs=3, episodes=6, seed=0, max_episode_steps=1000,
                  checkpoint_every=2)


class InterruptAfter:
    """post_checkpoint hook raising KeyboardInterrupt at the k-th checkpoint."""

    def __init__(self, k):
        self.k, self.calls, self.active = k, 0, None

    def __call__(self, trainer, path):
        self.calls += 1
        if self.calls == self.k:
            self.active = trainer.num_active
            raise KeyboardInterrupt


def test_doctests():
    assert doctest.testmod(checkpoint_module).failed == 0


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    out = tmp_path_factory.mktemp("straight")
    trainer = PopulationTrainer(CFG, out_dir=out).train()
    return out, trainer


@pytest.mark.parametrize("k", [1, 2])
def test_resume_after_interrupt_is_bit_identical(straight, tmp_path, k):
    _, reference = straight
    interrupted = PopulationTrainer(CFG, out_dir=tmp_path)
    hook = InterruptAfter(k)
    interrupted.register_op("post_checkpoint", hook)
    with pytest.raises(KeyboardInterrupt):
        interrupted.train()
    path = latest_checkpoint(tmp_path)
    assert path.name == f"ckpt_{2 * k:06d}.pt"
    resumed = PopulationTrainer(CFG, out_dir=tmp_path)
    load_checkpoint(path, resumed)
    assert resumed.num_active == hook.active
    resumed.train()
    assert np.array_equal(resumed.returns, reference.returns)
    assert np.array_equal(resumed.lengths, reference.lengths)
    assert torch.equal(resumed.weights, reference.weights)
    assert torch.equal(resumed.agent.rng.counter, reference.agent.rng.counter)
    assert torch.equal(resumed.env.state, reference.env.state)
    assert resumed.agent_steps == reference.agent_steps


def test_some_agents_had_finished_at_the_second_checkpoint(tmp_path):
    """The k=2 resume above covers a checkpoint with a compacted (partly finished) population."""
    trainer = PopulationTrainer(CFG, out_dir=tmp_path)
    hook = InterruptAfter(2)
    trainer.register_op("post_checkpoint", hook)
    with pytest.raises(KeyboardInterrupt):
        trainer.train()
    assert (trainer.episodes_done == 6).any() and hook.active < 3


def test_checkpoints_written_and_final(straight):
    out, trainer = straight
    names = sorted(p.name for p in (out / "checkpoints").glob("*.pt"))
    assert names == ["ckpt_000002.pt", "ckpt_000004.pt", "ckpt_000006.pt"]
    state = torch.load(out / "checkpoints" / "ckpt_000006.pt", weights_only=True)
    assert state["format_version"] == checkpoint_module.FORMAT_VERSION
    assert state["trainer"]["returns"].dtype == torch.float64
    assert state["agent"]["index"].numel() == 0


def test_corrupt_file(tmp_path):
    path = tmp_path / "ckpt_000001.pt"
    path.write_bytes(b"not a checkpoint at all")
    with pytest.raises(ValueError, match="ckpt_000001.pt: not a readable checkpoint"):
        load_checkpoint(path, PopulationTrainer(CFG))
    torch.save({"something": 1}, path)
    with pytest.raises(ValueError, match="ckpt_000001.pt.*'format_version' missing"):
        load_checkpoint(path, PopulationTrainer(CFG))


def _edited(straight, tmp_path, edit):
    out, _ = straight
    state = torch.load(out / "checkpoints" / "ckpt_000002.pt", weights_only=True)
    edit(state)
    path = tmp_path / "edited.pt"
    torch.save(state, path)
    return path


def test_wrong_format_version(straight, tmp_path):
    path = _edited(straight, tmp_path, lambda s: s.update(format_version=99))
    with pytest.raises(ValueError, match=r"edited.pt: field 'format_version' is 99"):
        load_checkpoint(path, PopulationTrainer(CFG))


def test_missing_field(straight, tmp_path):
    path = _edited(straight, tmp_path, lambda s: s["trainer"].pop("returns"))
    with pytest.raises(ValueError, match=r"edited.pt: field 'trainer.returns' is missing"):
        load_checkpoint(path, PopulationTrainer(CFG))


@pytest.mark.parametrize(
    ("field", "value"), [("map", "pinball_box"), ("runs", 2), ("seed", 3), ("alpha", 0.01)]
)
def test_mismatched_config(straight, field, value):
    out, _ = straight
    other = TrainConfig(**{**CFG.to_dict(), field: value})
    with pytest.raises(ValueError, match=rf"ckpt_000002.pt: config field '{field}'"):
        load_checkpoint(out / "checkpoints" / "ckpt_000002.pt", PopulationTrainer(other))


def test_checkpoint_every_may_differ(straight):
    out, reference = straight
    other = PopulationTrainer(TrainConfig(**{**CFG.to_dict(), "checkpoint_every": 5}))
    load_checkpoint(out / "checkpoints" / "ckpt_000004.pt", other)
    other.train()
    assert np.array_equal(other.returns, reference.returns)


def test_latest_checkpoint(tmp_path):
    assert latest_checkpoint(tmp_path) is None
    (tmp_path / "checkpoints").mkdir()
    for n in (2, 10, 4):
        (tmp_path / "checkpoints" / f"ckpt_{n:06d}.pt").write_bytes(b"")
    assert latest_checkpoint(tmp_path).name == "ckpt_000010.pt"
