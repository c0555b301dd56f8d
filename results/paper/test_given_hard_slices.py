"""The hard given-options arm's slice script (results/paper/given_hard_slices.py): the stack
refuses gaps and overlaps, keeps the agents' order, and a slice's config names its bank
relative to the repository; the table script (given_hard_table.py) pairs agents in order."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SCRIPT = HERE / "given_hard_slices.py"
TABLE = HERE / "given_hard_table.py"


@pytest.fixture()
def slices(tmp_path, monkeypatch):
    spec = importlib.util.spec_from_file_location("given_hard_slices", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setattr(module, "SLICES", tmp_path / "slices")
    monkeypatch.setattr(module, "ARM", tmp_path / "arm")
    return module


def _slice(module, a, b, wall=10.0):
    out = module.SLICES / f"{a}-{b}"
    out.mkdir(parents=True)
    rows = np.arange(a, b, dtype=np.float64)[:, None].repeat(3, axis=1)
    np.save(out / "returns.npy", rows)
    np.save(out / "lengths.npy", rows.astype(np.int64))
    info = {"wall_time_s": wall, "agent_steps": 100 * (b - a), "commit": "abc",
            "discoverers_wall_time_s": 2 * wall}
    (out / "run_info.json").write_text(json.dumps(info))


@pytest.mark.parametrize("spans", [[(0, 40), (50, 100)], [(0, 60), (50, 100)], [(0, 90)]])
def test_stack_refuses_slices_that_do_not_cover_every_agent_once(slices, spans):
    for a, b in spans:
        _slice(slices, a, b)
    with pytest.raises(SystemExit, match="do not cover agents 0-99 exactly once"):
        slices.stack()
    assert not slices.ARM.exists()


def test_stack_keeps_agent_order_and_adds_the_wall_times(slices):
    for a, b in [(40, 100), (0, 5), (5, 40)]:  # made in any order
        _slice(slices, a, b)
    slices.stack()
    returns = np.load(slices.ARM / "returns.npy")
    assert returns.shape == (100, 3) and np.array_equal(returns[:, 0], np.arange(100))
    info = json.loads((slices.ARM / "run_info.json").read_text())
    assert info["wall_time_s"] == 30.0 and info["discoverers_wall_time_s"] == 60.0
    assert info["slices"] == ["0-5", "5-40", "40-100"]
    assert json.loads((slices.ARM / "config.json").read_text())["agent"] == "given-options"


def test_a_slice_config_names_its_bank_relative_to_the_repository(slices, tmp_path):
    src, dst = tmp_path / "src.json", tmp_path / "dst.json"
    bank = ROOT / "runs" / "k48-given" / "sc-0-5" / "options.pt"
    src.write_text(json.dumps({"agent": "given-options", "options": str(bank)}))
    slices._copy_config(src, dst)
    assert json.loads(dst.read_text())["options"] == "runs/k48-given/sc-0-5/options.pt"


def _table(slices_module):
    spec = importlib.util.spec_from_file_location("given_hard_table", TABLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.slices = slices_module  # the table finds slices as the (patched) slice script does
    return module


def test_the_table_reads_slices_in_order_and_stops_at_a_gap(slices):
    table = _table(slices)
    for a, b in [(5, 9), (0, 5), (12, 20)]:  # 9-12 missing: 12-19 would pair with the wrong seeds
        _slice(slices, a, b)
    assert np.array_equal(table.given_returns()[:, 0], np.arange(9))
    slices.ARM.mkdir(parents=True)
    np.save(slices.ARM / "returns.npy", np.full((100, 3), 7.0))  # the stacked arm, once it exists
    assert table.given_returns().shape == (100, 3)
