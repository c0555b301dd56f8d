"""The Pinball dynamics of the original Java implementation, as a pure batched function.

``pinball_step(state, action, pinball_map)`` advances raw states ``[B, 4]`` (x, y, xdot, ydot)
by one step of actions ``[B]`` exactly as ``PinBall.step`` does (see ``PHYSICS.md`` sections
3 to 6 of the project's shared notes):

* the impulse (+-0.2 on one component) and the per-component clip to [-1, 1];
* 20 substeps of ``p += v r / 20``; after each, every polygon is tested at the new position;
  one polygon with one contacting edge reflects ``v`` about that edge, one polygon with two or
  more edges or two or more polygons reverse ``v``; a single-polygon bounce on the last substep
  is followed by one extra substep;
* an edge counts only if the ball is not moving away from it (angle between ``v`` and the
  direction to the contact point at most pi/1.99);
* the goal (centre strictly inside the target disc) is tested after every substep and ends the
  step at once, with reward +10000 replacing the step penalty and no drag;
* otherwise drag 0.995 once per step, then the out-of-bounds fallback (x > 1 -> 0.95,
  x < 0 -> 0.05, likewise y, velocity set to 0).

Why the code does not look like the Java loop: substeps are processed *event to event*. From a
ball's current substep, the positions of all remaining substeps under constant velocity are one
``cumsum`` (bit-identical to repeated ``p += d``); the first substep with a contact or the goal is
found in one pass; the event is resolved and the scan restarts from the next substep. A
:class:`~skillchain_torch.envs.pinball.grid.CollisionGrid` first sends balls that cannot meet
anything during this step down a free-flight path, and gives the others a few candidate edges.

Why no atan2: Java reflects with atan2/cos/sin; the vector form ``v' = 2 (v.e)/(e.e) e - v``
agrees to ~1e-16 and uses only correctly rounded arithmetic, so a ball's trajectory does not
depend on which batch it is in (torch's vectorised atan2 differs in the last bit between SIMD
lanes and the scalar tail). The approaching test likewise compares a dot product with
``cos(pi/1.99)``.
"""

from __future__ import annotations

import math

import torch

from .grid import collision_grid
from .maps import PinballMap
from .scalar import scalar_board, step_one

__all__ = ["pinball_step", "pinball_step_events", "NUM_ACTIONS", "ACTION_NAMES", "observation"]

NUM_ACTIONS = 5
ACTION_NAMES = ("ACC_X", "ACC_Y", "DEC_X", "DEC_Y", "NONE")
SUBSTEPS = 20
# Up to this many balls on the CPU, stepping them one by one in Python floats beats torch's
# per-operation overhead (benchmarks/env_throughput.py measures the crossover).
SCALAR_MAX_BATCH = 4
DRAG = 0.995
GOAL_REWARD = 10000.0
THRUST_PENALTY = -5.0
NONE_PENALTY = -1.0
# The Java approaching test accepts an edge when angle(c - p, v) <= pi / 1.99.
_COS_APPROACH = math.cos(math.pi / 1.99)
_COS2_APPROACH = _COS_APPROACH * _COS_APPROACH
# (dx, dy) of each action: +x, +y, -x, -y, none. The impulse is this / 5.
_IMPULSE = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (0.0, 0.0))


def observation(state: torch.Tensor) -> torch.Tensor:
    """The Java descriptor ``(x, y, (xdot + 1) / 2, (ydot + 1) / 2)`` of raw states ``[..., 4]``.

    Example:
        >>> observation(torch.tensor([[0.2, 0.9, 0.0, -1.0]], dtype=torch.float64))
        tensor([[0.2000, 0.9000, 0.5000, 0.0000]], dtype=torch.float64)
    """
    return torch.cat([state[..., :2], (state[..., 2:] + 1.0) / 2.0], dim=-1)


def pinball_step(state: torch.Tensor, action: torch.Tensor, pinball_map: PinballMap):
    """Advance raw states by one step; returns ``(next_state, reward, terminated)``.

    Args:
        state: ``[B, 4]`` raw (x, y, xdot, ydot), floating point (float64 is the reference).
        action: ``[B]`` int64 in ``0..4`` (+x, +y, -x, -y, none).
        pinball_map: the board (:func:`~skillchain_torch.envs.pinball.load_map`), on the
            device and dtype of ``state``.

    Returns:
        next_state ``[B, 4]``, reward ``[B]`` (-1, -5 or +10000) and terminated ``[B]`` bool.

    Example:
        >>> from skillchain_torch.envs.pinball import load_map
        >>> m = load_map("pinball_simple_single")
        >>> s = torch.tensor([[0.2, 0.9, 0.0, 0.0]], dtype=torch.float64)
        >>> s1, r, done = pinball_step(s, torch.tensor([0]), m)
        >>> s1[0, 2].item(), r.item(), done.item()
        (0.199, -5.0, False)
    """
    next_state, reward, terminated, _ = _step(state, action, pinball_map, with_events=False)
    return next_state, reward, terminated


def pinball_step_events(state: torch.Tensor, action: torch.Tensor, pinball_map: PinballMap):
    """:func:`pinball_step` plus per-ball event counts ``[B, 4]`` for diagnostics.

    Columns, as in the reference vectors: substeps with a single-edge reflection, with a
    two-or-more-edge contact on one polygon (v := -v), with contacts on two or more polygons
    (v := -v), and out-of-bounds fallbacks.
    """
    return _step(state, action, pinball_map, with_events=True)


def check_inputs(state: torch.Tensor, action: torch.Tensor, pinball_map: PinballMap) -> None:
    """Raise a ``ValueError`` naming the problem if ``state``/``action`` cannot be stepped."""
    if state.ndim != 2 or state.shape[-1] != 4:
        raise ValueError(f"state must have shape [B, 4] (x, y, xdot, ydot), got {tuple(state.shape)}")
    if not state.is_floating_point():
        raise ValueError(f"state must be a floating-point tensor, got dtype {state.dtype}")
    if action.shape != state.shape[:1]:
        raise ValueError(f"action must have shape [{state.shape[0]}], got {tuple(action.shape)}")
    if action.dtype not in (torch.int64, torch.int32, torch.int16, torch.int8, torch.uint8):
        raise ValueError(f"action must be an integer tensor (int64), got dtype {action.dtype}")
    bad = (action < 0) | (action >= NUM_ACTIONS)
    if bool(bad.any()):
        i = int(bad.nonzero()[0, 0])
        raise ValueError(
            f"action[{i}] = {int(action[i])} is out of range: actions are 0..4 "
            "(0 +x, 1 +y, 2 -x, 3 -y, 4 none)"
        )
    finite = torch.isfinite(state).all(dim=-1)
    if not bool(finite.all()):
        i = int((~finite).nonzero()[0, 0])
        raise ValueError(f"state[{i}] = {state[i].tolist()} is not finite")
    if pinball_map.edge_start.device != state.device:
        raise ValueError(
            f"pinball_map is on {pinball_map.edge_start.device} but state is on {state.device}; "
            "use pinball_map.to(state.device)"
        )


def _step(state, action, pinball_map, with_events: bool, scalar_max_batch: int | None = None):
    check_inputs(state, action, pinball_map)
    limit = SCALAR_MAX_BATCH if scalar_max_batch is None else scalar_max_batch
    if state.shape[0] <= limit and state.device.type == "cpu" and state.dtype == torch.float64:
        return _step_scalar(state, action, pinball_map)
    grid = collision_grid(pinball_map)
    r = pinball_map.ball_radius
    impulse = torch.tensor(_IMPULSE, dtype=state.dtype, device=state.device)

    p = state[:, :2]
    v = (state[:, 2:] + impulse[action] / 5.0).clamp(-1.0, 1.0)  # Java: v += d / 5; clip
    d = v * r / SUBSTEPS
    free_end = _flight(p, d)[:, -1]

    vv = v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]
    near = ~grid.is_free(grid.clearance.to(state.dtype)[grid.cell_index(p)], vv, r)

    next_p = free_end
    next_v = v * DRAG
    terminated = torch.zeros(state.shape[0], dtype=torch.bool, device=state.device)
    events = torch.zeros(state.shape[0], 4, dtype=torch.long, device=state.device)
    if bool(near.any()):
        idx = near.nonzero()[:, 0]
        p_n, v_n, term_n, ev_n = _resolve_near(p[idx], v[idx], pinball_map, grid)
        next_p = next_p.index_put((idx,), p_n)
        next_v = next_v.index_put((idx,), v_n)
        terminated = terminated.index_put((idx,), term_n)
        events = events.index_put((idx,), ev_n)

    next_state = torch.cat([next_p, next_v], dim=-1)
    penalty = torch.where(action == NUM_ACTIONS - 1, NONE_PENALTY, THRUST_PENALTY)
    reward = torch.where(terminated, GOAL_REWARD, penalty).to(state.dtype)
    return next_state, reward, terminated, events


def _step_scalar(state, action, pinball_map):
    """Tiny CPU batches: one ball at a time in Python floats (bit-identical, see scalar.py)."""
    board = scalar_board(pinball_map)
    rows, done, events = [], [], []
    for s, a in zip(state.tolist(), action.tolist()):
        s1, term, ev = step_one(s, a, board)
        rows.append(s1)
        done.append(term)
        events.append(ev)
    next_state = torch.tensor(rows, dtype=state.dtype).reshape(state.shape)
    terminated = torch.tensor(done, dtype=torch.bool)
    reward = torch.tensor(
        [GOAL_REWARD if t else (NONE_PENALTY if a == 4 else THRUST_PENALTY)
         for t, a in zip(done, action.tolist())],
        dtype=state.dtype,
    )
    return next_state, reward, terminated, torch.tensor(events, dtype=torch.long).reshape(-1, 4)


def _flight(p: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """Positions after each of 20 substeps of constant displacement: ``[B, 20, 2]``.

    A cumsum over ``[p, d, d, ...]`` adds left to right, so it equals Java's repeated ``p += d``
    bit for bit.
    """
    steps = torch.cat([p[:, None, :], d[:, None, :].expand(-1, SUBSTEPS, -1)], dim=1)
    return torch.cumsum(steps, dim=1)[:, 1:]


def _resolve_near(p, v, pinball_map: PinballMap, grid):
    """Run one step event to event for balls near something; returns (p, v, terminated, events).

    ``v`` is the velocity after the impulse and clip. Drag and the bounds check are applied
    here for balls that did not reach the goal.
    """
    m, dtype, device = p.shape[0], p.dtype, p.device
    r = pinball_map.ball_radius
    r2 = r * r
    tx, ty = pinball_map.target
    big_r2 = pinball_map.target_radius * pinball_map.target_radius

    cand = grid.cell_edges[grid.cell_index(p)]  # [m, K]; fixed for the step (grid reach covers it)
    valid = cand >= 0
    cand = cand.clamp_min(0)
    a = pinball_map.edge_start[cand]  # [m, K, 2]
    e = pinball_map.edge_end[cand] - a
    ee = e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1]
    poly = torch.where(valid, pinball_map.edge_polygon[cand], -1)

    j = torch.zeros(m, dtype=torch.long, device=device)  # next substep to run
    terminated = torch.zeros(m, dtype=torch.bool, device=device)
    events = torch.zeros(m, 4, dtype=torch.long, device=device)
    substep = torch.arange(SUBSTEPS, device=device)
    alive = torch.arange(m, device=device)
    while alive.numel() > 0:
        pa, va, ja = p[alive], v[alive], j[alive]
        ax, ay = a[alive, None, :, 0], a[alive, None, :, 1]  # [n, 1, K]
        ex, ey, eea = e[alive, None, :, 0], e[alive, None, :, 1], ee[alive, None, :]
        positions = _flight(pa, va * r / SUBSTEPS)  # [n, 20, 2]
        px, py = positions[..., 0:1], positions[..., 1:2]  # [n, 20, 1]
        # Closest point on each candidate edge and the contact test (Java: dist^2 <= r^2).
        t = (((px - ax) * ex + (py - ay) * ey) / eea).clamp(0.0, 1.0)
        dx = px - (ax + ex * t)
        dy = py - (ay + ey * t)
        dist2 = dx * dx + dy * dy
        vx, vy = va[:, 0, None, None], va[:, 1, None, None]
        # Approaching: angle between (closest - p) = (-dx, -dy) and v at most pi / 1.99, i.e.
        # toward >= cos(pi/1.99) |c - p| |v|. cos(pi/1.99) < 0, so compare squares when toward < 0
        # (no sqrt: the decision must not depend on the SIMD lane a ball lands in).
        toward = -(dx * vx + dy * vy)
        moving_to = (toward >= 0.0) | (toward * toward <= _COS2_APPROACH * dist2 * (vx * vx + vy * vy))
        contact = (dist2 <= r2) & moving_to & valid[alive, None, :]
        gx, gy = positions[..., 0] - tx, positions[..., 1] - ty
        goal = gx * gx + gy * gy < big_r2  # [n, 20]
        remaining = (ja[:, None] + substep) < SUBSTEPS
        event = (contact.any(-1) | goal) & remaining
        has_event = event.any(-1)

        k = torch.where(has_event, event.to(torch.int8).argmax(-1), SUBSTEPS - 1 - ja)
        rows = torch.arange(alive.numel(), device=device)
        pa = positions[rows, k]
        hit = contact[rows, k] & has_event[:, None]  # [n, K]
        n_edges = hit.sum(-1)
        # Response: reflect about the one contacting edge, otherwise reverse.
        first = hit.to(torch.int8).argmax(-1)
        fex, fey, fee = e[alive, first, 0], e[alive, first, 1], ee[alive, first]
        scale = 2.0 * (va[:, 0] * fex + va[:, 1] * fey) / fee
        reflected = torch.stack([scale * fex - va[:, 0], scale * fey - va[:, 1]], dim=-1)
        va = torch.where((n_edges == 1)[:, None], reflected, torch.where((n_edges > 1)[:, None], -va, va))
        poly_hit = torch.where(hit, poly[alive], -1)
        poly_lo = torch.where(hit, poly[alive], torch.iinfo(torch.long).max).min(-1).values
        one_polygon = (n_edges > 0) & (poly_hit.max(-1).values == poly_lo)
        # One extra substep after a single-polygon bounce on the last substep.
        extra = one_polygon & (ja + k == SUBSTEPS - 1)
        pa = torch.where(extra[:, None], pa + va * r / SUBSTEPS, pa)
        gx, gy = pa[:, 0] - tx, pa[:, 1] - ty
        reached = has_event & (gx * gx + gy * gy < big_r2)

        p[alive], v[alive] = pa, va
        terminated[alive] = reached
        j[alive] = ja + k + 1
        events[alive, 0] += (n_edges == 1).long()
        events[alive, 1] += (one_polygon & (n_edges > 1)).long()
        events[alive, 2] += ((n_edges > 0) & ~one_polygon).long()
        go_on = has_event & ~reached & (ja + k + 1 < SUBSTEPS)
        alive = alive[go_on]

    # Drag once per step, then the out-of-bounds fallback, for balls still in play.
    v = torch.where(terminated[:, None], v, v * DRAG)
    low, high = p < 0.0, p > 1.0
    moved = (low | high).any(-1) & ~terminated
    p = torch.where(high & ~terminated[:, None], 0.95, torch.where(low & ~terminated[:, None], 0.05, p))
    v = torch.where(moved[:, None], 0.0, v)
    events[:, 3] += moved.long()
    return p.to(dtype), v, terminated, events
