"""``skillchain plot`` (trainers/study/compare.py): learning curves of several runs in one figure,
and the window table with 95% intervals."""

import json
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture(scope="module")
def compare():
    from skillchain_torch.trainers.study import compare as module

    return module


def fake_run(path: Path, returns) -> Path:
    path.mkdir()
    np.save(path / "returns.npy", np.asarray(returns, dtype=np.float64))
    (path / "config.json").write_text(json.dumps({"map": "pinball_box", "seed": 0}))
    return path


def test_table_and_figure(compare, tmp_path, capsys):
    a = fake_run(tmp_path / "a", np.tile(np.arange(1.0, 11.0), (3, 1)))
    b = fake_run(tmp_path / "b", np.tile(np.arange(1.0, 11.0), (3, 1)) + [[0.0], [2.0], [4.0]])
    out = tmp_path / "cmp.png"
    assert compare.main([str(a), str(b), "--labels", "A", "B", "--out", str(out),
                         "--windows", "1-5,6-10,11-20"]) == 0
    assert out.stat().st_size > 0
    text = capsys.readouterr().out
    # B = A + (0, 2, 4) per run: sd 2 over 3 runs, t(0.975, 2) 2 / sqrt(3) = 4.97
    assert "| 1-5 | 3 +- 0 | 5 +- 5 | +2 +- 5 |" in text
    assert "| 6-10 | 8 +- 0 | 10 +- 5 | +2 +- 5 |" in text
    assert "11-20" not in text  # runs too short for that window


def test_partial_runs_and_windows(compare, tmp_path):
    r = np.ones((2, 6))
    r[1, 4:] = np.nan  # run 1 has done 4 episodes
    run = fake_run(tmp_path / "p", r)
    returns, config = compare.load_returns(run)
    assert returns.shape == (2, 4) and config["map"] == "pinball_box"
    assert compare.parse_windows("1-5, 7") == [(1, 5), (7, 7)]
    with pytest.raises(ValueError):
        compare.parse_windows("5-1")


def test_default_windows_follow_the_runs_length(compare):
    assert compare.default_windows(250)[-1] == (201, 250)
    assert compare.default_windows(60) == [(1, 10), (26, 50)]
    assert compare.default_windows(20) == [(1, 5), (6, 10), (11, 15), (16, 20)]


def test_skillchain_plot_draws_and_prints(tmp_path, capsys):
    from skillchain_torch.trainers.config.cli import main

    a = fake_run(tmp_path / "a", np.zeros((4, 12)))
    b = fake_run(tmp_path / "b", np.ones((4, 12)) * 100 + np.arange(4)[:, None])
    out = tmp_path / "fig.png"
    assert main(["plot", str(a), str(b), "--labels", "flat", "sc", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert out.stat().st_size > 0 and "| episodes | flat | sc | sc - flat |" in text
    assert "| 1-3 | 0 +- 0 | 102 +- 2 | +102 +- 2 * |" in text
    with pytest.raises(SystemExit):
        main(["plot", str(a), str(tmp_path / "missing")])
    assert "no returns.npy" in capsys.readouterr().err
