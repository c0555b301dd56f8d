"""``skillchain sweep SPEC``: a grid of run directories on Ray, skipped when complete."""

import sys

import numpy as np
import pytest

from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.trainers.config.cli import main
from skillchain_torch.trainers.study.sweep import expand_grid

SPEC = """
[base]
runs = 2
episodes = 3
max_episode_steps = 150
map = "pinball_box"
seed = 7
[grid]
alpha = [0.001, 0.002]
"""


def test_sweep_runs_cells_then_skips_them(ray_local, tmp_path, capsys):
    spec = tmp_path / "grid.toml"
    spec.write_text(SPEC)
    out = tmp_path / "sweep"
    argv = ["sweep", str(spec), "--out", str(out), "--workers", "2", "--block-size", "1",
            "--quiet"]
    assert main(argv) == 0
    assert "2 cells run, 0 skipped" in capsys.readouterr().out
    cells = sorted(p.name for p in out.iterdir() if p.is_dir())
    assert cells == ["alpha-0.001", "alpha-0.002"]
    reference = PopulationTrainer(TrainConfig(runs=2, episodes=3, max_episode_steps=150,
                                              map="pinball_box", seed=7, alpha=0.002)).train()
    np.testing.assert_array_equal(np.load(out / "alpha-0.002" / "returns.npy"), reference.returns)
    summary = (out / "summary.md").read_text()
    assert "| alpha-0.001 | 2 |" in summary and "| alpha-0.002 | 2 |" in summary
    assert (out / "summary.png").is_file()
    stamps = {c: (out / c / "returns.npy").stat().st_mtime_ns for c in cells}
    assert main(argv) == 0
    assert "0 cells run, 2 skipped" in capsys.readouterr().out
    assert stamps == {c: (out / c / "returns.npy").stat().st_mtime_ns for c in cells}


def test_grid_leaves_unread_fields_out():
    """``slots`` means nothing to the flat agent: one flat cell, two skill-chaining cells."""
    cells = expand_grid({"base": {"runs": 2},
                         "grid": {"agent": ["flat", "skill-chaining"], "slots": [2, 4]}})
    assert [name for name, _ in cells] == ["agent-flat", "agent-skill-chaining__slots-2",
                                           "agent-skill-chaining__slots-4"]
    assert [cfg.slots for _, cfg in cells] == [12, 2, 4]


@pytest.mark.parametrize(("text", "message"), [
    ("[grid]\nalpah = [1.0]\n", "[grid] has unknown TrainConfig fields alpah"),
    ("[grid]\nalpha = 0.1\n", "grid field 'alpha' must be a non-empty list"),
    ("[base]\nruns = 0\n", "cell base: runs must be >= 1"),
    ("[grid\n", "not valid TOML"),
    ("wokers = 2\n", "unknown keys wokers"),
])
def test_bad_specs_are_one_line(tmp_path, capsys, text, message):
    pytest.importorskip("ray")
    spec = tmp_path / "bad.toml"
    spec.write_text(text)
    with pytest.raises(SystemExit) as info:
        main(["sweep", str(spec), "--out", str(tmp_path / "out")])
    assert info.value.code == 2
    assert message in capsys.readouterr().err


def test_sweep_without_ray_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    spec = tmp_path / "grid.toml"
    spec.write_text(SPEC)
    with pytest.raises(SystemExit) as info:
        main(["sweep", str(spec), "--out", str(tmp_path / "out")])
    assert info.value.code == 2
    assert capsys.readouterr().err.strip().endswith(
        "skillchain sweep needs Ray, which is not installed: pip install skillchain_torch[ray]")


def test_doctests():
    import doctest

    from skillchain_torch.trainers.study import sweep

    assert doctest.testmod(sweep, optionflags=doctest.ELLIPSIS).failed == 0


def test_yaml_spec_reads_as_toml(tmp_path):
    pytest.importorskip("yaml")
    from skillchain_torch.trainers.study.sweep import load_spec

    (tmp_path / "a.toml").write_text(SPEC)
    (tmp_path / "a.yaml").write_text("base: {runs: 2, episodes: 3, max_episode_steps: 150, "
                                     "map: pinball_box, seed: 7}\ngrid: {alpha: [0.001, 0.002]}\n")
    assert load_spec(tmp_path / "a.yaml") == load_spec(tmp_path / "a.toml")
