"""The flat agent's per-step arithmetic in C (``_sarsa.c``), on CPU float64 tensors.

:class:`~skillchain_torch.agents.FlatSarsaAgent` runs these on the CPU when the extension is
built (:data:`AVAILABLE`; chosen by :func:`~skillchain_torch.backends.select.compiled`) in place
of its torch path (``LinearQHead``, ``epsilon_greedy``, ``SarsaUpdate``):

* :func:`linear_q`, :func:`sarsa_learn`, :func:`sarsa_observe`: Q values, the Sarsa update and
  the fused step (Q(s', .), the epsilon-greedy choice, the update) one agent row at a time.
  Their dot products sum in a fixed order of their own, so they agree with the torch path to
  rounding (~1e-16 relative), not bit for bit; the epsilon-greedy rule is the same decision for
  decision. Each row's numbers still depend only on that agent, so a population's agent p
  equals a single run with seed S + p bit for bit, as with the torch path.

Weights are agent-major ``[n, D, F]`` (a ``LinearQHead``'s layout). Every function checks
nothing: callers pass contiguous CPU float64 (int64 for indices, bool for flags) tensors of
matching shapes.

Example:
    >>> import torch
    >>> w = torch.ones(2, 5, 3, dtype=torch.float64)  # [n, D, F]
    >>> phi = torch.tensor([[1.0, 2.0, 3.0], [0.5, 0.5, 0.5]], dtype=torch.float64)
    >>> linear_q(w, phi)[:, 0].tolist() if AVAILABLE else [6.0, 1.5]
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
    """``q[i, d] = w[rows[i], d] . phi[i]`` (``rows`` default: all, in order): ``[n, D]``."""
    D, F = w.shape[1:]
    n = phi.shape[0]
    phi = phi.contiguous()  # rows are asked for at episode ends only: the copies cost nothing
    rows = None if rows is None else rows.to(torch.int64).contiguous()
    q = torch.empty(n, D, dtype=torch.float64)
    _c.linear_q(n, D, F, w.data_ptr(), 0 if rows is None else rows.data_ptr(), phi.data_ptr(),
                q.data_ptr())
    return q


def _step_args(step_size: Tensor) -> tuple[int, int]:
    return step_size.data_ptr(), (1 if step_size.ndim else 0)


def sarsa_learn(w: Tensor, phi: Tensor, action: Tensor, reward: Tensor, q_next: Tensor,
                terminated: Tensor | None, step_size: Tensor, gamma: float | None) -> None:
    """In place: ``w[i, a_i] += step * (delta * phi_i)`` with
    ``delta = (r + gamma q') - w[i, a_i] . phi_i`` (no bootstrap where ``terminated``;
    ``gamma=None`` means 1 without a multiplication)."""
    n, D, F = w.shape
    _c.sarsa_learn(n, D, F, w.data_ptr(), phi.data_ptr(), action.data_ptr(), reward.data_ptr(),
                   q_next.data_ptr(), 0 if terminated is None else terminated.data_ptr(),
                   *_step_args(step_size), 1.0 if gamma is None else gamma, gamma is not None)


def sarsa_observe(w: Tensor, phi: Tensor, phi_next: Tensor, action: Tensor, reward: Tensor,
                  uniforms: Tensor, slot: int, epsilon: float, step_size: Tensor,
                  gamma: float | None) -> Tensor:
    """One non-terminal step of every row: ``a'`` by the epsilon-greedy rule over
    ``Q(s', .)`` (the weights before the update) with the uniforms ``uniforms[i, slot]``
    (``uniforms [n, B, 2]``), then :func:`sarsa_learn`. Returns ``a'`` ``[n]``."""
    n, D, F = w.shape
    next_action = torch.empty(n, dtype=torch.int64)
    per_row, per_slot = uniforms.shape[1] * uniforms.shape[2], uniforms.shape[2]
    _c.sarsa_observe(n, D, F, w.data_ptr(), phi.data_ptr(), phi_next.data_ptr(),
                     action.data_ptr(), reward.data_ptr(), uniforms.data_ptr(), per_row,
                     slot * per_slot, float(epsilon), *_step_args(step_size),
                     1.0 if gamma is None else gamma, gamma is not None, next_action.data_ptr())
    return next_action
