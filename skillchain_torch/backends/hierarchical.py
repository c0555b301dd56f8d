"""The hierarchical agent's per-step arithmetic in C (``_hierarchical.c``).

:class:`~skillchain_torch.agents.HierarchicalAgent` with ``native=True`` (its default on CPU
float64 with Fourier option heads, when built: :data:`AVAILABLE`) runs every transition
through :func:`transition` and starts episodes with :func:`choose` and :func:`act`. Each
mirrors library pieces, with the same rules and the same uniforms:

====================  =====================================================================
:func:`choose`        ``LinearQHead.forward_mask`` + :func:`~skillchain_torch.policies.
                      epsilon_greedy` (the top-level decision)
:func:`act`           the executing options' values (``slot_values_rows``) + epsilon-greedy
:func:`transition`    the rest of ``HierarchicalAgent.transition`` after the memberships,
                      targets and uniforms of ``s'``, one C pass per agent: intra-option
                      Q-learning (:class:`~skillchain_torch.objectives.IntraOptionQLearning`
                      on a :class:`~skillchain_torch.options.FourierOptionQHead`, float
                      ``C``), the top-level choice (the same C function as :func:`choose`),
                      SMDP Sarsa (:class:`~skillchain_torch.objectives.SarsaUpdate`, and
                      with ``intra_option_primitives`` the option's primitive), the
                      next action (as :func:`act`)
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

from skillchain_torch.backends import initiation
from skillchain_torch.backends.select import builtin_type_problems, compiled
from skillchain_torch.options import FourierOptionQHead, OptionStatus

try:
    from skillchain_torch.backends import _hierarchical as _c
except ImportError:  # built without a C compiler: the agent keeps its torch path
    _c = None

__all__ = ["AVAILABLE", "choose", "act", "resolve", "transition"]

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


def resolve(bank, native: bool | None, completion_reward, num_primitives: int,
            pieces: dict | None = None) -> bool:
    """The agent's ``native`` argument made a choice for ``bank``'s options: ``None`` is
    ``True`` where the compiled path applies; ``True`` where it does not raises
    ``ValueError`` naming what is missing (:func:`~skillchain_torch.backends.compiled`).

    The step replaces the option heads' and the top level's maths, so it runs only where the
    option head is exactly :class:`FourierOptionQHead` and every piece in ``pieces``
    (``{name: (piece, built-in class)}``, the agent's top-level head and basis) is exactly its
    built-in class. The initiation sets are not replaced (their memberships reach the step
    from torch); the classifier chooses its own kernels (``InitiationClassifier.set_native``).
    """
    head = bank.q_head
    exact = type(head) is FourierOptionQHead
    needs = {
        "the compiled kernels (built)": AVAILABLE and initiation.AVAILABLE,
        "the CPU": bank.status.device.type == "cpu",
        f"{num_primitives} option actions": head.num_actions == num_primitives,
        "a 4-d observation": bank.obs_dim == 4,
        "float64 option heads": not exact or head.weight.dtype == torch.float64,
        "a float completion_reward": not isinstance(completion_reward, Tensor),
    }
    pieces = {"the option head": (head, FourierOptionQHead), **(pieces or {})}
    return compiled(native, needs, builtin_type_problems(pieces))


# The agent's per-step state, in the order the C step reads and writes it.
STATE = ("obs", "option_code", "contains", "decision_phi", "decision", "option", "action",
         "decision_return", "duration")


def _own(agent, name: str) -> Tensor:
    """The agent's float64 state array ``name``, contiguous (made so once if it is not)."""
    x = getattr(agent, name)
    if not x.is_contiguous() or x.dtype != torch.float64:
        x = x.to(torch.float64).contiguous()
        setattr(agent, name, x)
    return x


def transition(agent, next_obs: Tensor, reward: Tensor, terminated: Tensor, truncated: Tensor,
               stepped: Tensor, contains_next: Tensor, reached: Tensor,
               uniforms: Tensor) -> dict[str, Tensor]:  # fmt: skip
    """The rest of ``agent.transition`` after the memberships, targets and uniforms
    (``[P, 4]``) of ``s'``: its features, then every row in one C pass (weights updated in
    place, the state at ``s'`` in fresh tensors but for ``option_code`` and ``decision_phi``,
    updated in place). Returns the transition's monitoring dict.

    ``next_obs`` holds ``s`` on rows not stepped; ``terminated``/``truncated`` are masked to
    ``stepped``; ``reward`` is float64.
    """
    bank, head = agent.bank, agent.q_head
    P, D, F = head.weight.shape
    _, K, A, Fo = bank.q_head.weight.shape
    phi_next = agent.features(next_obs)
    # The option heads' code is picked from phi_next inside (shared_fourier_columns).
    columns = agent._code_columns
    next_code = bank.q_head.encode(next_obs) if columns is None else None
    reward, reached = reward.contiguous(), reached.contiguous()
    f64 = torch.float64
    # The two large state arrays are updated in place (see the C step); they are the agent's
    # own (every other writer replaces them), so nothing else sees the change. The [P]
    # outputs are rows of three fresh blocks (one allocation per dtype, not one per output).
    decision, option, action, duration, d_next, info_duration = torch.empty(
        6, P, dtype=torch.int64).unbind(0)  # fmt: skip
    decision_return, smdp_delta, info_return, value = torch.empty(4, P, dtype=f64).unbind(0)
    decision_ended, started = torch.empty(2, P, dtype=torch.bool).unbind(0)
    q, option_delta = torch.empty(P, D, dtype=f64), torch.empty(P, K, dtype=f64)
    new_state = (torch.empty(P, 4, dtype=f64), _own(agent, "option_code"),
                 torch.empty(P, K, dtype=torch.bool), _own(agent, "decision_phi"), decision,
                 option, action, decision_return, duration)  # STATE's order
    value = value if agent.WANTS_VALUE else None
    state = agent.__dict__  # STATE's arrays are plain attributes (HierarchicalAgent._PLAIN)
    step_size, gamma = agent.update.step_size, agent.gamma
    _c.step(P, K, A, F, Fo, head.weight.data_ptr(), bank.q_head.weight.data_ptr(),
            *[state[name].data_ptr() for name in STATE],
            next_obs.data_ptr(), reward.data_ptr(), terminated.data_ptr(), truncated.data_ptr(),
            stepped.data_ptr(), contains_next.data_ptr(), reached.data_ptr(),
            phi_next.data_ptr(), 0 if next_code is None else next_code.data_ptr(),
            0 if columns is None else columns.data_ptr(), bank.status.data_ptr(),
            uniforms.data_ptr(), agent.epsilon, agent.option_epsilon, gamma, gamma != 1.0,
            agent.max_option_steps, bank.q_head.alpha,
            float(agent.option_update.completion_reward), step_size.data_ptr(),
            1 if step_size.ndim else 0, int(OptionStatus.LEARNING),
            *[x.data_ptr() for x in new_state], q.data_ptr(), d_next.data_ptr(),
            decision_ended.data_ptr(), option_delta.data_ptr(), smdp_delta.data_ptr(),
            info_duration.data_ptr(), info_return.data_ptr(), started.data_ptr(),
            0 if value is None else value.data_ptr(),
            int(agent.failure_bootstrap == "primitives"),
            _own(agent, "state_phi").data_ptr() if agent.intra_option_primitives else 0,
            int(agent.interruption))  # fmt: skip
    info = {"decision_ended": decision_ended, "duration": info_duration,
            "decision_return": info_return, "option_delta": option_delta,
            "smdp_delta": smdp_delta, "decision": state["decision"], "option": state["option"],
            "reached": reached}  # fmt: skip
    state.update(zip(STATE, new_state))
    state.update(last_phi=phi_next, last_q=q, last_value=value)
    agent._options_starting(started)
    return info
