"""The tensor path's substeps for balls near an obstacle, processed event to event.

Why the code does not look like the Java loop: from a ball's current substep, the positions of
all remaining substeps under constant velocity are one ``cumsum`` (:func:`flight`,
bit-identical to repeated ``p += d``); the first substep with a contact (:func:`contacts`) or
the goal is found in one pass; the event is resolved and the scan restarts from the next
substep (:func:`resolve_near`). The step (:mod:`.physics`) sends here only the balls its
:class:`~skillchain_torch.envs.pinball.grid.CollisionGrid` cannot prove free for the whole
step, with the few candidate edges of their cell.

Why no atan2: Java reflects with atan2/cos/sin; the vector form ``v' = 2 (v.e)/(e.e) e - v``
agrees to ~1e-16 and uses only correctly rounded arithmetic, so a ball's trajectory does not
depend on which batch it is in (torch's vectorised atan2 differs in the last bit between SIMD
lanes and the scalar tail). The approaching test likewise compares a dot product with
``cos(pi/1.99)``.

Example:
    >>> p = torch.zeros(1, 2, dtype=torch.float64)
    >>> d = torch.tensor([[0.001, 0.0]], dtype=torch.float64)
    >>> flight(p, d)[0, -1].tolist()  # 20 substeps of d
    [0.02000000000000001, 0.0]
"""

from __future__ import annotations

import math

import torch

from .maps import PinballMap

__all__ = ["SUBSTEPS", "flight", "contacts", "resolve_near"]

SUBSTEPS = 20
# The Java approaching test accepts an edge when angle(c - p, v) <= pi / 1.99.
_COS_APPROACH = math.cos(math.pi / 1.99)
_COS2_APPROACH = _COS_APPROACH * _COS_APPROACH


def flight(p: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """Positions after each of 20 substeps of constant displacement: ``[B, 20, 2]``.

    A cumsum over ``[p, d, d, ...]`` adds left to right, so it equals Java's repeated ``p += d``
    bit for bit.
    """
    steps = torch.cat([p[:, None, :], d[:, None, :].expand(-1, SUBSTEPS, -1)], dim=1)
    return torch.cumsum(steps, dim=1)[:, 1:]


def resolve_near(p, v, pinball_map: PinballMap, grid, with_events: bool):
    """Run the 20 substeps of balls near something, event to event; returns
    ``(p, v, terminated, events)`` (``events``: columns 0-2 counted, column 3 zero).

    ``p [m, 2]`` and ``v [m, 2]``: positions at the start of the step and velocities after the
    impulse and clip. No drag and no bounds check: the step applies them to balls that did not
    reach the goal.

    Example:
        >>> from skillchain_torch.envs.pinball import load_map
        >>> from skillchain_torch.envs.pinball.grid import collision_grid
        >>> m = load_map("pinball_simple_single")
        >>> p = torch.tensor([[0.9, 0.15]], dtype=torch.float64)  # just below the target
        >>> v = torch.tensor([[0.0, 1.0]], dtype=torch.float64)
        >>> resolve_near(p, v, m, collision_grid(m), True)[2].tolist()
        [True]
    """
    m, device = p.shape[0], p.device
    r = pinball_map.ball_radius
    tx, ty = pinball_map.target
    big_r2 = pinball_map.target_radius * pinball_map.target_radius
    # Candidate edges of the start cell, fixed for the step (the grid's reach covers it).
    # Padding (-1) picks the table's last row, an edge far away that never touches.
    cand = grid.candidates(grid.cell_index(p))  # [m, K]
    geometry = grid.edge_geometry.to(p.dtype)[cand]  # [m, K, 5]: ax, ay, ex, ey, |e|^2
    polygon = grid.edge_polygon[cand]  # [m, K]

    j = torch.zeros(m, dtype=torch.long, device=device)  # substeps done
    terminated = torch.zeros(m, dtype=torch.bool, device=device)
    events = torch.zeros(m, 4, dtype=torch.long, device=device)
    substep = torch.arange(SUBSTEPS, device=device)
    alive = None  # None: every ball (saves the gathers on the first, largest pass)
    while True:
        pa, va, ja, geo, poly = (
            (p, v, j, geometry, polygon)
            if alive is None
            else (p[alive], v[alive], j[alive], geometry[alive], polygon[alive])
        )
        n = pa.shape[0]
        positions = flight(pa, va * r / SUBSTEPS)  # [n, 20, 2]
        contact = contacts(positions, va, geo, r)  # [n, 20, K]
        gx, gy = positions[..., 0] - tx, positions[..., 1] - ty
        event = (contact.any(-1) | (gx * gx + gy * gy < big_r2)) & (
            ja[:, None] + substep < SUBSTEPS
        )
        has_event = event.any(-1)
        # First event substep, or the last substep of the step for balls without one.
        k = torch.where(has_event, event.to(torch.int8).argmax(-1), SUBSTEPS - 1 - ja)
        rows = torch.arange(n, device=device)
        pa = positions[rows, k]
        hit = contact[rows, k] & has_event[:, None]  # [n, K]
        n_edges = hit.sum(-1)
        # One contacting edge: reflect about it; two or more (one polygon or several): reverse.
        e = geo[rows, hit.to(torch.int8).argmax(-1)]  # [n, 5]
        scale = 2.0 * (va[:, 0] * e[:, 2] + va[:, 1] * e[:, 3]) / e[:, 4]
        reflected = torch.stack([scale * e[:, 2] - va[:, 0], scale * e[:, 3] - va[:, 1]], -1)
        va = torch.where(
            (n_edges == 1)[:, None], reflected, torch.where((n_edges > 1)[:, None], -va, va)
        )
        hit_poly = torch.where(hit, poly, -1).amax(-1)  # (Tensor.max(dim) on int64: ~10 ms!)
        one_polygon = (n_edges > 0) & (
            torch.where(hit, poly, hit_poly[:, None]) == hit_poly[:, None]
        ).all(-1)
        # One extra substep after a single-polygon bounce on the last substep.
        extra = one_polygon & (ja + k == SUBSTEPS - 1)
        pa = torch.where(extra[:, None], pa + va * r / SUBSTEPS, pa)
        gx, gy = pa[:, 0] - tx, pa[:, 1] - ty
        reached = has_event & (gx * gx + gy * gy < big_r2)
        go_on = has_event & ~reached & (ja + k + 1 < SUBSTEPS)
        if with_events:
            counts = torch.stack(
                [n_edges == 1, one_polygon & (n_edges > 1), (n_edges > 0) & ~one_polygon], -1
            ).long()
        if alive is None:
            p, v, terminated, j = pa, va, reached, ja + k + 1
            if with_events:
                events[:, :3] += counts
            alive = go_on.nonzero()[:, 0]
        else:
            p[alive], v[alive], terminated[alive], j[alive] = pa, va, reached, ja + k + 1
            if with_events:
                events[alive, :3] += counts
            alive = alive[go_on]
        if alive.numel() == 0:
            break

    return p, v, terminated, events


def contacts(positions, v, geo, r: float):
    """Which candidate edges each substep position touches while approaching: ``[n, 20, K]``.

    Java's tests: the closest point ``c`` of the segment is within ``r`` (inclusive), and the
    angle between ``c - p`` and ``v`` is at most pi/1.99. ``cos(pi/1.99) < 0``, so the angle
    test is ``toward >= 0`` or ``toward^2 <= cos^2 |c - p|^2 |v|^2`` (squares, no sqrt, so the
    decision cannot depend on the SIMD lane a ball lands in).
    """
    px, py = positions[..., 0:1], positions[..., 1:2]  # [n, 20, 1]
    ax, ay, ex, ey, ee = (geo[:, None, :, i] for i in range(5))  # [n, 1, K]
    t = (((px - ax) * ex + (py - ay) * ey) / ee).clamp(0.0, 1.0)
    dx = px - (ax + ex * t)
    dy = py - (ay + ey * t)
    dist2 = dx * dx + dy * dy
    vx, vy = v[:, 0, None, None], v[:, 1, None, None]
    toward = -(dx * vx + dy * vy)
    approaching = (toward >= 0.0) | (
        toward * toward <= _COS2_APPROACH * dist2 * (vx * vx + vy * vy)
    )
    return (dist2 <= r * r) & approaching
