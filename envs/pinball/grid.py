"""A uniform grid over the board that tells the physics where nothing can happen.

The original simulator tests every polygon at every one of the 20 substeps. Most steps of a
ball are free flight, far from every edge, the target and the border; the grid lets
``pinball_step`` recognise those steps with one lookup and skip the per-edge tests, and gives
the remaining ("near") balls a short list of candidate edges instead of all of them. Both are
conservative bounds, so the trajectory is the same as testing everything.

For a cell with centre ``c`` and half-diagonal ``h``, any start position ``p`` in the cell
satisfies ``|p - c| <= h``. During one step a ball of speed ``|v|`` travels at most
``20 |v| r / 20 = |v| r`` in free flight (and ``21 |v| r / 20`` with the extra substep after a
bounce, which needs a collision first). Speed is at most sqrt(2) after the per-component clip.
With ``reach = r + 21 sqrt(2) r / 20 + h`` (plus 1e-9):

* ``cell_ids[cell_start[c] : cell_start[c + 1]]``: every edge within ``reach`` of the centre,
  in file order. A near ball only tests these;
* ``clearance[c] = min(edge distance - r, target distance - R, border distance) - h``: a ball in
  the cell with ``|v| r < clearance`` cannot touch an edge, reach the goal or leave the board
  during this step. Edges beyond ``reach`` are counted at distance ``reach``: a lower bound
  that already lets every speed fly free (``reach - r - h > sqrt(2) r``), so the physics
  decides exactly as with the true distance.

Why a list per cell (CSR) and not a dense ``cells x edges`` table: memory and time then grow
with the number of (cell, edge) pairs that are actually near each other, about linearly in
the number of edges, instead of with cells x edges (a map of 20,000 small triangles needed
15.7 GB the dense way). :meth:`CollisionGrid.build` estimates the size first and refuses,
naming the map, a map that would need more than :data:`MAX_GRID_BYTES` (or than the memory
available).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import torch

from skillchain_torch.resources import available_memory

from .maps import PinballMap

__all__ = [
    "CollisionGrid",
    "collision_grid",
    "check_grid_size",
    "grid_memory_estimate",
    "MAX_GRID_BYTES",
]

# Refuse maps whose grid (and the boards built from it) would need more than this.
MAX_GRID_BYTES = 4 << 30
# Candidate (cell, edge) pairs measured at once while building (bounds the build's workspace).
_PAIR_CHUNK = 1 << 18
# Bytes per stored (cell, edge) entry at the build's peak: the pairs kept as int32 (8, twice
# while the chunks are joined), the sort's indices (8) and its scratch, and the final int64
# list (8); measured peaks stay below this (benchmarks/collision_grid_memory.py). Per edge:
# geometry and the compiled board (native.py); per cell: clearance and offsets.
_BYTES_PER_ENTRY = 40
_BYTES_PER_EDGE = 400
_BYTES_PER_CELL = 32
_WORKSPACE_BYTES = _PAIR_CHUNK * 160
# Fixed costs (the cell centres and clearances, torch's allocator, page granularity).
_BASE_BYTES = 16 << 20


def point_segment_distance(points: torch.Tensor, start: torch.Tensor, end: torch.Tensor):
    """Distance from each point ``[N, 2]`` to each segment ``[E, 2] -> [E, 2]``: ``[N, E]``.

    Example:
        >>> p = torch.tensor([[0.5, 0.3]], dtype=torch.float64)
        >>> a, b = torch.tensor([[0.0, 0.0]]).double(), torch.tensor([[1.0, 0.0]]).double()
        >>> point_segment_distance(p, a, b)
        tensor([[0.3000]], dtype=torch.float64)
    """
    e = end - start
    diff = points[:, None, :] - start[None]
    t = ((diff * e).sum(-1) / (e * e).sum(-1).clamp_min(1e-300)).clamp(0.0, 1.0)
    closest = start[None] + t[..., None] * e[None]
    return (points[:, None, :] - closest).norm(dim=-1)


def _reach(r: float, half_diag: float) -> float:
    return r + 21.0 * math.sqrt(2.0) * r / 20.0 + half_diag + 1e-9


def _cell_ranges(start, end, reach: float, h: float, g: int):
    """Per edge, the inclusive cell index ranges ``(i0, i1, j0, j1)`` whose centres can lie
    within ``reach`` of it (a box, with one cell of margin against rounding)."""
    lo = torch.minimum(start, end) - reach
    hi = torch.maximum(start, end) + reach
    # Centre of cell i is (i - 0.5) h, so centre >= lo  <=>  i >= lo / h + 0.5.
    first = (torch.floor(lo / h + 0.5) - 1).clamp(0, g - 1).to(torch.long)
    last = (torch.floor(hi / h + 0.5) + 1).clamp(0, g - 1).to(torch.long)
    return first[:, 0], last[:, 0], first[:, 1], last[:, 1]


def grid_memory_estimate(pinball_map: PinballMap, resolution: int = 128) -> tuple[int, int]:
    """Upper bounds ``(bytes, entries)`` of building the grid of ``pinball_map`` and its boards.

    ``entries`` bounds the (cell, edge) pairs stored: per edge, the cells of its box, and no
    more than the lattice points that fit in the stadium of radius ``reach + h / sqrt(2)``
    around it (each centre owns a cell of area ``h^2`` inside that stadium).

    Example:
        >>> from skillchain_torch.envs.pinball import load_map
        >>> nbytes, entries = grid_memory_estimate(load_map("pinball_simple_single"))
        >>> 0 < entries < 100_000 and nbytes < 32 << 20
        True
    """
    g = int(resolution)
    h = 1.0 / (g - 2)
    reach = _reach(pinball_map.ball_radius, h * math.sqrt(0.5))
    start = pinball_map.edge_start.to("cpu", torch.float64)
    end = pinball_map.edge_end.to("cpu", torch.float64)
    if start.shape[0]:
        i0, i1, j0, j1 = _cell_ranges(start, end, reach, h, g)
        box = (i1 - i0 + 1) * (j1 - j0 + 1)
        rho = reach + h * math.sqrt(0.5)
        length = (end - start).norm(dim=-1)
        stadium = torch.floor((2.0 * rho * length + math.pi * rho * rho) / (h * h)) + 1
        entries = int(torch.minimum(box.double(), stadium).sum().item())
    else:
        entries = 0
    n_edges = int(start.shape[0])
    nbytes = (
        _BASE_BYTES
        + entries * _BYTES_PER_ENTRY
        + n_edges * _BYTES_PER_EDGE
        + g * g * _BYTES_PER_CELL
        + min(_WORKSPACE_BYTES, max(entries, 1) * 160)
    )
    return nbytes, entries


def check_grid_size(
    pinball_map: PinballMap, resolution: int = 128, max_bytes: int | None = None
) -> None:
    """``ValueError`` naming the map and the size if its grid would need more than
    ``max_bytes`` (default :data:`MAX_GRID_BYTES`) or than the memory available now.

    Cheap (no grid is built): the envs call it when they are created.

    Example:
        >>> from skillchain_torch.envs.pinball import load_map
        >>> check_grid_size(load_map("pinball_box"))  # fine: returns None
        >>> try:
        ...     check_grid_size(load_map("pinball_box"), max_bytes=1 << 20)
        ... except ValueError as err:
        ...     print("map 'pinball_box'" in str(err), "too large to simulate" in str(err))
        True True
    """
    limit = MAX_GRID_BYTES if max_bytes is None else int(max_bytes)
    why = f"the limit, grid.MAX_GRID_BYTES = {limit / 2**30:.3g} GiB"
    available = available_memory("cpu")  # MemAvailable, and the cgroup's limit
    if available is not None and available < limit:
        limit, why = available, f"the memory available now ({available / 2**30:.3g} GiB)"
    nbytes, entries = grid_memory_estimate(pinball_map, resolution)
    if nbytes > limit:
        raise ValueError(
            f"map {pinball_map.name!r} ({pinball_map.source}) is too large to simulate: its "
            f"collision grid would need about {nbytes / 2**30:.3g} GiB ({pinball_map.n_edges} "
            f"edges, up to {entries} cell-edge entries at resolution {resolution}), more than "
            f"{why}; use fewer or shorter edges"
        )


@dataclass(frozen=True)
class CollisionGrid:
    """Precomputed free-flight clearance and candidate edges on a ``G x G`` grid.

    Cells cover ``[-h, 1 + h]`` on each axis (one border cell beyond the unit square), so any
    position, even outside the board, clamps into a cell whose clearance is negative there.
    Cell ``c``'s candidate edges are ``cell_ids[cell_start[c] : cell_start[c + 1]]``;
    ``cell_ids`` ends with one extra ``-1`` so that padded gathers stay in bounds.

    Example:
        >>> from skillchain_torch.envs.pinball import load_map
        >>> grid = collision_grid(load_map("pinball_simple_single"))
        >>> grid.cell_start.shape[0] == grid.resolution ** 2 + 1
        True
        >>> grid.candidates(grid.cell_index(torch.tensor([[0.005, 0.5]]).double())).tolist()
        [[5, 7]]
    """

    resolution: int
    cell_size: float
    clearance: torch.Tensor  # [G*G] float64
    cell_start: torch.Tensor  # [G*G + 1] int64
    cell_ids: torch.Tensor  # [entries + 1] int64, file order within a cell; last: -1
    edge_geometry: torch.Tensor  # [E + 1, 5] float64: ax, ay, ex, ey, |e|^2; last row: padding
    edge_polygon: torch.Tensor  # [E + 1] int64; last row -1

    @classmethod
    def build(
        cls, pinball_map: PinballMap, resolution: int = 128, max_bytes: int | None = None
    ) -> CollisionGrid:
        """The grid of ``pinball_map``; ``ValueError`` if it would need more than
        ``max_bytes`` (default :data:`MAX_GRID_BYTES`) or the memory available."""
        f64 = torch.float64
        g = int(resolution)
        check_grid_size(pinball_map, g, max_bytes)
        h = 1.0 / (g - 2)  # g - 2 interior cells span the unit square, one border cell each side
        centres_1d = (torch.arange(g, dtype=f64) - 0.5) * h
        cy, cx = torch.meshgrid(centres_1d, centres_1d, indexing="ij")
        centres = torch.stack([cx.reshape(-1), cy.reshape(-1)], dim=-1)  # row-major: y, then x
        half_diag = h * math.sqrt(0.5)
        r = pinball_map.ball_radius
        reach = _reach(r, half_diag)

        start = pinball_map.edge_start.to("cpu", f64)
        end = pinball_map.edge_end.to("cpu", f64)
        near_dist = torch.full((g * g,), reach, dtype=f64)
        cells, edges = _near_pairs(start, end, centres_1d, reach, h, g, near_dist)
        edge_clear = near_dist - r
        target = torch.tensor(pinball_map.target, dtype=f64)
        goal_clear = (centres - target).norm(dim=-1) - pinball_map.target_radius
        border_clear = torch.minimum(centres, 1.0 - centres).min(dim=-1).values
        clearance = torch.minimum(torch.minimum(edge_clear, goal_clear), border_clear) - half_diag

        # Group the pairs by cell; a stable sort keeps each cell's edges in file order. The
        # order of the steps and the dels keep the peak near 24 bytes per entry.
        counts = torch.bincount(cells, minlength=g * g)
        cell_start = torch.cat([torch.zeros(1, dtype=torch.long), torch.cumsum(counts, 0)])
        by_cell = torch.sort(cells, stable=True).indices
        del cells
        cell_ids = torch.empty(by_cell.shape[0] + 1, dtype=torch.long)
        cell_ids[:-1] = edges[by_cell]
        cell_ids[-1] = -1
        del by_cell, edges
        # The padding row (index -1) is a degenerate edge far off the board: never in contact.
        e = end - start
        geometry = torch.cat([start, e, (e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1])[:, None]], -1)
        far = torch.tensor([[1e6, 1e6, 0.0, 0.0, 1.0]], dtype=f64)
        geometry = torch.cat([geometry, far])
        polygon = torch.cat([pinball_map.edge_polygon.cpu(), torch.tensor([-1])])
        device = pinball_map.edge_start.device
        return cls(
            g,
            h,
            clearance.to(device),
            cell_start.to(device),
            cell_ids.to(device),
            geometry.to(device),
            polygon.to(device),
        )

    @property
    def n_entries(self) -> int:
        """Number of stored (cell, candidate edge) pairs."""
        return int(self.cell_ids.shape[0]) - 1

    def candidates(self, cells: torch.Tensor) -> torch.Tensor:
        """Candidate edges of flat cell indices ``[m]``: ``[m, K]`` int64, padded with -1.

        ``K`` is the largest count among these cells (at least 1); each row lists its edges
        in file order.
        """
        first = self.cell_start[cells]
        count = self.cell_start[cells + 1] - first
        k = max(int(count.max().item()) if count.numel() else 0, 1)
        slot = torch.arange(k, device=cells.device)
        index = (first[:, None] + slot).clamp_max(self.cell_ids.shape[0] - 1)
        return torch.where(slot < count[:, None], self.cell_ids[index], -1)

    def cell_edge_list(self, cell: int) -> list[int]:
        """Candidate edges of one cell, as Python ints.

        Example:
            >>> from skillchain_torch.envs.pinball import load_map
            >>> collision_grid(load_map("pinball_box")).cell_edge_list(64 * 128 + 64)
            [16, 17, 18, 19]
        """
        lo, hi = self.cell_start[cell : cell + 2].tolist()
        return self.cell_ids[lo:hi].tolist()

    @staticmethod
    def is_free(clearance, vv, r: float):
        """Whether a ball with squared speed ``vv`` in a cell of this ``clearance`` flies free.

        Free flight travels ``|v| r`` per step; the test compares squares (no sqrt) with a
        relative margin, and works on floats and tensors alike (the compiled step makes the
        same comparison), so every path decides identically.
        """
        c = clearance - 1e-12
        return (c > 0.0) & (c * c > vv * _RR_MARGIN * (r * r))

    def cell_index(self, xy: torch.Tensor) -> torch.Tensor:
        """Flat cell index of positions ``[..., 2]`` (positions off the grid clamp to its rim)."""
        g = self.resolution
        ij = torch.floor(xy / self.cell_size).to(torch.long) + 1
        ij = ij.clamp(0, g - 1)
        return ij[..., 1] * g + ij[..., 0]


def _near_pairs(start, end, centres_1d, reach: float, h: float, g: int, near_dist):
    """The (cell, edge) pairs within ``reach``, as int32 ``(cells, edges)`` in edge order.

    Measures each edge against the cells of its box, a chunk of consecutive edges at a time
    on a padded ``[edges, rows, columns]`` block (broadcasting, no per-pair gathers), with the
    operations of :func:`point_segment_distance` in its order, so the same bits. Lowers
    ``near_dist[cell]`` to the nearest such edge's distance, in place.
    """
    n_edges = start.shape[0]
    empty = torch.zeros(0, dtype=torch.int32)
    if n_edges == 0:
        return empty, empty
    i0, i1, j0, j1 = _cell_ranges(start, end, reach, h, g)
    width, height = i1 - i0 + 1, j1 - j0 + 1
    e = end - start
    ee = (e * e).sum(-1).clamp_min(1e-300)
    out_cells, out_edges = [], []
    for lo, hi, w, hh in _chunks(width.tolist(), height.tolist()):
        cols, rows = torch.arange(w), torch.arange(hh)
        ci = (i0[lo:hi, None] + cols).clamp_max(g - 1)  # [k, W]; padding clamped, masked below
        cj = (j0[lo:hi, None] + rows).clamp_max(g - 1)  # [k, H]
        px = centres_1d[ci][:, None, :]  # [k, 1, W]
        py = centres_1d[cj][:, :, None]  # [k, H, 1]
        ax, ay = start[lo:hi, 0, None, None], start[lo:hi, 1, None, None]
        ex, ey = e[lo:hi, 0, None, None], e[lo:hi, 1, None, None]
        t = (((px - ax) * ex + (py - ay) * ey) / ee[lo:hi, None, None]).clamp(0.0, 1.0)
        ux = px - (ax + t * ex)
        uy = py - (ay + t * ey)
        dist = torch.stack([ux, uy], dim=-1).norm(dim=-1)  # torch's norm, as the formula's
        near = (dist <= reach) & (rows < height[lo:hi, None])[:, :, None]
        near &= (cols < width[lo:hi, None])[:, None, :]
        k, row, col = near.nonzero(as_tuple=True)  # edge-major, as the stable sort needs
        cell = cj[k, row] * g + ci[k, col]
        near_dist.scatter_reduce_(0, cell, dist[near], reduce="amin")
        out_cells.append(cell.to(torch.int32))
        out_edges.append((k + lo).to(torch.int32))
    return torch.cat(out_cells), torch.cat(out_edges)


def _chunks(widths: list, heights: list):
    """Consecutive edge ranges ``(lo, hi, W, H)`` whose padded blocks ``(hi - lo) W H`` stay
    within ``_PAIR_CHUNK`` cells (a single edge's box, at most ``G^2``, always fits)."""
    n, lo = len(widths), 0
    while lo < n:
        w, hh, hi = widths[lo], heights[lo], lo + 1
        while hi < n:
            w2, h2 = max(w, widths[hi]), max(hh, heights[hi])
            if (hi + 1 - lo) * w2 * h2 > _PAIR_CHUNK:
                break
            w, hh, hi = w2, h2, hi + 1
        yield lo, hi, w, hh
        lo = hi


_RR_MARGIN = (1.0 + 1e-9) ** 2
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def collision_grid(pinball_map: PinballMap) -> CollisionGrid:
    """The grid of ``pinball_map``, built once per map object and cached."""
    grid = _CACHE.get(pinball_map)
    if grid is None:
        grid = CollisionGrid.build(pinball_map)
        _CACHE[pinball_map] = grid
    return grid
