"""Every notebook in notebooks/ runs top to bottom without an error on a small budget.

The kernel inherits ``SKILLCHAIN_SMOKE=1``, which notebooks read to shrink their budgets
(about 10 s per notebook; mark a notebook's case slow if it ever takes more than 30 s).
Notebooks that promise something a run may stop showing (04 and 05: options created) assert it
in their last cell, so that a run which no longer shows it fails here.
"""

import os
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))


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


# Notebooks whose last code cell asserts what the title promises (a run that stops showing it
# fails ``test_notebook_runs``); the check below keeps those asserts from being dropped.
PROMISES = {
    "04_skill_chaining.ipynb": "assert n_options > 0",  # the agents discovered options
    "05_your_own_pieces.ipynb": "assert n_options > 0",  # ... with the user's own pieces
}


@pytest.mark.parametrize("name", sorted(PROMISES))
def test_notebook_asserts_its_promise(name):
    notebook = nbformat.read(NOTEBOOK_DIR / name, as_version=4)
    code = [cell.source for cell in notebook.cells if cell.cell_type == "code"]
    assert PROMISES[name] in code[-1], f"{name}'s last code cell lost {PROMISES[name]!r}"


def test_notebooks_found():
    assert any(p.name == "02_flat_sarsa.ipynb" for p in NOTEBOOKS)
    assert all(os.path.getsize(p) > 0 for p in NOTEBOOKS)
