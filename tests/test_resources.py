"""``skillchain_torch.resources``: what the machine has, read once for the config and the grid."""

import doctest

import pytest
import torch

from skillchain_torch import resources
from skillchain_torch.envs.pinball import grid, load_map


def test_doctest():
    assert doctest.testmod(resources).failed == 0


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_device_problem_names_the_device_and_why():
    assert "sees no CUDA device" in resources.device_problem("cuda:1")
    assert "such as cpu" in resources.device_problem("gpu please")
    assert resources.device_problem("cpu") is None


def test_the_grid_check_reads_the_same_available_memory(monkeypatch):
    """The collision grid refuses a map that does not fit in what is available now (the
    cgroup's limit included), read through the one function the config check uses too."""
    monkeypatch.setattr(grid, "available_memory", lambda device="cpu": 1 << 20)
    with pytest.raises(ValueError, match="more than the memory available now"):
        grid.check_grid_size(load_map("pinball_box"))
    monkeypatch.setattr(grid, "available_memory", lambda device="cpu": None)  # unknown: no check
    grid.check_grid_size(load_map("pinball_box"))
