"""Fixtures of the trainer tests: one local Ray for every Ray test of the session, and a
finished tiny run for the command-line hardening tests."""

import pytest
from cli_errors import TINY

from skillchain_torch.trainers.config.cli import main


@pytest.fixture(scope="session")
def ray_local():
    """A local Ray of 2 CPUs, started once (its start-up is seconds; the tests' runs are not).
    The code under test reuses a Ray already started in the process."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             configure_logging=False)
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A finished tiny flat run (with its final checkpoint)."""
    out = tmp_path_factory.mktemp("hardening") / "run"
    assert main(["train", *TINY, "--out", str(out)]) == 0
    return out
