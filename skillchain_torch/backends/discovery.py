"""Skill chaining's per-step bookkeeping in C (``_discovery.c``), the same bits.

:mod:`.compiled_discovery`'s twins of the discovery pieces call these for CPU tensors where the
extension is built (:data:`AVAILABLE`): :func:`~.events.target_indicator`,
:func:`~.overlap.exclude_overlap`, :meth:`~.executions.ExecutionTrace.record` and the
triggers and gestation samples of :meth:`~.skill_chaining.SkillChaining.after_transition`,
and :func:`~.events.event_list`.
They are booleans, copies and maxima, so they give the torch path's results exactly, and each
agent's row depends on that agent alone.

Example:
    >>> import torch
    >>> contains = torch.tensor([[True, True]])
    >>> exclusion = torch.tensor([[[False, False], [True, False]]])  # slot 1 avoids slot 0's set
    >>> trained = torch.tensor([[True, True]])
    >>> exclude_overlap(contains, exclusion, trained).tolist() if AVAILABLE else [[True, False]]
    [[True, False]]
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends.native import for_c

try:
    from skillchain_torch.backends import _discovery as _c
except ImportError:  # built without a C compiler: the torch path
    _c = None

__all__ = ["AVAILABLE", "applies", "target_indicator", "event_list", "exclude_overlap",
           "record", "record_ring", "copy_slots", "outcomes", "triggers"]

AVAILABLE = _c is not None
# Used wherever built (the same bits: no choice to make), by the compiled twins that
# skillchain_torch.backends.select.discovery_rules picks once, when an agent is built
# (same_bits_kernels builds without).


OBS_DIM = 4  # the ring and trace kernels copy Pinball's 4 numbers a state


def applies(*tensors: Tensor) -> bool:
    """Every tensor is on the CPU (the kernels' one condition; whether they run at all was
    chosen when the agent was built, by select.discovery_rules)."""
    for t in tensors:  # (a loop, not all() over a generator: this runs several times a step)
        if not t.is_cpu:
            return False
    return True


def _flags(x: Tensor) -> Tensor:
    return for_c(x, torch.bool)


def target_indicator(parent: Tensor, target_event: Tensor, status: Tensor, base_fired: Tensor,
                     contains: Tensor) -> Tensor:  # fmt: skip
    """:func:`~.events.target_indicator` from the bank's ``[P, K]`` metadata."""
    P, K = status.shape
    base_fired, contains = _flags(base_fired), _flags(contains)
    parent, target_event, status = (x.contiguous() for x in (parent, target_event, status))
    out = torch.empty(P, K, dtype=torch.bool)
    _c.target_indicator(P, K, base_fired.shape[1], parent.data_ptr(), target_event.data_ptr(),
                        status.data_ptr(), base_fired.data_ptr(), contains.data_ptr(),
                        out.data_ptr())  # fmt: skip
    return out


def event_list(parent: Tensor, target_event: Tensor, status: Tensor, num_base: int,
               max_branching: int) -> tuple[Tensor, Tensor]:  # fmt: skip
    """:func:`~.events.event_list` from the bank's ``[P, K]`` metadata."""
    P, K = status.shape
    parent, target_event, status = (x.contiguous() for x in (parent, target_event, status))
    base_on = torch.empty(P, num_base, dtype=torch.bool)
    slot_on = torch.empty(P, K, dtype=torch.bool)
    _c.event_list(P, K, num_base, parent.data_ptr(), target_event.data_ptr(), status.data_ptr(),
                  int(max_branching), base_on.data_ptr(), slot_on.data_ptr())  # fmt: skip
    return base_on, slot_on


def exclude_overlap(contains: Tensor, exclusion: Tensor, trained: Tensor) -> Tensor:
    """:func:`~.overlap.exclude_overlap`."""
    P, K = contains.shape
    contains, exclusion, trained = _flags(contains), _flags(exclusion), _flags(trained)
    out = torch.empty(P, K, dtype=torch.bool)
    _c.exclude_overlap(P, K, contains.data_ptr(), exclusion.data_ptr(), trained.data_ptr(),
                       out.data_ptr())  # fmt: skip
    return out


def record(states: Tensor, rows: Tensor, step: Tensor, obs: Tensor) -> None:
    """``states[p, min(step[p], T - 1)] = obs[p]`` for ``rows`` (float64 ``states``)."""
    P, T, _ = states.shape
    rows, step, obs = _flags(rows), for_c(step, torch.int64), for_c(obs, torch.float64)
    _c.record(P, T, rows.data_ptr(), step.data_ptr(), obs.data_ptr(), states.data_ptr(), 0)


def record_ring(states: Tensor, steps: Tensor, rows: Tensor, obs: Tensor) -> bool:
    """``states[p, steps[p] % L] = obs[p]; steps[p] += 1`` for ``rows`` in place, when
    ``states [P, L, 4]`` is contiguous CPU float64 and ``steps`` contiguous int64; ``False``
    (nothing done) otherwise."""
    if not (states.dtype == torch.float64 and steps.dtype == torch.int64
            and states.shape[-1] == OBS_DIM  # the kernel copies 4 numbers a state
            and states.is_contiguous() and steps.is_contiguous()
            and applies(states, steps, rows, obs)):  # fmt: skip
        return False
    P, L, _ = states.shape
    rows, obs = _flags(rows), for_c(obs, torch.float64)
    _c.record(P, L, rows.data_ptr(), steps.data_ptr(), obs.data_ptr(), states.data_ptr(), 1)
    return True


def copy_slots(slots: Tensor, rows: Tensor, slot: Tensor, held: Tensor, to_slots: bool) -> bool:
    """``held[p] = slots[p, max(slot[p], 0)]`` for the agents in ``rows [P]`` (or the reverse
    with ``to_slots``), in place, when ``slots [P, K, ...]`` and ``held [P, ...]`` are
    contiguous CPU float64; ``False`` (nothing done) otherwise."""
    f64 = torch.float64
    if not (slots.dtype == f64 and held.dtype == f64 and slots.is_contiguous()
            and held.is_contiguous() and applies(slots, held, rows, slot)):  # fmt: skip
        return False
    P, K = slots.shape[:2]
    rows, slot = _flags(rows), for_c(slot, torch.int64)
    _c.copy_slots(P, K, slots[0, 0].numel(), slots.data_ptr(), rows.data_ptr(), slot.data_ptr(),
                  held.data_ptr(), int(to_slots))  # fmt: skip
    return True


def outcomes(option: Tensor, reached: Tensor, duration: Tensor, ended: Tensor,
             terminated: Tensor, max_steps: int,
             out: tuple[Tensor, Tensor, Tensor] | None = None,
             ) -> tuple[Tensor, Tensor, Tensor, bool, bool]:  # fmt: skip
    """``(slot, success, failure, any_ended, any_failure)`` of the executions that ended
    (``ended`` and an option executing): :func:`~.executions.execution_outcome` masked to them,
    with ``slot = option.clamp(min=0)``. ``out``: contiguous ``(slot [P] int64, success [P]
    bool, failure [P] bool)`` to write them into (a caller's scratch), else new tensors."""
    P, K = reached.shape
    option, duration = for_c(option, torch.int64), for_c(duration, torch.int64)
    reached, ended, terminated = _flags(reached), _flags(ended), _flags(terminated)
    if out is None:
        out = (torch.empty(P, dtype=torch.int64), torch.empty(P, dtype=torch.bool),
               torch.empty(P, dtype=torch.bool))  # fmt: skip
    slot, success, failure = out
    code = _c.outcomes(P, K, option.data_ptr(), reached.data_ptr(), duration.data_ptr(),
                       ended.data_ptr(), terminated.data_ptr(), int(max_steps), slot.data_ptr(),
                       success.data_ptr(), failure.data_ptr())  # fmt: skip
    return slot, success, failure, code > 0, code > 1


def triggers(parent: Tensor, target_event: Tensor, status: Tensor, base_now: Tensor,
             base_next: Tensor, contains: Tensor, contains_next: Tensor, reached: Tensor,
             stepped: Tensor, sample: Tensor, gestation_q: Tensor, max_branching: int,
             trig_out: tuple[Tensor, Tensor] | None = None, blocked: Tensor | None = None,
             ) -> tuple[Tensor, Tensor, Tensor, Tensor, bool, Tensor | None]:  # fmt: skip
    """One step's ``(gestation_q, base_trig, slot_trig, base_now, any_listed, hits)`` of
    :meth:`~.skill_chaining.SkillChaining.after_transition` (new tensors, or ``trig_out``'s
    contiguous bool ``(base_trig [P, E], slot_trig [P, K])`` for the triggers); ``any_listed``:
    an event on its agent's list (:func:`event_list`) was triggered, so a creation may follow
    (not counting agents in ``blocked [P]``, bool, whose slots are all live: skill chaining's
    ``slots_full_logged``, agents that create nothing more);
    ``hits [P, K]``: the gestating options whose target the transition entered (``None`` when
    there is none, the usual step)."""
    P, K = status.shape
    E = base_now.shape[1]
    parent, target_event, status = (x.contiguous() for x in (parent, target_event, status))
    flags = [_flags(x) for x in (base_now, base_next, contains, contains_next, reached, stepped)]
    sample = for_c(sample, torch.float64)
    gestation_q = for_c(gestation_q, torch.float64)  # held: C reads its address
    out_q = torch.empty(P, K, dtype=torch.float64)
    if trig_out is None:
        trig_out = (torch.empty(P, E, dtype=torch.bool), torch.empty(P, K, dtype=torch.bool))
    base_trig, slot_trig = trig_out
    out_base_now = torch.empty(P, E, dtype=torch.bool)
    hits = torch.empty(P, K, dtype=torch.bool)
    if blocked is not None:  # (held here: C reads its address)
        if blocked.shape != (P,) or not blocked.is_cpu:
            raise ValueError(f"blocked must be a CPU [P={P}] mask, got {tuple(blocked.shape)} "
                             f"on {blocked.device}")  # fmt: skip
        blocked = _flags(blocked)
    any_listed, any_hit = _c.triggers(
        P, K, E, parent.data_ptr(), target_event.data_ptr(), status.data_ptr(),
        *(x.data_ptr() for x in flags), sample.data_ptr(), gestation_q.data_ptr(),
        int(max_branching), out_q.data_ptr(), base_trig.data_ptr(), slot_trig.data_ptr(),
        out_base_now.data_ptr(), hits.data_ptr(),
        0 if blocked is None else blocked.data_ptr())  # fmt: skip
    return out_q, base_trig, slot_trig, out_base_now, any_listed, hits if any_hit else None
