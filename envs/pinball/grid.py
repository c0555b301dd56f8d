"""A uniform grid over the board that tells the physics where nothing can happen.

The original simulator tests every polygon at every one of the 20 substeps. Most steps of a
ball are free flight, far from every edge, the target and the border; the grid lets
``pinball_step`` recognise those steps with one lookup and skip the per-edge tests, and gives
the remaining ("near") balls a short list of candidate edges instead of all of them. Both are
conservative bounds, so the trajectory is the same as testing everything.

For a cell with centre ``c`` and half-diagonal ``h``, any start position ``p`` in the cell
satisfies ``|p - c| <= h``. During one step a ball of speed ``|v|`` travels at most
``20 |v| r / 20 = |v| r`` in free flight (and ``21 |v| r / 20`` with the extra substep after a
bounce, which needs a collision first). Hence:

* ``clearance[c] = min(edge distance - r, target distance - R, border distance) - h``: a ball in
  the cell with ``|v| r < clearance`` cannot touch an edge, reach the goal or leave the board
  during this step;
* ``cell_edges[c]``: every edge within ``r + 21 sqrt(2) r / 20 + h`` of the centre (speed is at
  most sqrt(2) after the per-component clip), padded with -1. A near ball only tests these.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import torch

from .maps import PinballMap

__all__ = ["CollisionGrid", "collision_grid"]


def point_segment_distance(points: torch.Tensor, start: torch.Tensor, end: torch.Tensor):
    """Distance from each point ``[N, 2]`` to each segment ``[E, 2] -> [E, 2]``: ``[N, E]``."""
    e = end - start
    diff = points[:, None, :] - start[None]
    t = ((diff * e).sum(-1) / (e * e).sum(-1).clamp_min(1e-300)).clamp(0.0, 1.0)
    closest = start[None] + t[..., None] * e[None]
    return (points[:, None, :] - closest).norm(dim=-1)


@dataclass(frozen=True)
class CollisionGrid:
    """Precomputed free-flight clearance and candidate edges on a ``G x G`` grid.

    Cells cover ``[-h, 1 + h]`` on each axis (one border cell beyond the unit square), so any
    position, even outside the board, clamps into a cell whose clearance is negative there.

    Example:
        >>> from skillchain_torch.envs.pinball import load_map
        >>> grid = collision_grid(load_map("pinball_simple_single"))
        >>> grid.cell_edges.shape[0] == grid.resolution ** 2
        True
    """

    resolution: int
    cell_size: float
    clearance: torch.Tensor  # [G*G] float64
    cell_edges: torch.Tensor  # [G*G, K] int64, -1 = none
    edge_geometry: torch.Tensor  # [E + 1, 5] float64: ax, ay, ex, ey, |e|^2; last row: padding
    edge_polygon: torch.Tensor  # [E + 1] int64; last row -1

    @classmethod
    def build(cls, pinball_map: PinballMap, resolution: int = 128) -> CollisionGrid:
        f64 = torch.float64
        g = int(resolution)
        h = 1.0 / (g - 2)  # g - 2 interior cells span the unit square, one border cell each side
        centres_1d = (torch.arange(g, dtype=f64) - 0.5) * h
        cy, cx = torch.meshgrid(centres_1d, centres_1d, indexing="ij")
        centres = torch.stack([cx.reshape(-1), cy.reshape(-1)], dim=-1)  # row-major: y, then x
        half_diag = h * math.sqrt(0.5)
        r = pinball_map.ball_radius

        start = pinball_map.edge_start.to("cpu", f64)
        end = pinball_map.edge_end.to("cpu", f64)
        if start.shape[0] > 0:
            dist = point_segment_distance(centres, start, end)  # [G*G, E]
            edge_clear = dist.min(dim=1).values - r
        else:
            dist = torch.empty(centres.shape[0], 0, dtype=f64)
            edge_clear = torch.full((centres.shape[0],), math.inf, dtype=f64)
        target = torch.tensor(pinball_map.target, dtype=f64)
        goal_clear = (centres - target).norm(dim=-1) - pinball_map.target_radius
        border_clear = torch.minimum(centres, 1.0 - centres).min(dim=-1).values
        clearance = torch.minimum(torch.minimum(edge_clear, goal_clear), border_clear) - half_diag

        reach = r + 21.0 * math.sqrt(2.0) * r / 20.0 + half_diag + 1e-9
        near = dist <= reach
        k = max(int(near.sum(dim=1).max().item()) if near.numel() else 0, 1)
        # Sort so each cell's candidate edges come first, in file order (stable).
        order = torch.argsort((~near).to(torch.int8), dim=1, stable=True)[:, :k]
        cell_edges = (
            torch.where(torch.gather(near, 1, order), order, -1)
            if near.numel()
            else (torch.full((centres.shape[0], 1), -1, dtype=torch.long))
        )
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
            cell_edges.to(device),
            geometry.to(device),
            polygon.to(device),
        )

    @staticmethod
    def is_free(clearance, vv, r: float):
        """Whether a ball with squared speed ``vv`` in a cell of this ``clearance`` flies free.

        Free flight travels ``|v| r`` per step; the test compares squares (no sqrt) with a
        relative margin, and works on floats and tensors alike, so the scalar and batched
        paths decide identically.
        """
        c = clearance - 1e-12
        return (c > 0.0) & (c * c > vv * _RR_MARGIN * (r * r))

    def cell_index(self, xy: torch.Tensor) -> torch.Tensor:
        """Flat cell index of positions ``[..., 2]`` (positions off the grid clamp to its rim)."""
        g = self.resolution
        ij = torch.floor(xy / self.cell_size).to(torch.long) + 1
        ij = ij.clamp(0, g - 1)
        return ij[..., 1] * g + ij[..., 0]


_RR_MARGIN = (1.0 + 1e-9) ** 2
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def collision_grid(pinball_map: PinballMap) -> CollisionGrid:
    """The grid of ``pinball_map``, built once per map object and cached."""
    grid = _CACHE.get(pinball_map)
    if grid is None:
        grid = CollisionGrid.build(pinball_map)
        _CACHE[pinball_map] = grid
    return grid
