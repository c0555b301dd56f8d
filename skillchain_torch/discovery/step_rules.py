"""Skill chaining's rules at each transition (paper sections 4 and 5.1), beside the
orchestrator: the gestation samples (a gestating option's target entered: its positives and
the value sampled there), how executions end (a success adds positive examples, a failure a
negative one and drops the option's updates), and creating an option where a target event
fires from outside every set that already targets it (the branching limit, full agents logged
once).

A mixin of :class:`~skillchain_torch.discovery.SkillChaining`, which owns the state it reads;
each rule it applies is a named piece of :mod:`.creation`, :mod:`.events`, :mod:`.executions`
and :mod:`.gestation`.

Example:
    >>> import torch
    >>> from skillchain_torch.agents import SkillChainingAgent
    >>> agent = SkillChainingAgent.build(population=1, slots=2, order=1)
    >>> none = torch.zeros(1, 2, dtype=torch.bool)
    >>> agent.discovery._gestation_hits(none, none, torch.tensor([True])).tolist()
    [[False, False]]
"""

from __future__ import annotations

import logging

import torch
from torch import Tensor

from skillchain_torch.backends import discovery as backend
from skillchain_torch.options import OptionStatus
from skillchain_torch.options.status import slot_mask

from .creation import choose_creation, covered_start
from .events import entered, event_list, target_indicator
from .executions import execution_outcome

__all__ = ["StepRules"]

logger = logging.getLogger("skillchain_torch.discovery")  # the orchestrator's logger


class StepRules:
    """The per-transition rules :meth:`SkillChaining.after_transition` calls."""

    def _gestation_hits(self, raw_now: Tensor, reached: Tensor, stepped: Tensor) -> Tensor:
        """``[P, K]``: gestating options whose target was entered by this transition."""
        gestating = self.bank.status == OptionStatus.GESTATING
        hit = reached & gestating
        if not bool(hit.any()):  # the usual step: no target of a gestating option at s'
            return hit
        before = target_indicator(self.bank, self.base_now, raw_now)
        return entered(before, reached) & gestating & stepped[:, None]

    def _gestation_positives(self, hits: Tensor) -> None:
        """The last ``reading.gestation_positives`` states of each agent's trajectory become
        positive examples of the slots in ``hits [P, K]`` (their target just fired)."""
        if not bool(hits.any()):
            return
        classifier, n = self.bank.classifier, self.reading.gestation_positives
        for p, k in hits.nonzero().tolist():
            rows = torch.zeros_like(self.episode, dtype=torch.bool)
            rows[p] = True
            agents, obs = self.recent.window(rows, n)
            labels = torch.ones_like(agents, dtype=torch.bool)
            classifier.add_examples(agents, k, obs, labels)

    def _finish_executions(self, option: Tensor, reached: Tensor, duration: Tensor,
                           ended: Tensor, terminated: Tensor) -> None:  # fmt: skip
        """Examples, refits and dropped updates of the executions that ended."""
        if backend.NATIVE and backend.applies(option, reached):  # the same outcomes, compiled
            slot, success, failure, any_ended, any_failure = backend.outcomes(
                option, reached, duration, ended, terminated, self.max_option_steps,
                self._outcomes_out)  # fmt: skip
            if not any_ended:
                return
        else:
            ended = ended & (option >= 0)
            if not bool(ended.any()):
                return
            slot = option.clamp(min=0)
            hit = reached.gather(1, slot[:, None])[:, 0]
            success, failure = execution_outcome(hit, duration, terminated,
                                                 self.max_option_steps)  # fmt: skip
            success, failure = success & ended, failure & ended
            any_failure = bool(failure.any())
        timeout = failure & (duration >= self.max_option_steps)
        self.counts.add(ended & (option >= 0), slot, success, timeout, failure & ~timeout,
                        duration)  # fmt: skip
        classifier = self.bank.classifier
        touched = self.trace.store_examples(classifier, slot, duration, success, failure)
        # Paper: 100 sweeps per new data point. Logistic regression on failures alone says
        # "no" everywhere (the features are non-negative), so an option whose first executions
        # all fail leaves the repertoire; wait_for_both_classes keeps such a set "true
        # everywhere" until it has seen a success and a failure instead.
        fit = touched & classifier.has_both_classes() if self.wait_for_both_classes else touched
        if bool(fit.any()):
            classifier.fit(fit)
            self.fitted |= fit
        if any_failure:
            self.trace.drop_updates(slot, failure)

    def _create(self, base_trig: Tensor, slot_trig: Tensor, contains: Tensor, option: Tensor,
                sample: Tensor) -> Tensor:  # fmt: skip
        bank = self.bank
        base_on, slot_on = event_list(bank, len(self.events), self.max_branching)
        # An agent whose slots are full creates nothing; once its first blocked creation is
        # logged its triggers need no more work. (Late in a run every agent is full, and some
        # agent enters a learned option's set at nearly every step.)
        full = bank.full()
        open_ = (~(full & self.slots_full_logged))[:, None]
        base_trig, slot_trig = base_trig & base_on & open_, slot_trig & slot_on & open_
        if not (bool(base_trig.any()) or bool(slot_trig.any())):  # nothing can be created
            return torch.zeros(bank.population, dtype=torch.bool, device=base_trig.device)
        base_cov, slot_cov = covered_start(bank, len(self.events), contains, option)
        create, target_event, parent = choose_creation(base_trig, slot_trig, base_cov, slot_cov)
        if not bool(create.any()):
            return create
        self._log_slots_full(create & full)
        create = create & ~full
        if not bool(create.any()):
            return create
        slot = bank.allocate(create, target_event=target_event, parent=parent,
                             episode=self.episode)  # fmt: skip
        new = slot_mask(create, slot, bank.slots)
        self.gestation_q = torch.where(new, sample[:, None], self.gestation_q)
        self.convergence.reset(new)
        self.fitted &= ~new
        self.episode_weights = torch.where(new[..., None], bank.classifier.snapshot(),
                                           self.episode_weights)  # fmt: skip
        self._exclusion = None
        if self.recent is not None:  # the creating hit is the first of gestation
            self._gestation_positives(new)
        for p in create.nonzero()[:, 0].tolist():
            k = int(slot[p])
            self._emit("created", p, k, target=self.target_name(p, k))
        return create

    def _log_slots_full(self, blocked: Tensor) -> None:
        first = blocked & ~self.slots_full_logged
        if not bool(first.any()):
            return
        self.slots_full_logged |= first
        for p in first.nonzero()[:, 0].tolist():
            self._emit("slots_full", p, -1)
            logger.info("agent %d: all %d option slots are used; it creates no more options",
                        p, self.bank.slots)

