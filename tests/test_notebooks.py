"""Every notebook in notebooks/ runs top to bottom without an error on a small budget.

The kernel inherits ``SKILLCHAIN_SMOKE=1``, which notebooks read to shrink their budgets
(about 10 s per notebook; mark a notebook's case slow if it ever takes more than 30 s).
"""

import os
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path, monkeypatch):
    monkeypatch.setenv("SKILLCHAIN_SMOKE", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    notebook = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        notebook, kernel_name="python3", timeout=600,
        resources={"metadata": {"path": str(path.parent)}},  # run where the notebook lives
    )
    client.execute()  # raises CellExecutionError naming the failing cell
    errors = [out for cell in notebook.cells if cell.cell_type == "code"
              for out in cell.get("outputs", []) if out.get("output_type") == "error"]
    assert not errors, errors


def test_notebooks_found():
    assert any(p.name == "02_flat_sarsa.ipynb" for p in NOTEBOOKS)
    assert all(os.path.getsize(p) > 0 for p in NOTEBOOKS)
