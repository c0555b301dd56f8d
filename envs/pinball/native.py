"""The compiled Pinball step: the env's documented fast path, a whole CPU batch in one call.

``pip install`` compiles ``_native.c`` when a C compiler is present (``setup.py``). It steps one
ball at a time through the substeps with the same IEEE-double operations, in the same order,
as the tensor path of :mod:`.physics` (the definition), so trajectories are bit-identical to it
(``tests/envs/test_native.py``, ``tests/envs/test_physics.py``); only the speed differs (well
under a microsecond a ball). Without the extension, :data:`AVAILABLE` is False and the physics
runs its tensor path.

Example:
    >>> import torch
    >>> from skillchain_torch.envs.pinball import load_map
    >>> from skillchain_torch.envs.pinball.native import AVAILABLE, native_board
    >>> if AVAILABLE:
    ...     board = native_board(load_map("pinball_simple_single"))
    ...     state = torch.tensor([[0.2, 0.9, 0.0, 0.0]], dtype=torch.float64)
    ...     reward, terminated, n_goal = board.step(state, torch.tensor([0]))
    ...     print(state[0, 2].item(), reward.item(), n_goal)
    ... else:
    ...     print(0.199, -5.0, 0)
    0.199 -5.0 0
"""

from __future__ import annotations

import math
import weakref

import torch
from torch import Tensor

from .grid import collision_grid
from .maps import PinballMap

try:
    from . import _native
except ImportError:  # built without a C compiler: the tensor path takes over
    _native = None

__all__ = ["AVAILABLE", "NativeBoard", "native_board"]

AVAILABLE = _native is not None
# The C candidate list has room for this many edges per grid cell.
_MAX_CANDIDATES = 256
if AVAILABLE:
    # cos(pi / 1.99)^2 (physics.py's approaching test), computed once by Python's math.
    _native.set_cos2_approach(math.cos(math.pi / 1.99) ** 2)


class NativeBoard:
    """A map's edges and collision grid as flat CPU arrays, and the compiled step over them.

    Built from the map's :class:`~.grid.CollisionGrid`, whose edge geometry (edge vectors and
    squared lengths, as the tensor path computes them) and clearances it copies bit for bit.
    """

    def __init__(self, pinball_map: PinballMap):
        if not AVAILABLE:
            raise RuntimeError(
                "the compiled Pinball step is not built (no C compiler at install time); "
                "reinstall with gcc available, or use pinball_step's tensor path"
            )
        f64 = torch.float64
        grid = collision_grid(pinball_map)
        most = _most_candidates(grid)
        if most > _MAX_CANDIDATES:
            raise ValueError(
                f"a grid cell of map {pinball_map.name!r} has {most} candidate edges; the "
                f"compiled step holds at most {_MAX_CANDIDATES} (pinball_step uses its tensor "
                "path for such maps)"
            )
        # Per edge: ax, ay, ex, ey, |e|^2 (the grid's geometry, without its padding row) and
        # the polygon it belongs to.
        self.edges = torch.cat([grid.edge_geometry[:-1].to("cpu", f64),
                                grid.edge_polygon[:-1].to("cpu", f64)[:, None]], -1).contiguous()
        # The grid's own lists (CSR, int64), shared rather than copied: on large maps they are
        # the biggest structure. cell_ids ends with a -1 that no cell's range reaches.
        self.cell_start = grid.cell_start.to("cpu").contiguous()
        self.cell_ids = grid.cell_ids.to("cpu").contiguous()
        self.clearance = grid.clearance.to("cpu", f64).contiguous()
        tr = pinball_map.target_radius
        self.params = torch.tensor(
            [
                pinball_map.ball_radius,
                pinball_map.target[0],
                pinball_map.target[1],
                tr * tr,
                grid.cell_size,
                float(grid.resolution),
                float(self.edges.shape[0]),
                float(self.clearance.shape[0]),
            ],
            dtype=f64,
        )
        self._board_args = (
            self.params.data_ptr(),
            self.edges.data_ptr(),
            self.cell_start.data_ptr(),
            self.cell_ids.data_ptr(),
            self.clearance.data_ptr(),
        )

    def step_into(
        self,
        state: Tensor,
        action: Tensor,
        reward: Tensor,
        terminated: Tensor,
        obs: Tensor | None = None,
        events: Tensor | None = None,
        check: bool = True,
    ) -> int:
        """Advance ``state`` ``[n, 4]`` in place; write the outputs; return the number at the goal.

        Every tensor must be contiguous on the CPU: ``state`` float64, ``action`` int64,
        ``reward`` float64 ``[n]``, ``terminated`` bool ``[n]``, optional ``obs`` float64
        ``[n, 4]`` (the observation after the step) and ``events`` int64 ``[n, 4]``
        (``ValueError`` otherwise: the C code reads raw memory; ``check=False`` skips that
        test, ~10 us, for callers that allocate the tensors themselves). Raises ``ValueError``
        naming the first ball with an action outside 0..4 or a non-finite state; balls before
        it have been stepped.
        """
        n = state.shape[0]
        if check:
            _check_layout(n, state, action, reward, terminated, obs, events)
        out = _native.step(
            n,
            state.data_ptr(),
            action.data_ptr(),
            0 if obs is None else obs.data_ptr(),
            reward.data_ptr(),
            terminated.data_ptr(),
            0 if events is None else events.data_ptr(),
            *self._board_args,
        )
        if out < 0:  # the same errors as pinball_step's tensor path
            from .physics import _raise_bad_action, _raise_bad_state  # (physics imports us)

            i = -out - 1
            a = int(action[i])
            if not 0 <= a <= 4:
                _raise_bad_action(i, a)
            _raise_bad_state(i, state[i].tolist())
        return out

    def step(self, state: Tensor, action: Tensor, events: Tensor | None = None):
        """:meth:`step_into` with fresh ``reward`` and ``terminated``: ``(reward, terminated,
        n)``."""
        n = state.shape[0]
        reward = torch.empty(n, dtype=torch.float64)
        terminated = torch.empty(n, dtype=torch.bool)
        count = self.step_into(state, action, reward, terminated, events=events)
        return reward, terminated, count


def _check_layout(n, state, action, reward, terminated, obs, events) -> None:
    wanted = [("state", state, torch.float64, (n, 4)), ("action", action, torch.int64, (n,)),
              ("reward", reward, torch.float64, (n,)), ("terminated", terminated, torch.bool, (n,))]
    if obs is not None:
        wanted.append(("obs", obs, torch.float64, (n, 4)))
    if events is not None:
        wanted.append(("events", events, torch.int64, (n, 4)))
    for name, t, dtype, shape in wanted:
        if (t.dtype != dtype or tuple(t.shape) != shape or not t.is_contiguous()
                or t.device.type != "cpu"):
            raise ValueError(
                f"{name} must be a contiguous CPU {dtype} tensor of shape {list(shape)}, got "
                f"{t.dtype} {list(t.shape)} on {t.device}"
                f"{'' if t.is_contiguous() else ' (not contiguous)'}")


def _most_candidates(grid) -> int:
    counts = grid.cell_start[1:] - grid.cell_start[:-1]
    return int(counts.max().item()) if counts.numel() else 0


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_UNSUPPORTED = object()


def native_board(pinball_map: PinballMap) -> NativeBoard:
    """The :class:`NativeBoard` of ``pinball_map``, built once and cached.

    ``ValueError`` for a map with more than 256 candidate edges in a grid cell (see
    :func:`board_if_supported`).
    """
    board = board_if_supported(pinball_map)
    if board is None:
        NativeBoard(pinball_map)  # raises, naming the map and the count
    return board


def board_if_supported(pinball_map: PinballMap) -> NativeBoard | None:
    """The cached :class:`NativeBoard` of ``pinball_map``, or ``None`` if the compiled step
    cannot hold the map (a grid cell with more than 256 candidate edges: dense maps of
    thousands of edges), which then has to take the tensor path, or is not built.

    Example:
        >>> from skillchain_torch.envs.pinball import load_map
        >>> board_if_supported(load_map("pinball_box")) is not None or not AVAILABLE
        True
    """
    if not AVAILABLE:
        return None
    board = _CACHE.get(pinball_map)
    if board is None:
        if _most_candidates(collision_grid(pinball_map)) > _MAX_CANDIDATES:
            board = _UNSUPPORTED
        else:
            board = NativeBoard(pinball_map)
        _CACHE[pinball_map] = board
    return None if board is _UNSUPPORTED else board
