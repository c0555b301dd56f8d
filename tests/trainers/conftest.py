"""Fixtures of the trainer tests: one local Ray for every Ray test of the session."""

import pytest


@pytest.fixture(scope="session")
def ray_local():
    """A local Ray of 2 CPUs, started once (its start-up is seconds; the tests' runs are not).
    The code under test reuses a Ray already started in the process."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             configure_logging=False)
    yield ray
    ray.shutdown()
