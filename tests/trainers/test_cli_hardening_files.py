"""Issue 17 C: bad input to ``skillchain`` ends in one clear error line (exit 2, no traceback)
naming the flag, field or file and what it must be, or in correct results; never in silently
wrong data, and never leaving anything that refuses the corrected command.

This file: the files (the output directory, a full disk, a corrupt ``config.json`` on
``--resume``, bad arrays for ``summarize``, what a refused command leaves behind);
``test_cli_hardening.py``: the arguments. The simulated full disk calls ``main`` in-process.
"""

import errno
import json
import threading
from pathlib import Path

import numpy as np
import pytest
import torch
from cli_errors import TINY, error_line, main_refused, refused, run_cli

from skillchain_torch.trainers.config.cli import main


# 5. output directories -----------------------------------------------------------------------
def _unwritable_parent(tmp_path) -> Path:
    """A directory in which no directory can be created: mode 0o555, or, as root (whom
    permissions do not bind), the kernel's /sys."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        (ro / "probe").mkdir()
    except OSError:
        return ro
    (ro / "probe").rmdir()
    try:
        Path("/sys/skillchain-probe").mkdir()
    except OSError:
        return Path("/sys")
    Path("/sys/skillchain-probe").rmdir()
    pytest.skip("running as root, and no directory refuses root's writes (not even /sys)")


def test_unwritable_out_is_refused(tmp_path):
    parent = _unwritable_parent(tmp_path)
    out = parent / "skillchain-run"
    line = refused(run_cli("train", *TINY, "--out", out), f"--out {out}: ")
    assert "not writable" in line or "cannot write there" in line
    assert not out.exists()


def test_out_under_a_regular_file_is_refused(tmp_path):
    (tmp_path / "afile").write_text("x")
    refused(run_cli("train", *TINY, "--out", "afile/sub", cwd=tmp_path),
            "--out afile/sub:", "afile is a file, so no directory can be created under it")
    assert (tmp_path / "afile").read_text() == "x"


def _train_on_a_full_disk(monkeypatch, capsys, module, name, failure, argv) -> str:
    """Run ``main(argv)`` with ``module.name`` raising ``failure``; its one error line."""
    def full(*args, **kwargs):
        raise failure

    with monkeypatch.context() as patch:
        patch.setattr(module, name, full)
        with pytest.raises(SystemExit) as info:
            main(argv)
    assert info.value.code == 2
    return error_line(capsys.readouterr().err)


@pytest.mark.parametrize("failure", [
    RuntimeError("[enforce fail at inline_container.cc:664] . unexpected pos 64 vs 0 "
                 "PytorchStreamWriter failed writing file data/0: file write failed"),
    OSError(errno.ENOSPC, "No space left on device"),
])
def test_a_full_disk_at_the_first_checkpoint_fails_clearly_and_leaves_nothing(
        tmp_path, capsys, monkeypatch, failure):
    out = tmp_path / "run"
    argv = ["train", *TINY, "--out", str(out)]
    before = set(threading.enumerate())
    line = _train_on_a_full_disk(monkeypatch, capsys, torch, "save", failure, argv)
    assert f"cannot write the run's outputs in {out}" in line
    assert "No space left on device" in line or "PytorchStreamWriter failed" in line
    assert "nothing to resume" in line
    assert not out.exists()  # the same command works once there is space
    # the TensorBoard writer's thread, left running, could write into ``out`` as it is removed
    assert not [t for t in set(threading.enumerate()) - before
                if type(t).__name__ == "_AsyncWriterThread" and t.is_alive()]
    assert main(argv) == 0 and np.load(out / "returns.npy").shape == (1, 1)


def test_a_full_disk_after_the_checkpoint_points_to_resume(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    argv = ["train", *TINY, "--out", str(out)]
    failure = OSError(errno.ENOSPC, "No space left on device", str(out / "returns.npy"))
    line = _train_on_a_full_disk(monkeypatch, capsys, np, "save", failure, argv)
    assert "No space left on device" in line and f"train --resume {out}" in line
    assert not (out / "returns.npy").exists()
    assert main(["train", "--resume", str(out), "--quiet"]) == 0
    assert np.load(out / "returns.npy").shape == (1, 1)


# 6. a corrupt config.json on --resume --------------------------------------------------------
def _copy_run(finished_run, run: Path, **changes) -> Path:
    (run / "checkpoints").mkdir(parents=True)
    for path in ("config.json", "checkpoints/ckpt_000001.pt"):
        (run / path).write_bytes((finished_run / path).read_bytes())
    data = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**data, **changes}))
    return run


def test_resume_of_a_config_with_a_wrong_type_names_the_file_and_field(finished_run, tmp_path):
    run = _copy_run(finished_run, tmp_path / "run", runs="two")
    refused(run_cli("train", "--resume", run),
            f"{run / 'config.json'}: runs must be an integer, got 'two'")


@pytest.mark.parametrize(("field", "value", "message"), [
    ("runs", [1, 2], "runs must be an integer, got [1, 2]"),
    ("runs", 1.0, "runs must be an integer, got 1.0"),
    ("alpha", "fast", "alpha must be a number or null, got 'fast'"),
    ("scale_step_size", "yes", "scale_step_size must be true or false, got 'yes'"),
    ("seed", -5, "seed must be in [0, 9223372036854775807]"),
    ("device", "cuda:77", "device 'cuda:77' is not available"),
])
def test_resume_of_a_config_with_a_wrong_value(finished_run, tmp_path, capsys, field, value,
                                               message):
    run = _copy_run(finished_run, tmp_path / "run", **{field: value})
    main_refused(capsys, ["train", "--resume", run], f"{run / 'config.json'}: {message}")


# 7. summarize of bad arrays ------------------------------------------------------------------
def _write_arrays(directory: Path, returns, lengths=None) -> Path:
    np.save(directory / "lengths.npy",
            np.ones((2, 3), dtype=np.int64) if lengths is None else lengths)
    if isinstance(returns, bytes):
        (directory / "returns.npy").write_bytes(returns)
    else:
        np.save(directory / "returns.npy", returns)
    return directory


@pytest.mark.parametrize(("returns", "message"), [
    (np.arange(3.0), "returns.npy: shape (3,); expected a float64 .npy array of shape "
                     "[runs, episodes]"),
    (b"garbage", "returns.npy: not a readable .npy array"),
])
def test_summarize_of_a_bad_returns_file_names_the_file_and_shape(tmp_path, returns, message):
    _write_arrays(tmp_path, returns)
    refused(run_cli("summarize", tmp_path), str(tmp_path / message), command="summarize")


@pytest.mark.parametrize(("returns", "message"), [
    (np.zeros((0, 4)), "returns.npy: shape (0, 4); expected"),
    (np.zeros((2, 2, 2)), "returns.npy: shape (2, 2, 2); expected"),
    (np.array([["a", "b"]]), "returns.npy: holds <U1 values; expected"),
    (np.zeros((2, 5)), "lengths.npy: shape (2, 3) does not match returns.npy's (2, 5)"),
    (np.full((2, 3), np.inf), "returns.npy: holds infinite returns"),
])
def test_summarize_of_other_bad_arrays(tmp_path, capsys, returns, message):
    _write_arrays(tmp_path, returns)
    main_refused(capsys, ["summarize", tmp_path], str(tmp_path / message), command="summarize")


def test_summarize_of_a_good_run_still_works(finished_run, capsys):
    assert main(["summarize", str(finished_run)]) == 0
    assert "runs: 1, episodes: 1" in capsys.readouterr().out


# 8. a refused command leaves nothing behind --------------------------------------------------
def test_a_refused_command_leaves_nothing_that_blocks_the_corrected_one(tmp_path, capsys):
    out = tmp_path / "deep" / "run"
    refused(run_cli("train", *TINY, "--seed", "-1", "--out", out), "--seed")
    assert not (tmp_path / "deep").exists()
    # refused while building the agents, after every argument check passed
    (tmp_path / "garbage.pt").write_bytes(b"garbage")
    main_refused(capsys, ["train", *TINY, "--agent", "given-options", "--options",
                          tmp_path / "garbage.pt", "--out", out], "garbage.pt")
    assert not (tmp_path / "deep").exists()
    # an existing empty --out stays usable
    out.mkdir(parents=True)
    main_refused(capsys, ["train", *TINY, "--device", "bogus", "--out", out], "--device")
    assert list(out.iterdir()) == []
    assert main(["train", *TINY, "--seed", "0", "--out", str(out)]) == 0
    assert np.load(out / "returns.npy").shape == (1, 1)
