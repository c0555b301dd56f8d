"""Issue 17 C: bad input to ``skillchain`` ends in one clear error line (exit 2, no traceback)
naming the flag, field or file and what it must be, or in correct results; never in silently
wrong data, and never leaving anything that refuses the corrected command.

This file: the arguments (seeds, flags a run would ignore, sizes, devices) and their fuzz;
``test_cli_hardening_files.py``: the files. The reproducers run the installed console script
in a subprocess; the fuzz calls ``main`` in-process (``cli_errors.py``).
"""

import contextlib
import doctest
import io
import json
import os
import tempfile
from pathlib import Path
from unittest import mock

import cli_errors
import numpy as np
import pytest
import torch
from cli_errors import TINY, error_line, main_refused, refused, run_cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skillchain_torch.trainers.config import config as config_module
from skillchain_torch.trainers.config.cli import main
from skillchain_torch.trainers.config.config import INT64_MAX, ConfigError, TrainConfig
from skillchain_torch.trainers.outputs import run_outputs


def test_cli_errors_doctest():
    assert doctest.testmod(cli_errors).failed == 0


# 1. seeds ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("seed", "message"), [
    (2**64, "got 18446744073709551616"),  # used to wrap around to the streams of seed 0
    (-1, "got -1"),                       # used to die in numpy's SeedSequence
])
def test_seeds_outside_the_int64_streams_are_refused(tmp_path, seed, message):
    out = tmp_path / "run"
    done = run_cli("train", *TINY, "--seed", seed, "--out", out)
    refused(done, f"--seed: seed must be in [0, {INT64_MAX}]", "seed + p", message)
    assert not out.exists()


@pytest.mark.parametrize(("seed", "runs", "top"), [
    (2**63, 1, INT64_MAX),              # used to alias seed -2^63
    (INT64_MAX - 1, 3, INT64_MAX - 2),  # agent 2 would use seed 2^63
])
def test_seed_plus_the_last_agent_must_fit(tmp_path, capsys, seed, runs, top):
    out = tmp_path / "run"
    main_refused(capsys, ["train", *TINY, "--runs", runs, "--seed", seed, "--out", out],
                 f"--seed: seed must be in [0, {top}]", f"runs = {runs}), got {seed}")
    assert not out.exists()


def test_the_largest_seed_trains(tmp_path):
    out = tmp_path / "run"
    assert main(["train", *TINY, "--seed", str(INT64_MAX), "--out", str(out)]) == 0
    assert json.loads((out / "config.json").read_text())["seed"] == INT64_MAX
    returns = np.load(out / "returns.npy")
    assert returns.shape == (1, 1) and np.isfinite(returns).all()


# 2. flags that would be silently ignored ----------------------------------------------------
def test_resume_refuses_out(finished_run, tmp_path):
    before = sorted(p.name for p in finished_run.iterdir())
    done = run_cli("train", "--resume", finished_run, "--out", tmp_path / "elsewhere")
    refused(done, "--resume continues with the saved config", f"writing into {finished_run}",
            "do not pass --out")
    assert not (tmp_path / "elsewhere").exists()
    assert sorted(p.name for p in finished_run.iterdir()) == before


@pytest.mark.parametrize(("extra", "named"), [
    (["--overwrite"], "--overwrite"),
    (["--runs", "2"], "--runs"),
    (["--options", "x.pt", "--quiet"], "--options"),
    (["--out", "y", "--overwrite", "--seed", "3"], "--seed, --out, --overwrite"),
])
def test_resume_refuses_other_flags_it_would_ignore(finished_run, capsys, extra, named):
    main_refused(capsys, ["train", "--resume", finished_run, *extra],
                 "--resume continues with the saved config", f"do not pass {named}")


def test_options_with_a_flat_agent_are_refused(tmp_path):
    (tmp_path / "opt.pt").write_bytes(b"not read")
    out = tmp_path / "run"
    done = run_cli("train", *TINY, "--agent", "flat", "--options", tmp_path / "opt.pt",
                   "--out", out)
    refused(done, "--agent flat does not read --options (only given-options)")
    assert not out.exists()


@pytest.mark.parametrize(("agent", "extra", "named"), [
    ("flat", ["--slots", "3"], "--slots (only skill-chaining)"),
    ("flat", ["--completion-reward", "5"],
     "--completion-reward (only given-options or skill-chaining)"),
    ("skill-chaining", ["--options-agent", "1"], "--options-agent (only given-options)"),
    ("given-options", ["--options", "{tmp}/opt.pt", "--policy-start", "top-level"],
     "--policy-start (only skill-chaining)"),
])
def test_flags_the_agent_does_not_read_are_refused(tmp_path, capsys, agent, extra, named):
    (tmp_path / "opt.pt").write_bytes(b"not read")
    out = tmp_path / "run"
    extra = [a.format(tmp=tmp_path) for a in extra]
    main_refused(capsys, ["train", *TINY, "--agent", agent, *extra, "--out", out],
                 f"--agent {agent} does not read {named}")
    assert not out.exists()


# 3. sizes ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("extra", "fragments"), [
    (["--runs", 10**20], ["--runs: runs must be at most 2^63 - 1", "got 100000000000000000000"]),
    (["--episodes", 10**12], ["--episodes: the run needs an estimated 14.6 TiB of memory",
                              "for runs 1 x episodes 1000000000000",
                              "(returns and lengths [runs, episodes]: 14.6 TiB)",
                              "more than the", "available"]),
])
def test_sizes_that_cannot_fit_are_refused_before_allocating(tmp_path, extra, fragments):
    out = tmp_path / "run"
    refused(run_cli("train", *TINY, *extra, "--out", out), *fragments)
    assert not out.exists()


@pytest.mark.parametrize(("extra", "fragments"), [
    (["--order", 10**20], ["--order: order must be at most 2^63 - 1"]),
    (["--agent", "skill-chaining", "--slots", 10**20], ["--slots: slots must be at most 2^63 - 1"]),
    (["--max-episode-steps", 10**20], ["--max-episode-steps: max_episode_steps must be at most"]),
    (["--runs", 10**9], ["--runs: the run needs", "for runs 1000000000 x order 4", "Q weights"]),
    (["--order", 200], ["--order: the run needs", "for runs 1 x order 200", "Q weights"]),
    (["--agent", "skill-chaining", "--slots", 10**9],
     ["--slots: the run needs", "for runs 1 x slots 1000000000", "option banks"]),
])
def test_other_sizes_that_cannot_fit(tmp_path, capsys, extra, fragments):
    out = tmp_path / "run"
    main_refused(capsys, ["train", *TINY, *extra, "--out", out], *fragments)
    assert not out.exists()


def test_the_memory_check_reads_the_available_memory(monkeypatch):
    config = TrainConfig(map="pinball_box", runs=4, episodes=10)
    config.validate()
    need = sum(t[2] for t in config.memory_estimate())
    monkeypatch.setattr(config_module, "available_memory", lambda device="cpu": need)
    with pytest.raises(ConfigError, match="of memory for .* more than the .* available") as info:
        config.validate()
    assert info.value.fields == ("runs", "order")
    config.validate(memory=False)
    # float64 returns + int64 lengths [2, 3]; weights and features [2, 5 + 1, 2^4] float64
    # and the [2^4, 4] coefficients
    small = TrainConfig(map="pinball_box", runs=2, episodes=3, order=1)
    assert [t[2] for t in small.memory_estimate()] == [2 * 3 * 16, 2 * 6 * 16 * 8 + 16 * 4 * 8]


# 4. devices ----------------------------------------------------------------------------------
def test_an_unknown_device_is_refused(tmp_path):
    out = tmp_path / "run"
    refused(run_cli("train", *TINY, "--device", "bogus", "--out", out),
            "--device: device must be a torch device such as cpu, cuda or cuda:0, got 'bogus'")
    assert not out.exists()


def test_an_absent_cuda_device_is_refused(tmp_path):
    """``cuda`` on a CPU-only torch (on a CUDA machine: one index past the last device)."""
    out = tmp_path / "run"
    absent = f"cuda:{torch.cuda.device_count()}" if torch.cuda.is_available() else "cuda"
    refused(run_cli("train", *TINY, "--device", absent, "--out", out),
            f"--device: device '{absent}' is not available")
    assert not out.exists()


# fuzz ----------------------------------------------------------------------------------------
BIG = [-(2**63) - 1, -1, 0, 2**63 - 1, 2**63, 2**64, 10**20]


FLAGS = {
    "--map": st.sampled_from(["pinball_box", "pinball_nope", ""]),
    "--runs": st.sampled_from([1, 2, 0, 10**9, *BIG]),
    "--episodes": st.sampled_from([1, 2, 0, 10**12, *BIG]),
    "--seed": st.sampled_from([0, 7, *BIG]),
    "--alpha": st.sampled_from(["0.01", "0", "-1", "nan", "inf", "1e400", "x"]),
    "--epsilon": st.sampled_from(["0.5", "1", "1.01", "nan", "-0"]),
    "--gamma": st.sampled_from(["0.9", "1", "2", "nan"]),
    "--order": st.sampled_from([0, 1, 2, -1, 10**5, 10**20]),
    "--max-episode-steps": st.sampled_from([1, 30, 0, -4, 10**20, "1.5"]),
    "--slots": st.sampled_from([1, 2, 0, 10**9, 10**20]),
    "--options": st.sampled_from(["{tmp}/missing.pt", "{tmp}/garbage.pt", "{tmp}"]),
    "--options-agent": st.sampled_from(["0", "each", "-1", "x", str(10**20)]),
    "--initiation-bias": st.sampled_from(["0", "2", "nan"]),
    "--initiation-start": st.sampled_from(["everything", "biased", "fitted", "half"]),
    "--gestation-positives": st.sampled_from([0, 250, -1, 10**20]),
    "--value-bonus": st.sampled_from(["0", "inf"]),
    "--option-alpha": st.sampled_from(["0.0005", "-1", "nan"]),
    "--checkpoint-every": st.sampled_from([0, 1, -1, 10**20]),
    "--device": st.sampled_from(["cpu", "bogus", "cuda:999", "meta", ""]),
    "--threads": st.sampled_from([1, 2, 0, -1, 10**20]),
}


SWITCHES = ["--scale-step-size", "--initiation-centered", "--wait-for-both-classes",
            "--overwrite", "--torch-only"]


@st.composite
def train_argv(draw):
    argv = ["--map", "pinball_box", "--runs", "1", "--episodes", "1", "--max-episode-steps",
            "30"]
    agent = draw(st.sampled_from([None, "flat", "skill-chaining", "skill-chaining",
                                  "given-options", "bogus"]))
    if agent is not None:
        argv += ["--agent", agent]
    names = draw(st.lists(st.sampled_from(sorted(FLAGS)), max_size=3, unique=True))
    for name in names:
        argv += [name, str(draw(FLAGS[name]))]
    argv += draw(st.lists(st.sampled_from(SWITCHES), max_size=2, unique=True))
    resume = draw(st.booleans()) and draw(st.booleans())
    return argv, resume


def _run_main(argv) -> tuple[int, str]:
    err = io.StringIO()
    # (without skill chaining's option figure: its greedy rollouts take ~40 s per run)
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), \
            mock.patch.object(run_outputs, "write_discovery", lambda *args: None):
        try:
            code = main(argv)
        except SystemExit as exit_:
            code = exit_.code
    return code, err.getvalue()


@pytest.mark.slow
@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(train_argv())
def test_fuzzed_train_arguments_end_in_a_clear_error_or_a_correct_run(case):
    argv, resume = case
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "garbage.pt").write_bytes(b"garbage")
        argv = [a.replace("{tmp}", tmp) for a in argv] + ["--quiet"]
        out = Path(tmp) / "run"
        if resume:  # the drawn flags on the resume of a finished run
            assert main(["train", *TINY, "--out", str(out)]) == 0
            before = np.load(out / "returns.npy")
            argv = ["train", "--resume", str(out), *argv[8:]]  # (the TINY flags refused)
        else:
            argv = ["train", *argv, "--out", str(out)]
        code, err = _run_main(argv)
        if code == 0:
            config = json.loads((out / "config.json").read_text())
            returns, lengths = np.load(out / "returns.npy"), np.load(out / "lengths.npy")
            assert returns.shape == lengths.shape == (config["runs"], config["episodes"])
            assert np.isfinite(returns).all() and (lengths >= 1).all()
            assert (lengths <= config["max_episode_steps"]).all()
            if resume:
                assert np.array_equal(returns, before)
            return
        assert code == 2, (argv, code, err)
        line = error_line(err)
        assert "--" in line or ".json" in line or ".pt" in line or "map" in line, line
        if not resume:
            assert not out.exists() or not any(out.iterdir()), (argv, os.listdir(out))
