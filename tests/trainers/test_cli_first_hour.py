"""Issue 54's CLI items a new user hits first: bare Gymnasium ids, ``--obs-bounds`` written as
the error message writes it, ``reproduce --runs`` on both instances, and a labelled progress
bar (tests/trainers/test_logging.py)."""

from __future__ import annotations

import json

from skillchain_torch.trainers import TrainConfig
from skillchain_torch.trainers.config.arguments import build_parser
from skillchain_torch.trainers.config.cli import _attach_values, main
from skillchain_torch.trainers.outputs import checkpoint as checkpoint_module
from skillchain_torch.trainers.study.reproduce import paper_experiments

BOUNDS = "-2.4:2.4,-3:3,-0.21:0.21,-3.5:3.5"


def test_a_bare_gymnasium_id_is_gymnasiums():
    assert TrainConfig(env="CartPole-v1").env == "gymnasium:CartPole-v1"
    assert TrainConfig(env="gymnasium:CartPole-v1").env == "gymnasium:CartPole-v1"
    assert TrainConfig(env="gymnasium:my_module:Thing-v0").env == "gymnasium:my_module:Thing-v0"


def test_obs_bounds_take_a_value_that_starts_with_a_minus(tmp_path):
    assert _attach_values(["train", "--obs-bounds", BOUNDS, "--runs", "2"]) == \
        ["train", f"--obs-bounds={BOUNDS}", "--runs", "2"]
    assert _attach_values(["--runs", "-1"]) == ["--runs", "-1"]  # (only --obs-bounds)
    out = tmp_path / "cp"
    assert main(["train", "--env", "CartPole-v1", "--obs-bounds", BOUNDS, "--runs", "2",
                 "--episodes", "2", "--out", str(out), "--quiet"]) == 0  # fmt: skip
    saved = json.loads((out / "config.json").read_text())
    assert saved["env"] == "gymnasium:CartPole-v1" and saved["obs_bounds"] == BOUNDS


def test_reproduce_runs_apply_to_both_instances_unless_hard_runs_is_given():
    args = build_parser().parse_args(["reproduce", "paper", "--out", "x", "--runs", "2"])
    assert args.hard_runs is None
    runs = {e.config.map: e.config.runs for e in paper_experiments(runs=2, episodes=3)}
    assert set(runs.values()) == {2} and len(runs) == 2
    hard = {e.config.map: e.config.runs for e in paper_experiments(runs=2, episodes=3,
                                                                   hard_runs=5)}  # fmt: skip
    assert sorted(hard.values()) == [2, 5]


def test_config_file_toml_and_a_runs_config_json_with_flags_winning(tmp_path, capsys):
    toml = tmp_path / "run.toml"
    toml.write_text('agent = "skill-chaining"\nruns = 2\nepisodes = 2\nmap = "pinball_box"\n'
                    'max_episode_steps = 200\ngestation = 3\n')  # fmt: skip
    first = tmp_path / "first"
    assert main(["train", "--config", str(toml), "--runs", "3", "--out", str(first),
                 "--quiet"]) == 0  # fmt: skip
    saved = json.loads((first / "config.json").read_text())
    assert (saved["agent"], saved["runs"], saved["episodes"], saved["gestation"]) == \
        ("skill-chaining", 3, 2, 3)  # the flag won, the file gave the rest
    again = tmp_path / "again"
    assert main(["train", "--config", str(first / "config.json"), "--episodes", "3",
                 "--out", str(again), "--quiet"]) == 0  # fmt: skip
    redone = json.loads((again / "config.json").read_text())
    assert redone["episodes"] == 3 and {k: v for k, v in redone.items() if k != "episodes"} \
        == {k: v for k, v in saved.items() if k != "episodes"}
    bad = tmp_path / "bad.toml"
    bad.write_text('agnt = "flat"\n')
    for path, message in ((bad, "unknown field 'agnt'"), (tmp_path / "x.yaml", "expected a .json")):
        try:
            main(["train", "--config", str(path), "--out", str(tmp_path / "no")])
        except SystemExit:
            pass
        err = capsys.readouterr().err.strip()
        assert message in err and err.count("\n") == 0


def test_train_help_groups_its_flags_and_gives_every_default():
    from skillchain_torch.trainers.config.arguments import TRAIN_GROUPS

    train = build_parser().commands["train"]
    titles = [g.title for g in train._action_groups]
    assert [t for t, _, _ in TRAIN_GROUPS] == [t for t in titles if t in dict(
        (t, 1) for t, _, _ in TRAIN_GROUPS)]  # fmt: skip
    left = [a.dest for g in train._action_groups if g.title == "options"
            for a in g._group_actions if a.dest != "help"]
    assert left == [], left  # every flag sits in a named group
    missing = [a.dest for a in train._actions if a.dest != "help" and "default" not in a.help]
    assert missing == [], missing
    assert all("reading:" not in a.help for a in train._actions if a.help)


def test_resume_with_more_episodes_extends_a_finished_run_bit_for_bit(tmp_path, capsys):
    import numpy as np

    base = ["train", "--agent", "skill-chaining", "--map", "pinball_box", "--seed", "4",
            "--max-episode-steps", "400", "--runs", "3", "--checkpoint-every", "2", "--quiet"]
    straight, extended = tmp_path / "six", tmp_path / "four"
    assert main([*base, "--episodes", "6", "--out", str(straight)]) == 0
    assert main([*base, "--episodes", "4", "--out", str(extended)]) == 0
    assert main(["train", "--resume", str(extended), "--episodes", "6", "--quiet"]) == 0
    for name in ("returns.npy", "lengths.npy", "n_options.npy", "option_outcomes.npy"):
        assert np.array_equal(np.load(straight / name), np.load(extended / name)), name
    assert json.loads((extended / "config.json").read_text())["episodes"] == 6
    for argv, message in ((["--episodes", "3"], "fewer than the 6"),
                          (["--runs", "5"], "only --episodes, to extend it")):
        try:
            main(["train", "--resume", str(extended), *argv])
        except SystemExit:
            pass
        err = capsys.readouterr().err.strip()
        assert message in err and err.count("\n") == 0


def test_keep_checkpoints_keeps_the_newest_and_the_one_a_longer_run_extends_from(tmp_path):
    """--keep-checkpoints 2: the run's checkpoint folder holds the newest two and the newest
    written before any agent finished; the run still extends bit for bit from it, and a resume
    never deletes a checkpoint an earlier process wrote."""
    import numpy as np

    base = ["train", "--agent", "skill-chaining", "--map", "pinball_box", "--seed", "4",
            "--max-episode-steps", "400", "--runs", "3", "--checkpoint-every", "1", "--quiet"]
    every, kept = tmp_path / "every", tmp_path / "kept"
    assert main([*base, "--episodes", "5", "--out", str(every)]) == 0
    assert main([*base, "--episodes", "5", "--out", str(kept), "--keep-checkpoints", "2"]) == 0
    for name in ("returns.npy", "lengths.npy"):
        assert np.array_equal(np.load(every / name), np.load(kept / name)), name
    written = sorted(p.name for p in (every / "checkpoints").glob("ckpt_*.pt"))
    left = sorted(p.name for p in (kept / "checkpoints").glob("ckpt_*.pt"))
    anchor = checkpoint_module.extension_checkpoint(every)[0].name
    assert len(written) > 3 and left == sorted({*written[-2:], anchor})
    assert main(["train", "--resume", str(kept), "--episodes", "7", "--quiet"]) == 0
    longer = tmp_path / "seven"
    assert main([*base, "--episodes", "7", "--out", str(longer)]) == 0
    for name in ("returns.npy", "lengths.npy"):
        assert np.array_equal(np.load(longer / name), np.load(kept / name)), name
