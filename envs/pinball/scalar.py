"""The same step as :mod:`.physics`, for one ball in plain Python floats.

Why it exists: a single run (batch 1) pays torch's per-operation overhead (a few microseconds)
on every one of the ~50 tensor operations of a batched step, which makes it slower than a
pure-Python simulator. For tiny CPU batches :func:`~.physics.pinball_step` runs this instead.

Why it is bit-identical to the batched path: both use only ``+ - * /`` (correctly rounded in
IEEE double, in Python and in torch's SIMD lanes alike) in the same order, and compare squares
where a distance or an angle is tested, so every decision and every state matches bit for bit
(tests check it on random rollouts). It reads the map and the collision grid through
:class:`ScalarBoard`, a cache of Python lists.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

from .grid import CollisionGrid, collision_grid
from .maps import PinballMap

__all__ = ["ScalarBoard", "scalar_board", "step_one", "substeps"]

SUBSTEPS = 20
DRAG = 0.995
_COS2_APPROACH = math.cos(math.pi / 1.99) ** 2
_IMPULSE = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (0.0, 0.0))


@dataclass(frozen=True)
class ScalarBoard:
    """A map and its grid as Python lists, for :func:`step_one`."""

    r: float
    target: tuple[float, float]
    target_r2: float
    edges: tuple  # per edge: (ax, ay, ex, ey, ee, polygon)
    clearance: list
    cell_edges: _CellEdges  # cell_edges[cell]: tuple of edge ids, read from the grid on demand
    grid: CollisionGrid

    @classmethod
    def build(cls, pinball_map: PinballMap) -> ScalarBoard:
        grid = collision_grid(pinball_map)
        a = pinball_map.edge_start.double().cpu().tolist()
        b = pinball_map.edge_end.double().cpu().tolist()
        poly = pinball_map.edge_polygon.cpu().tolist()
        edges = []
        for (ax, ay), (bx, by), k in zip(a, b, poly):
            ex, ey = bx - ax, by - ay
            edges.append((ax, ay, ex, ey, ex * ex + ey * ey, k))
        tr = pinball_map.target_radius
        return cls(
            pinball_map.ball_radius,
            tuple(pinball_map.target),
            tr * tr,
            tuple(edges),
            grid.clearance.double().cpu().tolist(),
            _CellEdges(grid),
            grid,
        )

    def cell(self, x: float, y: float) -> int:
        g, h = self.grid.resolution, self.grid.cell_size
        i = min(max(math.floor(x / h) + 1, 0), g - 1)
        j = min(max(math.floor(y / h) + 1, 0), g - 1)
        return j * g + i


class _CellEdges(dict):
    """``cell -> tuple of candidate edge ids``, filled from the grid as cells are visited.

    Why lazy: a list of every cell's tuple costs ~36 bytes per (cell, edge) entry in Python
    ints, far more than the grid itself on large maps, and a ball visits few cells.
    """

    def __init__(self, grid: CollisionGrid):
        super().__init__()
        self._grid = grid

    def __missing__(self, cell: int) -> tuple:
        ids = self[cell] = tuple(self._grid.cell_edge_list(cell))
        return ids


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def scalar_board(pinball_map: PinballMap) -> ScalarBoard:
    """The :class:`ScalarBoard` of ``pinball_map``, built once and cached."""
    board = _CACHE.get(pinball_map)
    if board is None:
        board = _CACHE[pinball_map] = ScalarBoard.build(pinball_map)
    return board


def step_one(state, action: int, board: ScalarBoard):
    """One step of one ball: ``((x, y, xdot, ydot), terminated, events)``.

    ``events`` counts substeps with a single-edge reflection, a multi-edge contact on one
    polygon, a multi-polygon contact and the out-of-bounds fallback, as the batched path does.

    Example:
        >>> from skillchain_torch.envs.pinball import load_map
        >>> board = scalar_board(load_map("pinball_simple_single"))
        >>> step_one((0.2, 0.9, 0.0, 0.0), 0, board)[0][2]
        0.199
    """
    x, y, vx, vy = state
    ix, iy = _IMPULSE[action]
    vx = min(max(vx + ix / 5.0, -1.0), 1.0)
    vy = min(max(vy + iy / 5.0, -1.0), 1.0)
    r = board.r
    cell = board.cell(x, y)
    events = [0, 0, 0, 0]
    if CollisionGrid.is_free(board.clearance[cell], vx * vx + vy * vy, r):
        dx, dy = vx * r / SUBSTEPS, vy * r / SUBSTEPS
        for _ in range(SUBSTEPS):
            x += dx
            y += dy
        return (x, y, vx * DRAG, vy * DRAG), False, events

    # Keep the candidate edges this step can reach: a ball travels at most 21 |v| r / 20.
    reach = r + 21.0 * math.sqrt(vx * vx + vy * vy) * r / SUBSTEPS + 1e-9
    reach2 = reach * reach
    candidates = []
    for i in board.cell_edges[cell]:
        ax, ay, ex, ey, ee, _ = edge = board.edges[i]
        t = ((x - ax) * ex + (y - ay) * ey) / ee
        t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        dx, dy = x - (ax + ex * t), y - (ay + ey * t)
        if dx * dx + dy * dy <= reach2:
            candidates.append(edge)
    x, y, vx, vy, terminated = substeps(x, y, vx, vy, 0, candidates, board, events)
    if terminated:
        return (x, y, vx, vy), True, events

    vx, vy = vx * DRAG, vy * DRAG
    moved = False
    if x > 1.0:
        x, moved = 0.95, True
    elif x < 0.0:
        x, moved = 0.05, True
    if y > 1.0:
        y, moved = 0.95, True
    elif y < 0.0:
        y, moved = 0.05, True
    if moved:
        vx, vy = 0.0, 0.0
        events[3] += 1
    return (x, y, vx, vy), False, events


def substeps(x, y, vx, vy, j: int, candidates, board: ScalarBoard, events: list):
    """Substeps ``j..19`` of one ball near ``candidates``: ``(x, y, vx, vy, terminated)``.

    No drag and no bounds check (the caller's). The tensor path also calls this to finish the
    few balls that still have events after its first vectorised pass.
    """
    r = board.r
    tx, ty = board.target
    r2 = r * r
    while j < SUBSTEPS:
        x += vx * r / SUBSTEPS
        y += vy * r / SUBSTEPS
        hit = []
        vv = vx * vx + vy * vy
        for ax, ay, ex, ey, ee, poly in candidates:
            t = ((x - ax) * ex + (y - ay) * ey) / ee
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            dx = x - (ax + ex * t)
            dy = y - (ay + ey * t)
            dist2 = dx * dx + dy * dy
            if dist2 <= r2:
                toward = -(dx * vx + dy * vy)
                if toward >= 0.0 or toward * toward <= _COS2_APPROACH * dist2 * vv:
                    hit.append((ex, ey, ee, poly))
        if hit:
            one_polygon = all(h[3] == hit[0][3] for h in hit)
            if len(hit) == 1:
                ex, ey, ee, _ = hit[0]
                scale = 2.0 * (vx * ex + vy * ey) / ee
                vx, vy = scale * ex - vx, scale * ey - vy
                events[0] += 1
            else:
                vx, vy = -vx, -vy
                events[1 if one_polygon else 2] += 1
            if one_polygon and j == SUBSTEPS - 1:
                x += vx * r / SUBSTEPS
                y += vy * r / SUBSTEPS
        gx, gy = x - tx, y - ty
        if gx * gx + gy * gy < board.target_r2:
            return x, y, vx, vy, True
        j += 1
    return x, y, vx, vy, False
