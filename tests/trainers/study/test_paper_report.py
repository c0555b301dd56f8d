"""The paper report's tables and claims take Student-t intervals (trainers/study/intervals.py)."""

import doctest
import json
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study import paper_report
from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci
from skillchain_torch.trainers.study.paper_report import check_claims, write_report

# Three runs whose difference is 3.1 standard errors: outside a z interval (1.96), inside
# Welch's t interval (df 2.9, t 3.26); episodes 26-50 are the simple instance's first claim.
SC = np.repeat(np.array([[3.0], [5.0], [7.0]]), 50, axis=1)
FLAT = np.repeat(np.array([[0.0], [1.0], [2.0]]), 50, axis=1)


def _run(folder, returns, agent):
    folder.mkdir(parents=True)
    np.save(folder / "returns.npy", returns)
    np.save(folder / "lengths.npy", np.full(returns.shape, 100, dtype=np.int64))
    (folder / "config.json").write_text(json.dumps({"agent": agent, "map": "pinball_box"}))


def test_doctest():
    assert doctest.testmod(paper_report).failed == 0


def test_a_claim_needs_the_t_interval_to_exclude_zero():
    runs = {"flat": {"returns": FLAT}, "skill-chaining": {"returns": SC}}
    first = check_claims("simple", runs)[0]
    assert first["measure"] == "episodes 26-50"
    assert first["value"] == "+4 ± 4" and first["holds"] is False


def test_the_tables_print_t_intervals_and_say_so(tmp_path):
    _run(tmp_path / "simple" / "flat", FLAT, "flat")
    _run(tmp_path / "simple" / "skill-chaining", SC, "skill-chaining")
    text = write_report(tmp_path, figures=False).read_text()
    assert "95% Student t interval" in text and "Welch's 95% t interval" in text
    row = next(line for line in text.splitlines() if line.startswith("| 1-10 |"))
    flat_cell, sc_cell, diff_cell = (cell.strip() for cell in row.split("|")[2:5])
    assert flat_cell == "{:,.0f} ± {:,.0f}".format(*mean_ci(FLAT[:, 0]))  # 1 ± 2 (z: ± 1)
    assert flat_cell == "1 ± 2"
    assert diff_cell == "{:+,.0f} ± {:,.0f}".format(*diff_ci(SC[:, 0], FLAT[:, 0]))
    assert not diff_cell.endswith("*")
    assert json.loads((tmp_path / "report.json").read_text())["simple"][0]["holds"] is False


def test_committed_figures_are_kept_when_the_checkpoints_are_gone(tmp_path):
    """A fresh clone has the study's figures but not the checkpoints that drew them:
    ``--report-only`` there used to drop the figures from the report."""
    _run(tmp_path / "simple" / "flat", FLAT, "flat")
    _run(tmp_path / "simple" / "skill-chaining", SC, "skill-chaining")
    text = write_report(tmp_path, quiet=True).read_text()
    assert "need the skill-chaining run's checkpoint" in text and "(fig4b.png)" not in text
    for name in ("fig4b.png", "fig5.png"):
        (tmp_path / name).write_bytes(b"\x89PNG")
    text = write_report(tmp_path, quiet=True).read_text()
    assert "![greedy solutions](fig4b.png)" in text and "![initiation sets](fig5.png)" in text
    assert "checkpoints are not here to redraw them" in text
    assert (tmp_path / "fig4b.png").read_bytes() == b"\x89PNG"  # not overwritten


def test_the_published_report_carries_its_discussion_as_committed():
    """``results/paper/README.md`` ends with ``DISCUSSION.md``; after editing the discussion,
    ``skillchain reproduce paper --out results/paper --report-only`` rewrites the report."""
    study = Path(__file__).resolve().parents[3] / "results" / "paper"
    readme, discussion = (study / name for name in ("README.md", "DISCUSSION.md"))
    assert readme.read_text().rstrip().endswith(discussion.read_text().rstrip())
