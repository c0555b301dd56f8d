"""The collision grid: the same candidates and decisions as the dense original, linear memory,
refusal of maps too large, and dense maps beyond the compiled step's capacity."""

import doctest
import math
from pathlib import Path

import pytest
import torch

from skillchain_torch.envs.pinball import MAP_NAMES, PinballMap, load_map, native, physics
from skillchain_torch.envs.pinball import grid as grid_module
from skillchain_torch.envs.pinball.grid import (
    CollisionGrid,
    grid_memory_estimate,
    point_segment_distance,
)

# Ball, target, start and the four walls of the original domain, to which obstacles are added.
EMPTY = Path(load_map("pinball_empty").source).read_text()


def triangles_map(n, seed=0, low=0.3, high=0.95, side=0.004):
    """``n`` right triangles with legs ``side`` at random corners in ``[low, high]^2``."""
    gen = torch.Generator().manual_seed(seed)
    corners = low + (high - low) * torch.rand(n, 2, generator=gen, dtype=torch.float64)
    lines = [
        f"polygon {x!r} {y!r} {x + side!r} {y!r} {x!r} {y + side!r}" for x, y in corners.tolist()
    ]
    return PinballMap.from_string(EMPTY + "\n" + "\n".join(lines), name=f"triangles_{n}")


def test_doctests():
    assert doctest.testmod(grid_module).failed == 0


def dense_reference(m, g=128):
    """The original dense construction: candidate lists and clearances for every cell."""
    h = 1.0 / (g - 2)
    c1 = (torch.arange(g, dtype=torch.float64) - 0.5) * h
    cy, cx = torch.meshgrid(c1, c1, indexing="ij")
    centres = torch.stack([cx.reshape(-1), cy.reshape(-1)], dim=-1)
    half_diag = h * math.sqrt(0.5)
    r = m.ball_radius
    dist = point_segment_distance(centres, m.edge_start, m.edge_end)
    goal = (centres - torch.tensor(m.target, dtype=torch.float64)).norm(dim=-1) - m.target_radius
    border = torch.minimum(centres, 1.0 - centres).min(dim=-1).values
    clearance = torch.minimum(torch.minimum(dist.min(1).values - r, goal), border) - half_diag
    near = dist <= r + 21.0 * math.sqrt(2.0) * r / 20.0 + half_diag + 1e-9
    lists = [row.nonzero()[:, 0].tolist() for row in near]
    return lists, clearance


@pytest.mark.parametrize("name", [*MAP_NAMES, "triangles_100"])
def test_grid_matches_the_dense_original(name):
    """Same candidate edges per cell (file order), same clearance bits wherever an edge is
    near, and the same free-flight decision for every cell and speed: the physics cannot
    tell the two apart."""
    m = triangles_map(100) if name == "triangles_100" else load_map(name)
    grid = CollisionGrid.build(m)
    lists, clearance = dense_reference(m)
    assert [grid.cell_edge_list(c) for c in range(len(lists))] == lists
    has_edges = torch.tensor([bool(x) for x in lists])
    assert torch.equal(grid.clearance[has_edges], clearance[has_edges])
    vv = torch.linspace(0.0, 2.0, 201, dtype=torch.float64)  # |v|^2 <= 2 after the clip
    free = CollisionGrid.is_free
    r = m.ball_radius
    assert torch.equal(free(grid.clearance[:, None], vv, r), free(clearance[:, None], vv, r))
    cells = torch.tensor([0, 5000, 8256, 16383])
    padded = grid.candidates(cells)
    for row, c in zip(padded.tolist(), cells.tolist(), strict=True):
        k = len(lists[c])
        assert row[:k] == lists[c] and set(row[k:]) <= {-1}


def _peak_rss_tools():
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pytest.skip("needs Linux /proc/self/clear_refs to reset the peak RSS")

    def status(key):
        with open("/proc/self/status") as f:
            return next(int(x.split()[1]) * 1024 for x in f if x.startswith(key))

    return status


def test_grid_memory_grows_with_edges_not_cells_times_edges():
    """2,000 small triangles (6,016 edges): the dense layout's first allocation alone was
    16 B x 16,384 cells x 6,016 edges = 1.5 GiB; the lists need a few tens of MB."""
    m = triangles_map(2000)
    status = _peak_rss_tools()
    base = status("VmRSS:")
    grid = CollisionGrid.build(m)
    peak = status("VmHWM:") - base
    nbytes, entries = grid_memory_estimate(m)
    assert grid.n_entries <= entries and peak <= nbytes
    assert grid.n_entries < 200 * m.n_edges  # ~160 cells per small edge
    assert peak < 300 << 20, f"peak {peak / 2**20:.0f} MiB"


def test_estimate_bounds_the_entries():
    """Small and long edges (50 triangles with sides of 0.3, overlapping)."""
    for m in (load_map("pinball_medium"), triangles_map(50, side=0.3, high=0.65)):
        assert CollisionGrid.build(m).n_entries <= grid_memory_estimate(m)[1], m.name


def test_too_large_map_is_refused_by_the_builder():
    m = load_map("pinball_hard_single")
    with pytest.raises(ValueError, match=r"'pinball_hard_single' .* too large .* GiB"):
        CollisionGrid.build(m, max_bytes=1 << 20)
    CollisionGrid.build(m, max_bytes=1 << 30)  # within the limit: built


def test_map_denser_than_the_compiled_step_holds_steps_correctly(monkeypatch):
    """300 tiny triangles in a 0.05 x 0.05 patch: cells there list ~900 candidate edges, more
    than the compiled step's 256, so pinball_step takes its Python paths (the same bits)
    instead of failing or dropping edges."""
    m = triangles_map(300, low=0.55, high=0.6, side=0.002)
    counts = CollisionGrid.build(m).cell_start.diff()
    assert int(counts.max()) > 256 and counts.numel() == 128 * 128
    assert native.board_if_supported(m) is None
    if native.AVAILABLE:
        with pytest.raises(ValueError, match=r"has \d+ candidate edges; .* at most 256"):
            native.native_board(m)
    gen = torch.Generator().manual_seed(0)
    state = torch.cat(
        [
            0.53 + 0.1 * torch.rand(6, 2, generator=gen, dtype=torch.float64),
            torch.rand(6, 2, generator=gen, dtype=torch.float64) * 2 - 1,
        ],
        dim=-1,
    )
    bounces = 0
    for _ in range(8):
        action = torch.randint(0, 5, (6,), generator=gen)
        default = physics._step(state, action, m, True)  # the compiled step cannot hold it
        tensor = physics._step(state, action, m, True, compiled=False)
        for x, y in zip(default, tensor, strict=True):
            assert torch.equal(x, y)
        bounces += int(default[3][:, :3].sum())
        state = default[0]
    assert bounces > 0
