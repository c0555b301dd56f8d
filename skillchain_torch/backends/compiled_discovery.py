"""Skill chaining's rules with their per-step bookkeeping compiled: the same bits.

:class:`CompiledSkillChaining` is :class:`~skillchain_torch.discovery.SkillChaining` with the
bookkeeping it does every step replaced by :mod:`.discovery`'s kernels: the triggers and
gestation samples of a transition, the outcomes of ended executions, the target events' and
no-overlap rule's booleans, the execution trace and the ring of recent states, and (for the
built-in classifier in its compiled mode) the examples stored straight from the trace. They
are booleans, copies and maxima, so every result is the torch path's, bit for bit; the rules
themselves (creation, gestation, convergence, chaining) are the torch class's, untouched.

:func:`~.select.discovery_rules` picks this class once, when the agent is built, for an agent
whose step is compiled (CPU, float64, the built-in pieces) where the kernels are built; a
reader of ``discovery/`` sees only the torch path.

Example:
    >>> import torch
    >>> from skillchain_torch.options import OptionBank
    >>> bank = OptionBank.build(population=1, slots=2, order=1, capacity=8)
    >>> rules = CompiledSkillChaining(bank)
    >>> isinstance(rules.trace, CompiledExecutionTrace), rules.gestation
    (True, 10)
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends import discovery as kernels
from skillchain_torch.backends import initiation as initiation_kernels
from skillchain_torch.discovery.skill_chaining import (
    ExecutionTrace,
    RecentStates,
    SkillChaining,
    event_list,
    exclude_overlap,
)
from skillchain_torch.options.bank import target_indicator

__all__ = ["CompiledSkillChaining", "CompiledExecutionTrace", "CompiledRecentStates"]

OBS_DIM = kernels.OBS_DIM  # the trace and ring kernels copy Pinball's 4 numbers a state


def compiled_target_indicator(bank, base_fired: Tensor, contains: Tensor) -> Tensor:
    """:func:`~skillchain_torch.options.bank.target_indicator`, compiled."""
    if not kernels.applies(contains, bank.status):
        return target_indicator(bank, base_fired, contains)
    return kernels.target_indicator(bank.parent, bank.target_event, bank.status, base_fired,
                                    contains)  # fmt: skip


def compiled_event_list(bank, num_base: int, max_branching: int) -> tuple[Tensor, Tensor]:
    """:func:`~skillchain_torch.discovery.skill_chaining.event_list`, compiled."""
    if not kernels.applies(bank.status):
        return event_list(bank, num_base, max_branching)
    return kernels.event_list(bank.parent, bank.target_event, bank.status, num_base,
                              max_branching)  # fmt: skip


def compiled_exclude_overlap(contains: Tensor, exclusion: Tensor, trained: Tensor) -> Tensor:
    """:func:`~skillchain_torch.discovery.skill_chaining.exclude_overlap`, compiled."""
    if not kernels.applies(contains, exclusion):
        return exclude_overlap(contains, exclusion, trained)
    return kernels.exclude_overlap(contains, exclusion, trained)


class CompiledExecutionTrace(ExecutionTrace):
    """:class:`~skillchain_torch.discovery.skill_chaining.ExecutionTrace` with its copies
    compiled (each falls back to the torch copy where its kernel does not apply)."""

    def start(self, rows: Tensor, slot: Tensor) -> None:
        tensors = self.q_head.slot_tensors()
        if all(kernels.copy_slots(value, rows, slot, self.snapshot[name], False)
               for name, value in tensors.items()):  # fmt: skip
            return  # one compiled copy per tensor
        super().start(rows, slot)

    def record(self, rows: Tensor, step: Tensor, obs: Tensor) -> None:
        if (self.states.dtype == torch.float64 and self.states.shape[-1] == OBS_DIM
                and kernels.applies(self.states, rows)):  # fmt: skip
            kernels.record(self.states, rows, step, obs)
            return
        super().record(rows, step, obs)

    def store_examples(self, classifier, slot: Tensor, duration: Tensor, success: Tensor,
                       failure: Tensor) -> Tensor:  # fmt: skip
        # A compiled classifier stores them straight from the trace (the same examples in the
        # same order, so the same stores).
        if (getattr(classifier, "native", False) and self.states.dtype == torch.float64
                and self.states.shape[-1] == OBS_DIM):  # fmt: skip
            touched = torch.zeros(classifier.population, classifier.slots, dtype=torch.bool)
            stores = initiation_kernels.stores_of(classifier)
            initiation_kernels.store_executions(stores, self.states, slot, duration, success,
                                                failure, touched)  # fmt: skip
            classifier.dirty |= touched
            return touched
        return super().store_examples(classifier, slot, duration, success, failure)

    def drop_updates(self, slot: Tensor, failure: Tensor) -> None:
        tensors = self.q_head.slot_tensors()
        if all(kernels.copy_slots(value, failure, slot, self.snapshot[name], True)
               for name, value in tensors.items()):  # fmt: skip
            return
        super().drop_updates(slot, failure)


class CompiledRecentStates(RecentStates):
    """:class:`~skillchain_torch.discovery.skill_chaining.RecentStates` with its ring write
    compiled (this runs every step)."""

    def record(self, rows: Tensor, obs: Tensor) -> None:
        if kernels.record_ring(self.states, self.steps, rows, obs):
            return
        super().record(rows, obs)


class CompiledSkillChaining(SkillChaining):
    """:class:`~skillchain_torch.discovery.SkillChaining` with its per-step bookkeeping
    compiled (the same bits; see the module docstring). Takes SkillChaining's arguments."""

    trace_class = CompiledExecutionTrace
    recent_class = CompiledRecentStates
    target_indicator = staticmethod(compiled_target_indicator)
    event_list = staticmethod(compiled_event_list)
    exclude_overlap = staticmethod(compiled_exclude_overlap)

    def __init__(self, bank, *args, **kwargs):
        super().__init__(bank, *args, **kwargs)
        P, K, E = bank.population, bank.slots, len(self.events)
        # Reused CPU arrays for what the compiled outcomes and triggers write and the step
        # reads once (never kept), so they are not allocated every step.
        b = dict(dtype=torch.bool)
        self._outcomes_out = (torch.empty(P, dtype=torch.int64), torch.empty(P, **b),
                              torch.empty(P, **b))  # fmt: skip
        self._triggers_out = (torch.empty(P, E, **b), torch.empty(P, K, **b))

    def _triggers(self, contains: Tensor, option: Tensor, sample: Tensor, reached: Tensor,
                  stepped: Tensor, raw_now: Tensor, raw_next: Tensor,
                  events: Tensor) -> Tensor:  # fmt: skip
        if not kernels.applies(contains, stepped):
            return super()._triggers(contains, option, sample, reached, stepped, raw_now,
                                     raw_next, events)  # fmt: skip
        bank = self.bank
        self.gestation_q, base_trig, slot_trig, self.base_now, any_listed, hits = (
            kernels.triggers(bank.parent, bank.target_event, bank.status, self.base_now,
                             events, raw_now, raw_next, reached, stepped, sample,
                             self.gestation_q, self.max_branching, self._triggers_out,
                             blocked=self.slots_full_logged))
        # (an agent whose full slots are logged creates nothing: _create would only find that
        # out; late in a run every agent is full and enters a learned set at most steps)
        if self.recent is not None and hits is not None:  # (the hits of _gestation_hits)
            self._gestation_positives(hits)
        if not any_listed:  # only listed events create
            return torch.zeros_like(stepped)
        return self._create(base_trig, slot_trig, contains, option, sample)

    def _outcomes(self, option: Tensor, reached: Tensor, duration: Tensor, ended: Tensor,
                  terminated: Tensor) -> tuple[Tensor, Tensor, Tensor, bool] | None:  # fmt: skip
        if not kernels.applies(option, reached):
            return super()._outcomes(option, reached, duration, ended, terminated)
        slot, success, failure, any_ended, any_failure = kernels.outcomes(
            option, reached, duration, ended, terminated, self.max_option_steps,
            self._outcomes_out)  # fmt: skip
        return (slot, success, failure, any_failure) if any_ended else None
