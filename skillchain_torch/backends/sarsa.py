"""The flat agent's per-step arithmetic in C (``_sarsa.c``), on CPU float64 tensors.

:class:`~skillchain_torch.agents.FlatSarsaAgent` uses these on the CPU when the extension is built
(:data:`AVAILABLE`); they replace the torch fast path of :mod:`.kernels`:

* :func:`linear_q`, :func:`sarsa_learn`, :func:`sarsa_observe`: Q values, the Sarsa update and
  the fused step (Q(s', .), tabulated epsilon-greedy choice, update) one agent row at a time.
  Their dot products sum in a fixed order of their own, so they agree with
  ``LinearQHead``/``SarsaUpdate`` to rounding (~1e-16 relative), not bit for bit; each row's
  numbers still depend only on that agent, so a population's agent p equals a single run
  with seed S + p bit for bit, as with the torch path.

Every function checks nothing: callers pass contiguous CPU float64 (int64 for indices,
bool for flags) tensors of matching shapes.

Example:
    >>> import torch
    >>> w = torch.ones(5, 2, 3, dtype=torch.float64)  # [D, n, F]
    >>> phi = torch.tensor([[1.0, 2.0, 3.0], [0.5, 0.5, 0.5]], dtype=torch.float64)
    >>> linear_q(w, phi).tolist()[0] if AVAILABLE else [6.0, 1.5]
    [6.0, 1.5]
"""

from __future__ import annotations

import torch
from torch import Tensor

try:
    from . import _sarsa as _c
except ImportError:  # built without a C compiler: the agent keeps its torch path
    _c = None

__all__ = ["AVAILABLE", "linear_q", "sarsa_learn", "sarsa_observe"]

AVAILABLE = _c is not None


def linear_q(w: Tensor, phi: Tensor, rows: Tensor | None = None) -> Tensor:
    """``q[d, i] = w[d, rows[i]] . phi[i]`` for action-major weights ``[D, N, F]``: ``[D, n]``."""
    D, N, F = w.shape
    n = phi.shape[0]
    phi = phi.contiguous()  # called at episode ends only: the copies cost nothing that shows
    rows = None if rows is None else rows.to(torch.int64).contiguous()
    q = torch.empty(D, n, dtype=torch.float64)
    _c.linear_q(n, D, F, w.data_ptr(), N, 0 if rows is None else rows.data_ptr(),
                phi.data_ptr(), q.data_ptr())
    return q


def _step_args(step_size: Tensor) -> tuple[int, int]:
    return step_size.data_ptr(), (1 if step_size.ndim else 0)


def sarsa_learn(w: Tensor, phi: Tensor, action: Tensor, reward: Tensor, q_next: Tensor,
                terminated: Tensor | None, step_size: Tensor, gamma: float | None) -> None:
    """In place: ``w[a_i, i] += step * (delta * phi_i)`` with
    ``delta = (r + gamma q') - w[a_i, i] . phi_i`` (no bootstrap where ``terminated``;
    ``gamma=None`` means 1 without a multiplication)."""
    D, n, F = w.shape
    _c.sarsa_learn(n, D, F, w.data_ptr(), phi.data_ptr(), action.data_ptr(), reward.data_ptr(),
                   q_next.data_ptr(), 0 if terminated is None else terminated.data_ptr(),
                   *_step_args(step_size), 1.0 if gamma is None else gamma, gamma is not None)


def sarsa_observe(w: Tensor, phi: Tensor, phi_next: Tensor, action: Tensor, reward: Tensor,
                  table: Tensor, slot: int, step_size: Tensor, gamma: float | None) -> Tensor:
    """One non-terminal step of every row: ``a'`` from ``table[i, slot, code(Q(s', .))]``
    (Q with the weights before the update), then :func:`sarsa_learn`. Returns ``a'`` ``[n]``."""
    D, n, F = w.shape
    next_action = torch.empty(n, dtype=torch.int64)
    table_row = table.shape[1] * table.shape[2]
    _c.sarsa_observe(n, D, F, w.data_ptr(), phi.data_ptr(), phi_next.data_ptr(),
                     action.data_ptr(), reward.data_ptr(), table.data_ptr(), table_row,
                     slot * table.shape[2], *_step_args(step_size),
                     1.0 if gamma is None else gamma, gamma is not None, next_action.data_ptr())
    return next_action
