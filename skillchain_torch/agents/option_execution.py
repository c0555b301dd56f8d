"""The options inside the hierarchical agent: which initiation sets hold a state, which
targets fired, the executing option's action (paper sections 2 and 4), and the readings of
an execution the paper leaves open (interruption, what the primitives learn inside options).

A mixin of :class:`~skillchain_torch.agents.HierarchicalAgent` (it reads ``bank``, ``events``,
the no-overlap ``_exclusion`` and the per-step state); skill chaining overrides :meth:`narrow`
and :meth:`targets` with its own rules.

Example:
    >>> from skillchain_torch.agents import HierarchicalAgent
    >>> from skillchain_torch.options import OptionBank
    >>> agent = HierarchicalAgent(OptionBank.build(population=1, slots=2, order=1), order=1)
    >>> agent.membership(torch.tensor([[0.2, 0.9, 0.5, 0.5]], dtype=torch.float64)).tolist()
    [[True, True]]
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends import hierarchical as backend
from skillchain_torch.discovery.events import evaluate_base_events, target_indicator
from skillchain_torch.discovery.overlap import exclude_overlap
from skillchain_torch.options import OptionStatus
from skillchain_torch.policies import epsilon_greedy

__all__ = ["OptionExecution", "FAILURE_BOOTSTRAPS", "INTRA_OPTION_TARGETS", "END_OUTSIDE_SET"]


FAILURE_BOOTSTRAPS = ("decision", "primitives")
INTRA_OPTION_TARGETS = ("decisions", "primitives")
# Which executions end where they leave their option's own set: none (the paper), those of
# options whose sets are learned (OptionStatus.LEARNED), or every one.
END_OUTSIDE_SET = {"off": None, "learned": OptionStatus.LEARNED, "always": OptionStatus.LEARNING}


class OptionExecution:
    """Memberships, targets and the executing option's action."""

    def _set_readings(self, failure_bootstrap: str, intra_option_primitives: bool,
                      intra_option_target: str, interruption: bool,
                      end_outside_set: str) -> None:  # fmt: skip
        """Check and keep the readings of an execution (HierarchicalAgent's arguments)."""
        if failure_bootstrap not in FAILURE_BOOTSTRAPS:
            raise ValueError(f"failure_bootstrap must be one of {', '.join(FAILURE_BOOTSTRAPS)}"
                             f", got {failure_bootstrap!r}")  # fmt: skip
        if intra_option_target not in INTRA_OPTION_TARGETS:
            raise ValueError(f"intra_option_target must be one of "
                             f"{', '.join(INTRA_OPTION_TARGETS)}, got {intra_option_target!r}")
        if end_outside_set not in END_OUTSIDE_SET:
            raise ValueError(f"end_outside_set must be one of {', '.join(END_OUTSIDE_SET)}, "
                             f"got {end_outside_set!r}")  # fmt: skip
        self.failure_bootstrap = failure_bootstrap
        self.intra_option_primitives = bool(intra_option_primitives)
        self.intra_option_target = intra_option_target
        self.interruption, self.end_outside_set = bool(interruption), end_outside_set
        self.leave_from = END_OUTSIDE_SET[end_outside_set]

    def membership(self, obs: Tensor) -> Tensor:
        """``[P, K]``: which initiation sets hold ``obs [P, 4]`` for *choosing* an option (one
        classifier evaluation per visited state). The classifiers' own sets are kept as
        ``_raw_contains``: the targets of chained options, and where options learn."""
        self._raw_contains = self.bank.classifier.contains(obs)
        return self.narrow(self._raw_contains)

    def narrow(self, contains: Tensor) -> Tensor:
        """The sets an option may be chosen in, from the classifiers' own ``contains [P, K]``
        (skill chaining: its no-overlap rule, section 4.3)."""
        if self._exclusion is None:
            return contains
        return exclude_overlap(contains, self._exclusion, self.bank.classifier.trained)

    def targets(self, next_obs: Tensor, terminated: Tensor, contains: Tensor) -> Tensor:
        """``[P, K]``: each live option's termination predicate (target event) at ``s'``.

        A chained option's target is its parent's own initiation set (the classifier's, as in
        discovery), not the parent's set narrowed by the no-overlap rule."""
        raw = contains if self._exclusion is None else self._raw_contains
        bank = self.bank
        # OptionBank.target_reached's answer from the events' values (compiled where built):
        # this runs every step, and target_reached costs ~140 us of small torch ops.
        if bank.slots and int(bank.target_event.max()) >= len(self.events):
            used = int(bank.target_event.max())
            raise ValueError(f"target event {used} used by a slot, but only {len(self.events)} "
                             f"given")  # fmt: skip
        return target_indicator(bank, evaluate_base_events(self.events, next_obs, terminated),
                                raw)  # fmt: skip

    def _best_decision(self) -> Tensor:
        """``[P]``: ``max_d Q(s', d)`` over the decisions available at ``s'`` (``last_q``)."""
        return self.last_q.masked_fill(~self.last_available, -torch.inf).max(1).values

    def _best_primitive(self) -> Tensor:
        """``[P]``: ``max_a Q(s', a)`` over the primitives at ``s'`` (``last_q``)."""
        return self.last_q[:, :self.num_primitives].max(1).values

    def _interrupted(self, going_on: Tensor, phi_next: Tensor) -> Tensor:
        """``[P]``: the executions in ``going_on`` that stop at ``s'`` because the option in
        force is no longer the greedy decision there (``Q(s', o) < max_d Q(s', d)``;
        ``interruption``, Sutton, Precup & Singh 1999, section 5)."""
        in_force = self.decision[:, None]
        q_o = self.last_q.gather(1, in_force)[:, 0]  # valued where available at s'
        gone = (going_on & ~self.last_available.gather(1, in_force)[:, 0]).nonzero()[:, 0]
        if gone.numel() > 0:  # s' left the option's set: value it there
            q_o = q_o.index_put((gone,), self.q_head.q_value(phi_next, self.decision, gone))
        return going_on & (q_o < self._best_decision())

    def _leaves(self, own_next: Tensor) -> Tensor | bool:
        """``[P]``: executions whose ``s'`` lies outside their option's own initiation set
        (``own_next [P, K]``), which end there under ``end_outside_set`` (``"learned"``: only
        options whose sets are learned; ``"off"``: none, ``False``)."""
        if self.leave_from is None:
            return False
        slot = self.option.clamp(min=0)[:, None]
        status = self.bank.status.gather(1, slot)[:, 0]
        return (self.option >= 0) & (status >= self.leave_from) & ~own_next.gather(1, slot)[:, 0]

    def _learn_inside(self, reward: Tensor, terminated: Tensor, inside: Tensor,
                      stepped: Tensor, phi_next: Tensor) -> None:  # fmt: skip
        """``intra_option_primitives``: the primitive an option took at ``s`` moves toward
        ``r + max Q(s', .)`` (one Q-learning step; over every available decision, or the
        primitives only with ``intra_option_target="primitives"``); ``state_phi`` moves on."""
        best = (self._best_primitive() if self.intra_option_target == "primitives"
                else self._best_decision())  # fmt: skip
        self.learn(self.state_phi, self.action, reward, torch.ones_like(self.duration), best,
                   terminated, inside)
        self.state_phi = torch.where(stepped[:, None], phi_next, self.state_phi)

    def _act(self, rows: Tensor, uniforms: Tensor) -> None:
        """Set ``action`` of ``rows [P]``: the primitive decision, or the executing option's
        epsilon-greedy action by its Q-head at the current state."""
        if self.native:
            self.action = backend.act(self.bank.q_head.weight, self.option_code, rows,
                                      self.decision, self.option, uniforms, self.option_epsilon,
                                      self.action.clone())  # fmt: skip
            return
        action = self.decision.clamp(max=self.num_primitives - 1)
        executing = rows & (self.option >= 0)
        index = executing.nonzero()[:, 0]
        if index.numel() > 0:  # only the executing rows' option values (a row's own sums)
            q_opt = self.bank.q_head.slot_values_rows(self.option_code, self.option, index)
            all_actions = torch.ones_like(q_opt, dtype=torch.bool)
            by_option = epsilon_greedy(q_opt, all_actions, self.option_epsilon, uniforms[index],
                                       check=False)  # fmt: skip
            action = action.index_put((index,), by_option)
        self.action = torch.where(rows, action, self.action)

