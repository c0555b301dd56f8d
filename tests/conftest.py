"""Shared test fixtures: headless plotting and the shared reference data."""

from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")


def _find_shared() -> Path:
    for parent in Path(__file__).resolve().parents:
        candidate = parent / "shared" / "pinball"
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError("shared/pinball (reference vectors) not found above the tests")


@pytest.fixture(scope="session")
def vectors_dir() -> Path:
    """Folder of trajectories produced by the original Java implementation."""
    return _find_shared() / "vectors"
