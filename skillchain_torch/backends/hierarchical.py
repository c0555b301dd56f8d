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

:func:`transition` takes the agent's declared state (:class:`~skillchain_torch.agents.
step_state.StepState`) and what torch computed at ``s'`` (:class:`AtNext`), the weights it
learns (:class:`Learned`) and the agent's settings (:class:`StepRules`), and returns the state
at ``s'`` with :class:`StepOutputs`; it never reads the agent itself.

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

from dataclasses import replace
from typing import TYPE_CHECKING, NamedTuple

import torch
from torch import Tensor

from skillchain_torch.backends import initiation
from skillchain_torch.backends.native import for_c
from skillchain_torch.backends.select import builtin_type_problems, compiled
from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import FourierOptionQHead, OptionStatus

if TYPE_CHECKING:  # (the agent's module imports this one)
    from skillchain_torch.agents.step_state import StepState

try:
    from skillchain_torch.backends import _hierarchical as _c
except ImportError:  # built without a C compiler: the agent keeps its torch path
    _c = None

__all__ = ["AVAILABLE", "AtNext", "Learned", "StepOutputs", "StepRules", "act", "choose",
           "resolve", "transition"]

AVAILABLE = _c is not None
OBS_DIM = 4  # the step copies Pinball's 4 numbers a state
# _hierarchical.c's stack rows (decisions, and option actions, per agent), read from the kernel.
MAX_CHOICES = _c.MAX_CHOICES if _c is not None else None


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


def resolve(native: bool | None, *, option_head, top_head, top_features, device: torch.device,
            obs_dim: int, num_primitives: int, completion_reward) -> bool:  # fmt: skip
    """The agent's ``native`` argument made a choice: ``None`` is ``True`` where the compiled
    step applies; ``True`` where it does not raises ``ValueError`` naming what is missing
    (:func:`~skillchain_torch.backends.compiled`).

    The step replaces the maths of the option heads, the top-level head and its features, so
    it runs only where they are exactly :class:`FourierOptionQHead`, :class:`LinearQHead` and
    :class:`FourierBasis`, on ``device`` the CPU. The initiation sets are not replaced (their
    memberships reach the step from torch); the classifier takes its own kernel from
    :func:`~.select.initiation_kernel` (``InitiationClassifier.set_native``).
    """
    exact = type(option_head) is FourierOptionQHead
    needs = {
        "the compiled kernels (built)": AVAILABLE and initiation.AVAILABLE,
        "the CPU": device.type == "cpu",
        f"{num_primitives} option actions": option_head.num_actions == num_primitives,
        "a 4-d observation": obs_dim == OBS_DIM,
        "float64 option heads": not exact or option_head.weight.dtype == torch.float64,
        "a float completion_reward": not isinstance(completion_reward, Tensor),
        f"at most {MAX_CHOICES} decisions (primitives + option slots)":
            not AVAILABLE or type(top_head) is not LinearQHead
            or top_head.num_decisions <= MAX_CHOICES,
    }
    return compiled(native, needs, builtin_type_problems({
        "the option head": (option_head, FourierOptionQHead),
        "the top-level head": (top_head, LinearQHead),
        "the top-level features": (top_features, FourierBasis)}))


class StepRules(NamedTuple):
    """The agent's settings the step follows (``HierarchicalAgent``'s arguments)."""

    epsilon: float
    option_epsilon: float
    gamma: float
    max_option_steps: int
    option_alpha: float  #: the option heads' step size (``FourierOptionQHead.alpha``)
    completion_reward: float
    failure_bootstrap_primitives: bool  #: ``failure_bootstrap == "primitives"``
    intra_option_primitives: bool
    #: those updates bootstrap on ``max_a Q(s', a)`` over the primitives only
    intra_option_primitive_target: bool
    interruption: bool
    #: an execution of an option of at least this status ends at an ``s'`` outside its own
    #: set (``None``: never; ``HierarchicalAgent``'s ``end_outside_set``)
    leave_from: OptionStatus | None = None


class Learned(NamedTuple):
    """The weights the step updates in place, and the slots' status (which options learn)."""

    top: Tensor  #: ``[P, D, F]``: the top-level ``LinearQHead.weight``
    options: Tensor  #: ``[P, K, A, Fo]``: the ``FourierOptionQHead.weight``
    step_size: Tensor  #: ``[]`` or ``[F]``: ``SarsaUpdate.step_size``
    status: Tensor  #: ``[P, K]`` int64: each slot's :class:`OptionStatus`


class AtNext(NamedTuple):
    """What torch computed at ``s'`` for the step (``[P]`` flags masked to ``stepped``)."""

    obs: Tensor  #: ``[P, 4]``: ``s'`` (``s`` on rows not stepped)
    reward: Tensor  #: ``[P]`` float64
    terminated: Tensor  #: ``[P]`` bool
    truncated: Tensor  #: ``[P]`` bool
    stepped: Tensor  #: ``[P]`` bool: the rows that took a step
    contains: Tensor  #: ``[P, K]`` bool: the memberships at ``s'``
    reached: Tensor  #: ``[P, K]`` bool: each option's target event at ``s'``
    uniforms: Tensor  #: ``[P, 4]``: the step's draws (top level, then the option's)
    phi: Tensor  #: ``[P, F]``: the top level's features of ``s'``
    code: Tensor | None  #: ``[P, Fo]``: the option heads' code of ``s'``, or ``None``:
    code_columns: Tensor | None  #: ... picked from ``phi`` at these ``[Fo]`` int64 columns
    own: Tensor | None = None  #: ``[P, K]`` bool: each option's own set at ``s'``


class StepOutputs(NamedTuple):
    """What the step reports beside the state at ``s'`` (``[P]`` unless noted)."""

    q: Tensor  #: ``[P, D]``: the values the decision at ``s'`` was taken with (0 elsewhere)
    decision_ended: Tensor  #: bool: the SMDP update happened
    duration: Tensor  #: int64: the decision's duration k, this step included
    decision_return: Tensor  #: its return R, this step included
    option_delta: Tensor  #: ``[P, K]``: intra-option TD errors (0 where no update)
    smdp_delta: Tensor  #: the SMDP TD errors (0 where no update)
    started: Tensor  #: bool: the rows that took an option as their new decision
    value: Tensor | None  #: ``Q(s', d)`` of the decision in force after the step


def transition(state: StepState, learned: Learned, at_next: AtNext, rules: StepRules,
               want_value: bool = False) -> tuple[StepState, StepOutputs]:  # fmt: skip
    """``HierarchicalAgent.transition`` after the memberships, targets, features and uniforms
    of ``s'``, every row in one C pass: ``(the state at s', the step's outputs)``.

    ``learned``'s weights are updated in place. The new state's ``option_code``,
    ``decision_phi`` and ``state_phi`` are ``state``'s own arrays updated in place (made
    contiguous float64 first if they are not); its other fields are fresh tensors, so
    ``state``'s still hold ``s``. ``want_value``: compute :attr:`StepOutputs.value`.
    """
    P, D, F = learned.top.shape
    _, K, A, Fo = learned.options.shape
    f64 = torch.float64
    reward, reached = at_next.reward.contiguous(), at_next.reached.contiguous()
    own = state.own_contains.contiguous()  # the kernel applies option_update_mask's rule
    own_next = None  # the own sets at s', read only where executions end outside them
    if rules.leave_from is not None:
        if at_next.own is None:
            raise ValueError("end_outside_set needs AtNext.own, the own sets at s'")
        own_next = at_next.own.contiguous()
    # The [P] outputs are rows of three fresh blocks (one allocation per dtype, not one per
    # output: this runs every step).
    decision, option, action, duration, d_next, info_duration = torch.empty(
        6, P, dtype=torch.int64).unbind(0)  # fmt: skip
    decision_return, smdp_delta, info_return, value = torch.empty(4, P, dtype=f64).unbind(0)
    decision_ended, started = torch.empty(2, P, dtype=torch.bool).unbind(0)
    q, option_delta = torch.empty(P, D, dtype=f64), torch.empty(P, K, dtype=f64)
    # The two large arrays are updated in place (each row is read before it is written).
    code, decision_phi = for_c(state.option_code, f64), for_c(state.decision_phi, f64)
    state_phi = for_c(state.state_phi, f64) if rules.intra_option_primitives else None
    new = replace(state, obs=torch.empty(P, 4, dtype=f64), option_code=code,
                  contains=torch.empty(P, K, dtype=torch.bool), decision_phi=decision_phi,
                  decision=decision, option=option, action=action,
                  decision_return=decision_return, duration=duration,
                  state_phi=state.state_phi if state_phi is None else state_phi)  # fmt: skip
    value = value if want_value else None
    columns, next_code = at_next.code_columns, at_next.code
    _c.step(P, K, A, F, Fo, learned.top.data_ptr(), learned.options.data_ptr(),
            *[x.data_ptr() for x in (state.obs, code, state.contains, decision_phi,
                                     state.decision, state.option, state.action,
                                     state.decision_return, state.duration)],
            at_next.obs.data_ptr(), reward.data_ptr(), at_next.terminated.data_ptr(),
            at_next.truncated.data_ptr(), at_next.stepped.data_ptr(),
            at_next.contains.data_ptr(), reached.data_ptr(), at_next.phi.data_ptr(),
            0 if next_code is None else next_code.data_ptr(),
            0 if columns is None else columns.data_ptr(), learned.status.data_ptr(),
            at_next.uniforms.data_ptr(), rules.epsilon, rules.option_epsilon, rules.gamma,
            rules.gamma != 1.0, rules.max_option_steps, rules.option_alpha,
            float(rules.completion_reward), learned.step_size.data_ptr(),
            1 if learned.step_size.ndim else 0, int(OptionStatus.LEARNING),
            *[x.data_ptr() for x in (new.obs, new.option_code, new.contains, new.decision_phi,
                                     new.decision, new.option, new.action,
                                     new.decision_return, new.duration)],
            q.data_ptr(), d_next.data_ptr(), decision_ended.data_ptr(), option_delta.data_ptr(),
            smdp_delta.data_ptr(), info_duration.data_ptr(), info_return.data_ptr(),
            started.data_ptr(), 0 if value is None else value.data_ptr(),
            int(rules.failure_bootstrap_primitives),
            0 if state_phi is None else state_phi.data_ptr(), int(rules.interruption),
            own.data_ptr(), int(rules.intra_option_primitive_target),
            0 if own_next is None else own_next.data_ptr(),
            int(rules.leave_from or 0))  # fmt: skip
    return new, StepOutputs(q, decision_ended, info_duration, info_return, option_delta,
                            smdp_delta, started, value)
