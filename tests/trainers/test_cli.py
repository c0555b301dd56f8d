"""The ``skillchain`` command line: argument errors, outputs, the seed contract, resume."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from skillchain_torch.trainers.config.cli import main

SMALL = ["--map", "pinball_box", "--episodes", "2", "--max-episode-steps", "300", "--quiet"]


def _fails(argv, capsys, message):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert message in err, err
    return err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--map", "nope"], "unknown map 'nope'; known maps: pinball_box"),
        (["--runs", "0"], "runs must be >= 1, got 0"),
        (["--episodes", "0"], "episodes must be >= 1, got 0"),
        (["--epsilon", "1.5"], "epsilon must be in [0, 1], got 1.5"),
        (["--epsilon", "-0.1"], "epsilon must be in [0, 1]"),
        (["--alpha", "0"], "alpha must be > 0 and finite, got 0.0"),
        (["--alpha", "-1"], "alpha must be > 0"),
        (["--gamma", "1.01"], "gamma must be in [0, 1]"),
        (["--order", "-1"], "order must be >= 0, got -1"),
        (["--max-episode-steps", "0"], "--max-episode-steps: max_episode_steps must be >= 1"),
        (["--checkpoint-every", "-1"], "--checkpoint-every: checkpoint_every must be >= 0"),
        (["--agent", "options"], "invalid choice: 'options'"),
        (["--runs", "two"], "invalid int value: 'two'"),
        (["--threads", "0"], "--threads must be >= 1"),
    ],
)
def test_argument_errors(tmp_path, capsys, argv, message):
    err = _fails(["train", "--out", str(tmp_path / "run"), *argv], capsys, message)
    # one line that names the problem and where help is, not the ~35-line usage above it
    assert err.strip().splitlines() == [err.strip()]
    assert err.startswith("skillchain train: error: ") and "usage:" not in err
    assert not (tmp_path / "run").exists()


def test_missing_out_and_existing_directory(tmp_path, capsys):
    _fails(["train", "--runs", "1"], capsys, "--out DIR is required")
    (tmp_path / "notes.txt").write_text("keep me")
    _fails(["train", "--out", str(tmp_path)], capsys, "exists and is not empty")


def test_resume_errors(tmp_path, capsys):
    _fails(["train", "--resume", str(tmp_path)], capsys, "no config.json there")
    err = _fails(["train", "--resume", str(tmp_path), "--runs", "2"], capsys,
                 "--resume continues with the saved config")
    assert "do not pass --runs" in err


@pytest.fixture(scope="module")
def three_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "three"
    assert main(["train", "--runs", "3", "--seed", "0", "--out", str(out),
                 "--checkpoint-every", "1", *SMALL]) == 0
    return out


def test_outputs_shapes_and_dtypes(three_runs):
    out = three_runs
    returns, lengths = np.load(out / "returns.npy"), np.load(out / "lengths.npy")
    assert returns.dtype == np.float64 and returns.shape == (3, 2)
    assert lengths.dtype == np.int64 and lengths.shape == (3, 2)
    assert (lengths >= 1).all() and (lengths <= 300).all()
    config = json.loads((out / "config.json").read_text())
    assert config["runs"] == 3 and config["order"] == 4 and config["alpha"] == 0.001
    assert config["gamma"] == 1.0 and config["epsilon"] == 0.01
    assert list((out / "tb").rglob("events.out.tfevents.*"))
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == [
        "ckpt_000001.pt", "ckpt_000002.pt"]
    png = (out / "learning_curve.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    info = json.loads((out / "run_info.json").read_text())
    assert info["agent_steps"] == int(lengths.sum()) and info["wall_time_s"] > 0


def test_row_p_equals_run_with_seed_plus_p(three_runs, tmp_path):
    assert main(["train", "--runs", "1", "--seed", "2", "--out", str(tmp_path), *SMALL]) == 0
    assert np.array_equal(np.load(tmp_path / "returns.npy")[0],
                          np.load(three_runs / "returns.npy")[2])
    assert np.array_equal(np.load(tmp_path / "lengths.npy")[0],
                          np.load(three_runs / "lengths.npy")[2])


def test_overwrite_and_resume_of_a_finished_run(three_runs, tmp_path, capsys):
    out = tmp_path / "again"
    argv = ["train", "--runs", "3", "--seed", "0", "--out", str(out), *SMALL]
    assert main(argv) == 0
    assert main([*argv, "--overwrite"]) == 0
    assert np.array_equal(np.load(out / "returns.npy"), np.load(three_runs / "returns.npy"))
    assert main(["train", "--resume", str(out), "--quiet"]) == 0
    assert np.array_equal(np.load(out / "returns.npy"), np.load(three_runs / "returns.npy"))


def test_resume_a_corrupt_checkpoint(three_runs, tmp_path, capsys):
    out = tmp_path / "corrupt"
    (out / "checkpoints").mkdir(parents=True)
    (out / "config.json").write_text((three_runs / "config.json").read_text())
    (out / "checkpoints" / "ckpt_000001.pt").write_bytes(b"garbage")
    _fails(["train", "--resume", str(out)], capsys, "ckpt_000001.pt: not a readable checkpoint")


def test_resume_continues_an_interrupted_run(three_runs, tmp_path):
    """Copy the three-run directory's first checkpoint into a fresh run and resume it."""
    out = tmp_path / "resumed"
    (out / "checkpoints").mkdir(parents=True)
    (out / "config.json").write_text((three_runs / "config.json").read_text())
    first = three_runs / "checkpoints" / "ckpt_000001.pt"
    (out / "checkpoints" / first.name).write_bytes(first.read_bytes())
    assert main(["train", "--resume", str(out), "--quiet"]) == 0
    assert np.array_equal(np.load(out / "returns.npy"), np.load(three_runs / "returns.npy"))
    final = torch.load(out / "checkpoints" / "ckpt_000002.pt", weights_only=True)
    reference = torch.load(three_runs / "checkpoints" / "ckpt_000002.pt", weights_only=True)
    assert torch.equal(final["agent"]["q_head"]["weight"], reference["agent"]["q_head"]["weight"])


def test_summarize(three_runs, capsys, tmp_path):
    assert main(["summarize", str(three_runs)]) == 0
    out = capsys.readouterr().out
    assert "| 1-2 |" in out and "steps per run" in out
    _fails(["summarize", str(tmp_path)], capsys, "not a finished run directory")


def test_console_script_help():
    script = Path(sys.executable).parent / "skillchain"
    env = {**os.environ, "COLUMNS": "100"}
    for argv in ([], ["train"]):
        done = subprocess.run([str(script), *argv, "--help"], capture_output=True, text=True,
                              env=env, timeout=60)
        assert done.returncode == 0, done.stderr
        assert "usage: skillchain" in done.stdout
    assert "--scale-step-size" in done.stdout and "--resume DIR" in done.stdout


def test_torch_only_run_resumes_only_as_torch_only(tmp_path, capsys):
    """--torch-only is recorded in run_info.json, and its checkpoints refuse the other kind."""
    from skillchain_torch.backends import hierarchical as native_hierarchical

    out = tmp_path / "run"
    argv = ["train", "--agent", "skill-chaining", "--slots", "2", "--out", str(out), *SMALL]
    assert main([*argv, "--torch-only"]) == 0
    assert json.loads((out / "run_info.json").read_text())["compiled_agent"] is False
    if native_hierarchical.AVAILABLE:
        _fails(["train", "--resume", str(out), "--quiet"], capsys, "--torch-only")
    assert main(["train", "--resume", str(out), "--quiet", "--torch-only"]) == 0


def test_failure_bootstrap_and_kept_negatives_flags_and_legacy_configs(tmp_path):
    from skillchain_torch.trainers import TrainConfig
    from skillchain_torch.trainers.config.cli import _config_from_args, build_parser

    parser = build_parser()
    args = parser.parse_args(["train", "--agent", "skill-chaining", "--failure-bootstrap",
                              "decision", "--keep-negatives", "off", "--out", str(tmp_path)])
    cfg = _config_from_args(parser, args)
    assert (cfg.failure_bootstrap, cfg.keep_negatives) == ("decision", False)
    default = TrainConfig()
    assert (default.failure_bootstrap, default.keep_negatives) == ("primitives", True)
    # A config saved before the fields existed ran with the old behaviour, whatever the default.
    saved = {k: v for k, v in default.to_dict().items()
             if k not in ("failure_bootstrap", "keep_negatives")}
    old = TrainConfig.from_dict(saved)
    assert (old.failure_bootstrap, old.keep_negatives) == ("decision", False)
    with pytest.raises(ValueError, match="failure_bootstrap must be one of"):
        TrainConfig(failure_bootstrap="optimistic").validate()


@pytest.mark.parametrize("field", ["intra_option_primitives", "option_interruption"])
def test_top_level_learning_flags_reach_the_agent(tmp_path, field):
    from skillchain_torch.agents.skill_chaining_run import SkillChainingRunAgent
    from skillchain_torch.trainers import TrainConfig
    from skillchain_torch.trainers.config.cli import _config_from_args, build_parser

    flag = "--" + field.replace("_", "-")
    parser = build_parser()
    for value, expected in (("on", True), ("off", False)):
        args = parser.parse_args(["train", "--agent", "skill-chaining", "--out", str(tmp_path),
                                  flag, value])
        assert getattr(_config_from_args(parser, args), field) is expected
    assert getattr(TrainConfig(), field) is False
    saved = {k: v for k, v in TrainConfig().to_dict().items() if k != field}
    assert getattr(TrainConfig.from_dict(saved), field) is False  # runs before the field
    cfg = TrainConfig(agent="skill-chaining", runs=2, slots=2, **{field: True}).resolved()
    agent = SkillChainingRunAgent(cfg)
    assert (agent.intra_option_primitives, agent.interruption) == (
        field == "intra_option_primitives", field == "option_interruption")


@pytest.mark.parametrize("value", ["off", "learned", "always"])
def test_end_outside_set_reaches_the_agent(tmp_path, value):
    from skillchain_torch.agents.skill_chaining_run import SkillChainingRunAgent
    from skillchain_torch.trainers import TrainConfig
    from skillchain_torch.trainers.config.cli import _config_from_args, build_parser

    parser = build_parser()
    args = parser.parse_args(["train", "--agent", "skill-chaining", "--out", str(tmp_path),
                              "--end-outside-set", value])
    assert _config_from_args(parser, args).end_outside_set == value
    saved = {k: v for k, v in TrainConfig().to_dict().items() if k != "end_outside_set"}
    assert TrainConfig.from_dict(saved).end_outside_set == "off"  # runs before the field
    cfg = TrainConfig(agent="skill-chaining", runs=2, slots=2, end_outside_set=value).resolved()
    assert SkillChainingRunAgent(cfg).end_outside_set == value


def test_option_start_and_learning_flags_reach_the_config(tmp_path):
    from skillchain_torch.trainers.config.cli import _config_from_args, build_parser

    parser = build_parser()
    args = parser.parse_args(["train", "--agent", "skill-chaining", "--policy-start",
                              "top-level", "--value-start", "agent", "--value-bonus", "3",
                              "--option-alpha", "0", "--completion-reward", "500",
                              "--out", str(tmp_path)])
    cfg = _config_from_args(parser, args)
    assert (cfg.policy_start, cfg.value_start, cfg.value_bonus) == ("top-level", "agent", 3.0)
    assert (cfg.option_alpha, cfg.completion_reward) == (0.0, 500.0)
    with pytest.raises(SystemExit):
        parser.parse_args(["train", "--policy-start", "copy"])


@pytest.mark.parametrize("checkpoint_every", [0, 1])
def test_ctrl_c_says_resume_only_when_a_checkpoint_exists(tmp_path, capsys, monkeypatch,
                                                          checkpoint_every):
    """Ctrl-C after the second episode of three: with a checkpoint behind it the hint is
    --resume, and that resume finishes the run; with none written it says so and --overwrite
    starts again."""
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    train = PopulationTrainer.train

    def interrupted(self, *args, **kwargs):
        def stop(trainer, *rest):
            if trainer.episodes_done.min() >= 2:
                raise KeyboardInterrupt
        self.register_op("post_episodes", stop, name="ctrl_c")
        return train(self, *args, **kwargs)

    out = tmp_path / "run"
    argv = ["train", "--out", str(out), *SMALL, "--episodes", "3",
            "--checkpoint-every", str(checkpoint_every)]
    monkeypatch.setattr(PopulationTrainer, "train", interrupted)
    assert main(argv) == 130
    err = capsys.readouterr().err
    monkeypatch.setattr(PopulationTrainer, "train", train)
    if checkpoint_every:
        assert f"continue with: skillchain train --resume {out}" in err
        assert main(["train", "--resume", str(out), "--quiet"]) == 0
    else:
        assert "nothing to resume" in err and "--resume" not in err
        assert main([*argv, "--overwrite"]) == 0
    assert np.load(out / "returns.npy").shape == (1, 3)


def test_the_commit_is_read_when_the_run_starts(tmp_path, monkeypatch):
    """run_info.json names the code the process runs, not a commit made while it ran."""
    from skillchain_torch.trainers.outputs import run_outputs

    monkeypatch.setattr(run_outputs, "_COMMIT", run_outputs._UNREAD)
    reads = iter(["aaaa", "bbbb"])
    monkeypatch.setattr(run_outputs, "_read_commit", lambda: next(reads))
    out = tmp_path / "run"
    assert main(["train", "--out", str(out), *SMALL]) == 0
    assert json.loads((out / "run_info.json").read_text())["commit"] == "aaaa"


def test_every_subcommand_help_reads_plainly():
    """Each subcommand's help formats: no literal ``%%`` (argparse %-formats help strings, not
    descriptions)."""
    import argparse

    from skillchain_torch.trainers.config.arguments import build_parser

    parser = build_parser()
    [sub] = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    assert {"train", "eval", "plot", "verify"} <= set(sub.choices)
    for name, command in sub.choices.items():
        text = command.format_help()
        assert "%%" not in text, f"skillchain {name} --help shows %%"
