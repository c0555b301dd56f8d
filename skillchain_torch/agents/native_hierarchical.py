"""The hierarchical agent's per-step arithmetic in C (``_hierarchical_native.c``).

:class:`~skillchain_torch.agents.HierarchicalAgent` with ``native=True`` (its default on CPU
float64 with Fourier option heads, when built: :data:`AVAILABLE`) runs every transition
through :func:`step` and starts episodes with :func:`choose` and :func:`act`. Each function
mirrors library pieces, with the same rules and the same uniforms:

====================  =====================================================================
:func:`choose`        ``LinearQHead.forward_mask`` + :func:`~skillchain_torch.policies.
                      epsilon_greedy` (the top-level decision)
:func:`act`           the executing options' values (``slot_values_rows``) + epsilon-greedy
:func:`smdp`          :class:`~skillchain_torch.objectives.SarsaUpdate` with ``next_value``
:func:`intra_option`  :class:`~skillchain_torch.objectives.IntraOptionQLearning` on a
                      :class:`~skillchain_torch.options.FourierOptionQHead` (float ``C``)
:func:`step`          the whole of ``HierarchicalAgent.transition`` after the memberships,
                      targets, features and uniforms of ``s'``: the four pieces above (the
                      same C row functions) in its order, one pass per agent
====================  =====================================================================

The sums run in a fixed order of their own, so values and weights agree with the torch path
to rounding (tested at 1e-10), not bit for bit. Each agent's numbers depend on that agent
alone, so agent p of a population still equals agent p alone, bit for bit.

Nothing is checked here: callers pass contiguous CPU float64 tensors (int64 indices, bool
flags) of matching shapes.

Example:
    >>> import torch
    >>> w = torch.zeros(1, 2, 3, dtype=torch.float64)
    >>> w[0, 1] = 1.0                                     # decision 1 is worth phi's sum
    >>> phi = torch.ones(1, 3, dtype=torch.float64)
    >>> u = torch.tensor([[0.5, 0.5]], dtype=torch.float64)
    >>> ok = torch.ones(1, 2, dtype=torch.bool)
    >>> if AVAILABLE:
    ...     q, decision = choose(w, phi, ok, ok[:, 0], 0, u, epsilon=0.0)
    ...     print(q.tolist(), decision.tolist())
    ... else:
    ...     print([[0.0, 3.0]], [1])
    [[0.0, 3.0]] [1]
"""

from __future__ import annotations

import torch
from torch import Tensor

try:
    from skillchain_torch.agents import _hierarchical_native as _c
except ImportError:  # built without a C compiler: the agent keeps its torch path
    _c = None

__all__ = ["AVAILABLE", "choose", "act", "smdp", "intra_option", "step"]

AVAILABLE = _c is not None


def choose(w: Tensor, phi: Tensor, available: Tensor, rows: Tensor, dense: int,
           uniforms: Tensor, epsilon: float) -> tuple[Tensor, Tensor]:  # fmt: skip
    """``(q [P, D], decision [P])``: values of the available decisions of ``rows`` (0
    elsewhere) and every row's epsilon-greedy decision (``uniforms [P, >= 2]``, a row view
    is fine)."""
    P, D, F = w.shape
    q = torch.empty(P, D, dtype=torch.float64)
    decision = torch.empty(P, dtype=torch.int64)
    _c.choose(P, D, F, w.data_ptr(), phi.data_ptr(), available.data_ptr(), rows.data_ptr(),
              dense, uniforms.data_ptr(), uniforms.stride(0), float(epsilon), q.data_ptr(),
              decision.data_ptr())  # fmt: skip
    return q, decision


def act(w: Tensor, code: Tensor, rows: Tensor, decision: Tensor, option: Tensor,
        uniforms: Tensor, epsilon: float, action: Tensor) -> Tensor:  # fmt: skip
    """``action`` with ``rows`` rewritten: the primitive decision, or the executing option's
    epsilon-greedy action (option weights ``w [P, K, A, F]``). Writes into ``action``."""
    P, K, A, F = w.shape
    _c.act(P, K, A, F, w.data_ptr(), code.data_ptr(), rows.data_ptr(), decision.data_ptr(),
           option.data_ptr(), uniforms.data_ptr(), uniforms.stride(0), float(epsilon),
           action.data_ptr())  # fmt: skip
    return action


def smdp(w: Tensor, phi: Tensor, decision: Tensor, ret: Tensor, duration: Tensor,
         q_next: Tensor, terminal: Tensor, active: Tensor, step_size: Tensor,
         gamma: float) -> Tensor:  # fmt: skip
    """SMDP Sarsa on the ``active`` rows, in place; the TD errors ``[P]`` (0 elsewhere).
    ``gamma == 1`` adds ``Q(s', d')`` without a power, as the torch path."""
    P, D, F = w.shape
    delta = torch.empty(P, dtype=torch.float64)
    _c.smdp(P, D, F, w.data_ptr(), phi.data_ptr(), decision.data_ptr(), ret.data_ptr(),
            duration.data_ptr(), q_next.data_ptr(), terminal.data_ptr(), active.data_ptr(),
            step_size.data_ptr(), 1 if step_size.ndim else 0, float(gamma), gamma != 1.0,
            delta.data_ptr())  # fmt: skip
    return delta


def intra_option(w: Tensor, code: Tensor, next_code: Tensor, action: Tensor, reward: Tensor,
                 terminated: Tensor, mask: Tensor, reached: Tensor, alpha: float, gamma: float,
                 completion: float) -> Tensor:  # fmt: skip
    """Intra-option Q-learning of the ``mask [P, K]`` slots, in place; the TD errors
    ``[P, K]`` (0 elsewhere)."""
    P, K, A, F = w.shape
    delta = torch.empty(P, K, dtype=torch.float64)
    _c.intra_option(P, K, A, F, w.data_ptr(), code.data_ptr(), next_code.data_ptr(),
                    action.data_ptr(), reward.data_ptr(), terminated.data_ptr(),
                    mask.data_ptr(), reached.data_ptr(), float(alpha), float(gamma),
                    float(completion), delta.data_ptr())  # fmt: skip
    return delta


# The agent's per-step state, in the order step() reads and writes it.
STATE = ("obs", "option_code", "contains", "decision_phi", "decision", "option", "action",
          "decision_return", "duration")


def step(agent, next_obs: Tensor, reward: Tensor, terminated: Tensor, truncated: Tensor,
         stepped: Tensor, contains_next: Tensor, reached: Tensor, phi_next: Tensor,
         next_code: Tensor | None, columns: Tensor | None, uniforms: Tensor,
         executable_from: int, value: bool = False) -> dict[str, Tensor]:  # fmt: skip
    """``agent``'s transition for every row (its weights updated in place).

    The option heads' code of ``s'`` is ``next_code``, or (``None``) the ``columns`` of
    ``phi_next``. Returns the state at ``s'`` under the agent's attribute names (fresh
    tensors) plus ``q [P, D]`` (the values the decision at ``s'`` was taken with), ``d_next``,
    ``decision_ended``, ``option_delta [P, K]``, ``smdp_delta``, ``info_duration``,
    ``info_return`` (the decision's k and R before a new decision resets them), ``started``
    (rows that start an option) and with ``value`` Q(s', d) of the decision in force after the
    step (stepped rows). ``next_obs`` must already hold ``s`` on rows not stepped.
    """
    bank, head = agent.bank, agent.q_head
    P, D, F = head.weight.shape
    _, K, A, Fo = bank.q_head.weight.shape
    f64, i64 = dict(dtype=torch.float64), dict(dtype=torch.int64)
    out = {
        "obs": torch.empty(P, 4, **f64), "option_code": torch.empty(P, Fo, **f64),
        "contains": torch.empty(P, K, dtype=torch.bool), "decision_phi": torch.empty(P, F, **f64),
        "decision": torch.empty(P, **i64), "option": torch.empty(P, **i64),
        "action": torch.empty(P, **i64), "decision_return": torch.empty(P, **f64),
        "duration": torch.empty(P, **i64), "q": torch.empty(P, D, **f64),
        "d_next": torch.empty(P, **i64), "decision_ended": torch.empty(P, dtype=torch.bool),
        "option_delta": torch.empty(P, K, **f64), "smdp_delta": torch.empty(P, **f64),
        "info_duration": torch.empty(P, **i64), "info_return": torch.empty(P, **f64),
        "started": torch.empty(P, dtype=torch.bool),
        "value": torch.empty(P, **f64) if value else None,
    }  # fmt: skip
    step_size = agent.update.step_size
    gamma = agent.gamma
    _c.step(P, K, A, F, Fo, head.weight.data_ptr(), bank.q_head.weight.data_ptr(),
            *(getattr(agent, name).data_ptr() for name in STATE[:4]),
            *(getattr(agent, name).data_ptr() for name in STATE[4:]),
            next_obs.data_ptr(), reward.data_ptr(), terminated.data_ptr(), truncated.data_ptr(),
            stepped.data_ptr(), contains_next.data_ptr(), reached.data_ptr(),
            phi_next.data_ptr(), 0 if next_code is None else next_code.data_ptr(),
            0 if columns is None else columns.data_ptr(), bank.status.data_ptr(),
            uniforms.data_ptr(), agent.epsilon, agent.option_epsilon, gamma, gamma != 1.0,
            agent.max_option_steps, bank.q_head.alpha,
            float(agent.option_update.completion_reward), step_size.data_ptr(),
            1 if step_size.ndim else 0, int(executable_from),
            *(out[name].data_ptr() for name in STATE),
            *(out[name].data_ptr() for name in ("q", "d_next", "decision_ended", "option_delta",
                                                "smdp_delta", "info_duration", "info_return",
                                                "started")),
            0 if out["value"] is None else out["value"].data_ptr())  # fmt: skip
    return out
