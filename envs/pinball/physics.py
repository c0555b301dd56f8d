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

A :class:`~skillchain_torch.envs.pinball.grid.CollisionGrid` sends balls that cannot meet
anything during this step down a free-flight path; the others run their substeps event to event
(:mod:`.collisions`, which also says why the code does not look like the Java loop).

Two paths, one set of bits: the tensor code below is the definition; on the CPU in float64
every batch goes through the compiled step instead (:mod:`.native`, the env's documented fast
path, when ``pip install`` could compile it). Tests step random rollouts and the Java reference
trajectories through both and compare every bit.
"""

from __future__ import annotations

import torch

from . import native
from .collisions import SUBSTEPS, flight, resolve_near
from .grid import collision_grid
from .maps import PinballMap

__all__ = ["pinball_step", "pinball_step_events", "NUM_ACTIONS", "ACTION_NAMES", "observation"]

NUM_ACTIONS = 5
ACTION_NAMES = ("ACC_X", "ACC_Y", "DEC_X", "DEC_Y", "NONE")
# On the CPU in float64, every batch goes through the compiled step when it was built
# (native.py: the same bits, ~0.3 us a ball). Tests switch it off to check the other paths.
NATIVE = native.AVAILABLE
DRAG = 0.995
GOAL_REWARD = 10000.0
THRUST_PENALTY = -5.0
NONE_PENALTY = -1.0
# (dx, dy) of each action: +x, +y, -x, -y, none. The impulse is this / 5.
_IMPULSE = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (0.0, 0.0))


def observation(state: torch.Tensor) -> torch.Tensor:
    """The Java descriptor ``(x, y, (xdot + 1) / 2, (ydot + 1) / 2)`` of raw states ``[..., 4]``.

    Example:
        >>> observation(torch.tensor([[0.2, 0.9, 0.0, -1.0]], dtype=torch.float64))
        tensor([[0.2000, 0.9000, 0.5000, 0.0000]], dtype=torch.float64)
    """
    # x * (1, 1, 1/2, 1/2) + (0, 0, 1/2, 1/2) equals (x, y, (xdot + 1) / 2, (ydot + 1) / 2) bit for
    # bit (halving is exact), in two operations instead of a slice-and-concatenate.
    scale, shift = _descriptor_affine(state)
    return state * scale + shift


def _descriptor_affine(state: torch.Tensor):
    key = (state.dtype, state.device)
    affine = _AFFINE.get(key)
    if affine is None:
        scale = torch.tensor([1.0, 1.0, 0.5, 0.5], dtype=state.dtype, device=state.device)
        affine = _AFFINE[key] = (
            scale,
            torch.tensor([0.0, 0.0, 0.5, 0.5], dtype=state.dtype, device=state.device),
        )
    return affine


_AFFINE: dict = {}


def _impulse_table(state: torch.Tensor) -> torch.Tensor:
    key = ("impulse", state.dtype, state.device)
    table = _AFFINE.get(key)
    if table is None:
        table = _AFFINE[key] = torch.tensor(_IMPULSE, dtype=state.dtype, device=state.device)
    return table


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
    _check_structure(state, action, pinball_map)
    bad = (action < 0) | (action >= NUM_ACTIONS)
    if bool(bad.any()):
        i = int(bad.nonzero()[0, 0])
        _raise_bad_action(i, int(action[i]))
    finite = torch.isfinite(state).all(dim=-1)
    if not bool(finite.all()):
        i = int((~finite).nonzero()[0, 0])
        _raise_bad_state(i, state[i].tolist())


def _check_structure(state, action, pinball_map) -> None:
    if state.ndim != 2 or state.shape[-1] != 4:
        raise ValueError(
            f"state must have shape [B, 4] (x, y, xdot, ydot), got {tuple(state.shape)}"
        )
    if not state.is_floating_point():
        raise ValueError(f"state must be a floating-point tensor, got dtype {state.dtype}")
    if action.shape != state.shape[:1]:
        raise ValueError(f"action must have shape [{state.shape[0]}], got {tuple(action.shape)}")
    if action.dtype not in _INT_DTYPES:
        raise ValueError(f"action must be an integer tensor (int64), got dtype {action.dtype}")
    if pinball_map.edge_start.device != state.device:
        raise ValueError(
            f"pinball_map is on {pinball_map.edge_start.device} but state is on {state.device}; "
            "use pinball_map.to(state.device)"
        )


def _raise_bad_action(i: int, value: int):
    raise ValueError(
        f"action[{i}] = {value} is out of range: actions are 0..4 (0 +x, 1 +y, 2 -x, 3 -y, 4 none)"
    )


def _raise_bad_state(i: int, row: list):
    raise ValueError(f"state[{i}] = {row} is not finite")


_INT_DTYPES = (torch.int64, torch.int32, torch.int16, torch.int8, torch.uint8)


def _step(state, action, pinball_map, with_events: bool, compiled: bool = True):
    """The step; ``compiled=False`` runs the tensor path even where the compiled step could."""
    on_cpu64 = state.device.type == "cpu" and state.dtype == torch.float64
    if compiled and NATIVE and on_cpu64:
        # None for maps with more candidate edges per cell than the C step holds: those take
        # the tensor path below (the same bits, slower).
        board = native.board_if_supported(pinball_map)
        if board is not None:
            return _step_native(state, action, pinball_map, board)
    check_inputs(state, action, pinball_map)
    grid = collision_grid(pinball_map)
    r = pinball_map.ball_radius
    impulse = _impulse_table(state)

    p = state[:, :2]
    v = (state[:, 2:] + impulse[action] / 5.0).clamp(-1.0, 1.0)  # Java: v += d / 5; clip
    d = v * r / SUBSTEPS
    free_end = flight(p, d)[:, -1]

    vv = v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]
    near = ~grid.is_free(grid.clearance.to(state.dtype)[grid.cell_index(p)], vv, r)

    next_p = free_end
    next_v = v * DRAG
    terminated = torch.zeros(state.shape[0], dtype=torch.bool, device=state.device)
    events = torch.zeros(state.shape[0], 4, dtype=torch.long, device=state.device)
    if bool(near.any()):
        idx = near.nonzero()[:, 0]
        p_n, v_n, term_n, ev_n = _drag_and_bounds(
            *resolve_near(p[idx], v[idx], pinball_map, grid, with_events))
        next_p = next_p.index_put((idx,), p_n)
        next_v = next_v.index_put((idx,), v_n)
        terminated = terminated.index_put((idx,), term_n)
        events = events.index_put((idx,), ev_n)

    next_state = torch.cat([next_p, next_v], dim=-1)
    penalty = torch.where(action == NUM_ACTIONS - 1, NONE_PENALTY, THRUST_PENALTY)
    reward = torch.where(terminated, GOAL_REWARD, penalty).to(state.dtype)
    return next_state, reward, terminated, events


def _step_native(state, action, pinball_map, board=None):
    """CPU float64 batches of any size through the compiled step (bit-identical, native.py)."""
    _check_structure(state, action, pinball_map)
    n = state.shape[0]
    next_state = state.clone(memory_format=torch.contiguous_format)  # stepped in place
    reward = torch.empty(n, dtype=torch.float64)
    terminated = torch.empty(n, dtype=torch.bool)
    events = torch.empty(n, 4, dtype=torch.long)
    if board is None:
        board = native.native_board(pinball_map)
    action = action.to("cpu", torch.long).contiguous()  # C reads it as int64 host memory
    board.step_into(next_state, action, reward, terminated, None, events, check=False)
    return next_state, reward, terminated, events


def _drag_and_bounds(p, v, terminated, events):
    """Drag once per step, then the out-of-bounds fallback, for near balls still in play."""
    playing = ~terminated[:, None]
    v = torch.where(playing, v * DRAG, v)
    high, low = (p > 1.0) & playing, (p < 0.0) & playing
    moved = (low | high).any(-1)
    p = torch.where(high, 0.95, torch.where(low, 0.05, p))
    v = torch.where(moved[:, None], 0.0, v)
    events[:, 3] += moved.long()
    return p, v, terminated, events
