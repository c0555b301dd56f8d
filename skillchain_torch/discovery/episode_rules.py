"""Skill chaining's rules at the end of an episode (paper section 5.1): an initiation set whose
classifier has settled is learned (and becomes a target event), and an option whose gestation
is over joins the agent's decisions with its initial ``Q(s, o)`` and policy.

A mixin of :class:`~skillchain_torch.discovery.SkillChaining`, which owns the state it reads
(``bank``, ``convergence``, ``episode``, ``episode_weights``, ``fitted``, ``gestation_q``, the
reading and the starts); each rule it applies is a named piece of :mod:`.convergence` and
:mod:`.gestation`.

Example:
    >>> import torch
    >>> from skillchain_torch.agents import SkillChainingAgent
    >>> agent = SkillChainingAgent.build(population=1, slots=2, order=1)
    >>> agent.discovery.end_episodes(torch.tensor([True]), agent.q_head)
    >>> agent.discovery.episode.tolist()
    [1]
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import OptionStatus

from .gestation import (
    cached_projection,
    gestation_over,
    initialise_option_policies,
    initialise_option_values,
    state_value_fit,
)
from .value_scale import shift_option_values, target_levels

__all__ = ["EpisodeRules"]


class EpisodeRules:
    """:meth:`end_episodes`: convergence and chaining, the end of gestation."""

    def end_episodes(self, rows: Tensor, q_head: LinearQHead) -> None:
        """Agents ``rows [P]`` ended an episode: convergence and chaining, end of gestation."""
        bank, classifier = self.bank, self.bank.classifier
        learning = bank.status == OptionStatus.LEARNING
        counted = rows[:, None] & learning & self.fitted
        if bool(counted.any()):
            change = classifier.weight_change(self.episode_weights)
            converged = self.convergence.update(change, counted)
            learned = converged & classifier.stored_classes()[0]  # needs a positive example
            if bool(learned.any()):
                bank.set_status(learned, OptionStatus.LEARNED)
                classifier.constrain(learned)  # distance 0.1 from a positive example
                for p, k in learned.nonzero().tolist():
                    self._emit("learned", p, k, target=self.target_name(p, k))
        join = gestation_over(bank, self.episode, rows, self.gestation)
        if bool(join.any()):
            self._start_sets(join)
            value = torch.nan_to_num(self.gestation_q, neginf=0.0)
            bank.set_status(join, OptionStatus.LEARNING)
            initialise_option_values(q_head, join, value, q_head.num_decisions - bank.slots)
            if self.value_start == "agent":
                self._agent_values(q_head, join)
            if self.policy_start != "zero":  # a copy of the top level's primitive values
                if self._projection is None:  # once per run: a fixed grid, no random numbers
                    self._projection = cached_projection(self.top_basis, bank.q_head.basis)
                initialise_option_policies(bank.q_head, q_head, join, self._projection,
                                           bank.num_actions)  # fmt: skip
            if self.policy_start == "top-level-shifted":  # ... on the option's own scale
                level = target_levels(bank, q_head, self.top_basis, join)
                shift_option_values(bank.q_head, join, self.completion_reward - level)
            for p, k in join.nonzero().tolist():
                self._emit("joined", p, k, target=self.target_name(p, k),
                           value=float(value[p, k]))  # fmt: skip
        self.counts.end_episodes(rows)
        self.episode = self.episode + rows.to(torch.int64)
        self.episode_weights = torch.where(rows[:, None, None], classifier.snapshot(),
                                           self.episode_weights)  # fmt: skip
        self.fitted = self.fitted & ~rows[:, None]

    @torch.no_grad()
    def _agent_values(self, q_head: LinearQHead, join: Tensor) -> None:
        """``Q(s, o) = max_a Q(s, a) + value_bonus`` (fitted) for the options in ``join``."""
        if self._value_fit is None:  # once per run: a fixed grid, no random numbers
            self._value_fit = state_value_fit(self.top_basis)
        primitives = q_head.weight.shape[1] - self.bank.slots
        for p, k in join.nonzero().tolist():
            w = self._value_fit(q_head.weight[p, :primitives])
            w[0] += self.value_bonus
            q_head.weight[p, primitives + k] = w.to(q_head.weight.dtype)

    def _start_sets(self, join: Tensor) -> None:
        """The initiation sets of the options in ``join [P, K]`` as gestation ends, by the
        reading: fitted on their gestation positives (``start="fitted"``), and under the
        distance constraint from now on (``constrain="start"``)."""
        classifier = self.bank.classifier
        if self.reading.start == "fitted":
            positive, negative = classifier.stored_classes()
            fit = join & positive & (negative | self.reading.one_class_fits)
            if bool(fit.any()):
                classifier.fit(fit)
        if self.reading.constrain == "start":
            classifier.constrain(join)

