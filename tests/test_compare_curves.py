"""benchmarks/compare_curves.py: learning curves of several runs in one figure, window table."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "compare_curves.py"


@pytest.fixture(scope="module")
def compare():
    spec = importlib.util.spec_from_file_location("compare_curves", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
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
    assert "| 1-5 | 3 +- 0 | 5 +- 1 | +2 +- 1 |" in text  # B = A + (0, 2, 4) per run
    assert "| 6-10 | 8 +- 0 | 10 +- 1 | +2 +- 1 |" in text
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
