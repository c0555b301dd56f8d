"""Shared test fixtures: headless plotting and the shared reference data."""

import os
import subprocess
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

if os.environ.get("PYTEST_XDIST_WORKER"):  # make test: one pytest worker per core
    import torch

    # torch's own intra-op threads, one per core in every worker, would oversubscribe the
    # cores (OpenMP threads spin while they wait); the commands the tests start inherit it
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    torch.set_num_threads(1)


def _origin() -> Path | None:
    """The checkout this one was cloned from, when that is a local path (a scratch clone of a
    checkout that sits beside shared/)."""
    try:
        url = subprocess.run(["git", "config", "--get", "remote.origin.url"],
                             cwd=Path(__file__).parent, capture_output=True, text=True,
                             timeout=10).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return Path(url).resolve() if url and Path(url).is_dir() else None


def _find_shared() -> Path:
    """shared/pinball: $SKILLCHAIN_SHARED, else above the tests, else above the local origin."""
    if os.environ.get("SKILLCHAIN_SHARED"):
        return Path(os.environ["SKILLCHAIN_SHARED"]) / "pinball"
    origin = _origin()
    roots = [*Path(__file__).resolve().parents, *([origin, *origin.parents] if origin else [])]
    for parent in roots:
        candidate = parent / "shared" / "pinball"
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError("shared/pinball (reference vectors) not found above the tests or "
                            "their local origin; set SKILLCHAIN_SHARED to the shared/ folder")


@pytest.fixture(scope="session")
def vectors_dir() -> Path:
    """Folder of trajectories produced by the original Java implementation."""
    return _find_shared() / "vectors"
