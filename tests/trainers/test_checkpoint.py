"""Checkpoints: an interrupted and resumed run is bit-identical; bad files fail clearly."""

import doctest

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skillchain_torch.trainers import (
    PopulationTrainer,
    TrainConfig,
    latest_checkpoint,
    load_checkpoint,
)
from skillchain_torch.trainers.outputs import checkpoint as checkpoint_module
from skillchain_torch.trainers.outputs.checkpoint import (
    DamagedCheckpoint,
    payload_digest,
    read_checkpoint,
    resume_checkpoint,
)

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


# ---------------------------------------------------------------- integrity (issue 17)
def _flip_in_returns(path, bit=0x40):
    """Alter one byte of the stored returns: torch still reads the file, with other numbers."""
    data = bytearray(path.read_bytes())
    returns = torch.load(path, weights_only=True)["trainer"]["returns"]
    at = data.find(returns.numpy().tobytes())
    assert at > 0
    data[at + 3] ^= bit
    path.write_bytes(bytes(data))
    altered = torch.load(path, weights_only=True)["trainer"]["returns"]
    assert not torch.equal(altered, returns)  # loads silently without the digest


def test_checkpoint_holds_a_digest_of_its_contents(straight):
    out, _ = straight
    state = torch.load(out / "checkpoints" / "ckpt_000004.pt", weights_only=True)
    assert state["sha256"] == payload_digest(state)
    assert isinstance(read_checkpoint(out / "checkpoints" / "ckpt_000004.pt")["config"],
                      TrainConfig)


def test_altered_checkpoint_fails_its_checksum(straight, tmp_path):
    out, _ = straight
    path = tmp_path / "ckpt_000004.pt"
    path.write_bytes((out / "checkpoints" / "ckpt_000004.pt").read_bytes())
    _flip_in_returns(path)
    with pytest.raises(DamagedCheckpoint, match=r"ckpt_000004.pt: checksum mismatch .* "
                                                r"altered or damaged"):
        load_checkpoint(path, PopulationTrainer(CFG))
    edited = _edited(straight, tmp_path, lambda s: s["trainer"]["returns"].mul_(2))
    with pytest.raises(DamagedCheckpoint, match="edited.pt: checksum mismatch"):
        read_checkpoint(edited)


def test_checkpoint_without_digest_still_loads(straight, tmp_path):
    """Checkpoints of published runs have no sha256; they load (unverified) and resume."""
    _, reference = straight
    path = _edited(straight, tmp_path, lambda s: s.pop("sha256"))
    resumed = PopulationTrainer(CFG)
    load_checkpoint(path, resumed)
    resumed.train()
    assert np.array_equal(resumed.returns, reference.returns)


def _run_dir(straight, tmp_path, names):
    out, _ = straight
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    for name in names:
        (run / "checkpoints" / name).write_bytes((out / "checkpoints" / name).read_bytes())
    return run / "checkpoints"


@pytest.mark.parametrize("damage", ["flip", "truncate"])
def test_resume_takes_the_previous_good_checkpoint(straight, tmp_path, caplog, damage):
    _, reference = straight
    ckpts = _run_dir(straight, tmp_path, ["ckpt_000002.pt", "ckpt_000004.pt"])
    latest = ckpts / "ckpt_000004.pt"
    if damage == "flip":
        _flip_in_returns(latest)
    else:
        latest.write_bytes(latest.read_bytes()[:5000])
    damaged_bytes = latest.read_bytes()
    trainer = PopulationTrainer(CFG, out_dir=ckpts.parent)
    with caplog.at_level("WARNING"):
        assert resume_checkpoint(ckpts.parent, trainer).name == "ckpt_000002.pt"
    assert "ckpt_000004.pt" in caplog.text and "previous good checkpoint ckpt_000002.pt" \
        in caplog.text
    # Nothing lost: the damaged file is kept aside, the good one untouched.
    assert (ckpts / "ckpt_000004.pt.damaged").read_bytes() == damaged_bytes
    trainer.train()
    assert np.array_equal(trainer.returns, reference.returns)
    assert sorted(p.name for p in ckpts.iterdir()) == [
        "ckpt_000002.pt", "ckpt_000004.pt", "ckpt_000004.pt.damaged", "ckpt_000006.pt"]
    read_checkpoint(ckpts / "ckpt_000004.pt")  # rewritten, verified


def test_resume_with_no_good_checkpoint_names_the_latest(straight, tmp_path):
    ckpts = _run_dir(straight, tmp_path, ["ckpt_000002.pt", "ckpt_000004.pt"])
    for path in ckpts.iterdir():
        _flip_in_returns(path)
    with pytest.raises(ValueError, match=r"ckpt_000004.pt: checksum mismatch.*; no earlier "
                                         r"checkpoint verifies either"):
        resume_checkpoint(ckpts.parent, PopulationTrainer(CFG))
    assert sorted(p.name for p in ckpts.iterdir()) == ["ckpt_000002.pt", "ckpt_000004.pt"]


def test_resume_does_not_fall_back_over_another_config(straight, tmp_path):
    ckpts = _run_dir(straight, tmp_path, ["ckpt_000002.pt", "ckpt_000004.pt"])
    other = PopulationTrainer(TrainConfig(**{**CFG.to_dict(), "seed": 3}))
    with pytest.raises(ValueError, match=r"ckpt_000004.pt: config field 'seed'"):
        resume_checkpoint(ckpts.parent, other)


def test_a_checkpoint_that_does_not_read_back_replaces_nothing(straight, tmp_path, monkeypatch):
    ckpts = _run_dir(straight, tmp_path, ["ckpt_000002.pt"])
    before = (ckpts / "ckpt_000002.pt").read_bytes()
    trainer = PopulationTrainer(CFG, out_dir=ckpts.parent)
    load_checkpoint(ckpts / "ckpt_000002.pt", trainer)

    def unreadable(path):
        raise DamagedCheckpoint(f"{path}: simulated bad write")

    monkeypatch.setattr(checkpoint_module, "read_checkpoint", unreadable)
    with pytest.raises(OSError, match="does not read back .* the earlier checkpoints are kept"):
        checkpoint_module.save_checkpoint(trainer, ckpts / "ckpt_000002.pt")
    assert (ckpts / "ckpt_000002.pt").read_bytes() == before
    assert sorted(p.name for p in ckpts.iterdir()) == ["ckpt_000002.pt"]


def test_a_failed_write_leaves_no_partial_file(straight, tmp_path, monkeypatch):
    ckpts = _run_dir(straight, tmp_path, ["ckpt_000002.pt"])
    trainer = PopulationTrainer(CFG, out_dir=ckpts.parent)
    load_checkpoint(ckpts / "ckpt_000002.pt", trainer)

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(torch, "save", full)
    with pytest.raises(OSError, match="No space left"):
        checkpoint_module.save_checkpoint(trainer, ckpts / "ckpt_000004.pt")
    assert sorted(p.name for p in ckpts.iterdir()) == ["ckpt_000002.pt"]


def _read_outcome(path, original: dict | None) -> None:
    """``read_checkpoint`` gives a one-line ValueError naming the file, or the original."""
    try:
        state = read_checkpoint(path)
    except ValueError as error:
        text = str(error)
        assert text.startswith(f"{path}: ") and "\n" not in text and len(text) < 600, text
        return
    assert original is not None, "random bytes read as a checkpoint"
    state["config"] = state["config"].to_dict()
    assert payload_digest(state) == payload_digest(original)


_FUZZ = settings(max_examples=40, deadline=None,
                 suppress_health_check=[HealthCheck.function_scoped_fixture])


@_FUZZ
@given(data=st.binary(max_size=4096))
def test_fuzz_checkpoint_reader_on_random_bytes(tmp_path, data):
    path = tmp_path / "ckpt_000001.pt"
    path.write_bytes(data)
    _read_outcome(path, None)


@_FUZZ
@given(cut=st.integers(min_value=0, max_value=1 << 30),
       flips=st.lists(st.tuples(st.integers(min_value=0, max_value=1 << 30),
                                st.integers(min_value=1, max_value=255)), max_size=4))
def test_fuzz_checkpoint_reader_on_corrupted_files(straight, tmp_path, cut, flips):
    out, _ = straight
    good = out / "checkpoints" / "ckpt_000002.pt"
    original = torch.load(good, weights_only=True)
    data = bytearray(good.read_bytes())
    for at, mask in flips:
        data[at % len(data)] ^= mask
    if cut % 3 == 0:
        del data[cut % len(data):]
    path = tmp_path / "ckpt_000002.pt"
    path.write_bytes(bytes(data))
    _read_outcome(path, original)


def test_checkpoints_by_the_clock_change_no_bit_and_resume_bit_for_bit(tmp_path):
    """checkpoint_minutes writes checkpoints between episode counts (here at every batch that
    ends an episode, the clock's threshold at 0.0001 minutes): the run is the same, and one
    interrupted after such a checkpoint resumes to the same arrays."""
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint, load_checkpoint

    def config(minutes):
        return TrainConfig(agent="skill-chaining", map="pinball_box", runs=3, episodes=4,
                           seed=5, max_episode_steps=200, gestation=1, checkpoint_every=0,
                           checkpoint_minutes=minutes)  # fmt: skip

    reference = PopulationTrainer(config(0.0), out_dir=tmp_path / "plain").train()
    assert sorted(p.name for p in (tmp_path / "plain" / "checkpoints").glob("*.pt")) == [
        "ckpt_000004.pt"]  # the final one only

    class Stop(Exception):
        pass

    seen = []

    def stop_at_third(trainer, path):
        seen.append(path)
        if len(seen) == 3:
            raise Stop

    clocked = PopulationTrainer(config(1e-4), out_dir=tmp_path / "clocked")
    clocked.register_op("post_checkpoint", stop_at_third)
    with pytest.raises(Stop):
        clocked.train()
    assert int(clocked.episodes_done.min()) < 4  # stopped mid-run, between episode counts
    resumed = PopulationTrainer(config(1e-4), out_dir=tmp_path / "clocked")
    load_checkpoint(latest_checkpoint(tmp_path / "clocked"), resumed)
    resumed.train()
    assert np.array_equal(resumed.returns, reference.returns)
    assert np.array_equal(resumed.lengths, reference.lengths)
    whole = PopulationTrainer(config(1e-4), out_dir=tmp_path / "whole").train()
    assert np.array_equal(whole.returns, reference.returns)
