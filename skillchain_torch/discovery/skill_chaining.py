"""``SkillChaining``: the discovery rules of paper sections 4 and 5.1 for a population.

One object holds the discovery state of P agents and applies the rules, each a named piece of
this package with the paper's value as default:

=========================  ==================================================  ==============
rule                       piece                                               paper value
=========================  ==================================================  ==============
target events              :mod:`.events` (base events, learned sets)          goal
creation, covered start    :mod:`.creation`                                    -
gestation, Q(s, o) init    :mod:`.gestation`                                   10 episodes
initiation-set examples,   :mod:`.executions`                                  250 steps
dropped failed updates
learned (convergence)      :mod:`.convergence`                                 0.15, twice
chaining + distance        :meth:`SkillChaining.end_episodes`                  0.1
constraint
no overlap                 :mod:`.overlap`                                     siblings, parent
branching limit            :func:`.events.event_list`                          3
slots full                 :meth:`SkillChaining.after_transition`              logged once
=========================  ==================================================  ==============

The agent (:class:`~skillchain_torch.agents.SkillChainingAgent`) calls it at four points:
:meth:`membership` / :meth:`targets` while it evaluates a state, :meth:`record` before each
transition, :meth:`after_transition` after its updates, and :meth:`end_episodes` when
episodes end. Every operation is row-wise (no reduction across agents), so agent p's options
are created, learned and chained identically alone or in a population.

Discovery events (``created``, ``joined``, ``learned``, ``slots_full``) are appended to
:attr:`log` as :class:`DiscoveryEvent` for loggers to drain.

Example:
    >>> import torch
    >>> from skillchain_torch.options import OptionBank, GoalEvent
    >>> bank = OptionBank.build(population=2, slots=4, order=1, capacity=16)
    >>> sc = SkillChaining(bank, events=(GoalEvent(),))
    >>> sc.gestation, sc.max_branching, sc.convergence.threshold
    (10, 3, 0.15)
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import GoalEvent, OptionBank, OptionStatus, TerminationPredicate
from skillchain_torch.options.status import slot_mask

from . import native_discovery
from .convergence import CONVERGENCE_EPISODES, CONVERGENCE_THRESHOLD, ConvergenceTest
from .creation import choose_creation, covered_start
from .events import MAX_BRANCHING, entered, evaluate_base_events, event_list, target_indicator
from .executions import ExecutionTrace, execution_outcome
from .gestation import GESTATION_EPISODES, gestation_over, initialise_option_values
from .overlap import exclude_overlap, overlap_exclusion

__all__ = ["SkillChaining", "DiscoveryEvent"]

logger = logging.getLogger("skillchain_torch.discovery")
MAX_OPTION_STEPS = 250


@dataclass(frozen=True)
class DiscoveryEvent:
    """One discovery event of one agent.

    ``kind``: ``"created"`` (a new gestating option in ``slot`` targeting ``target``),
    ``"joined"`` (gestation over, ``value`` = the initial Q(s, o)), ``"learned"`` (initiation
    set converged; now a target event) or ``"slots_full"`` (an uncovered event fired but no
    slot was left; logged once per agent, ``slot = -1``). ``episode`` is 0-based.
    """

    kind: str
    agent: int
    slot: int
    episode: int
    target: str = ""
    value: float = float("nan")


class SkillChaining:
    """Skill-chaining discovery for a population of agents sharing an :class:`OptionBank`.

    Args:
        bank: the agents' options (P agents, K slots); discovery fills its slots.
        events: the base target events, the goal first (section 4.4: add any indicator).
        gestation: episodes a new option gestates (paper: 10).
        max_branching: options per target event before it leaves the list (paper: 3).
        convergence_threshold: mean classifier weight change per episode (paper: 0.15).
        convergence_episodes: consecutive such episodes (paper: 2).
        max_option_steps: an execution longer than this failed (paper: 250).
        overlap: apply the no-overlap rule (paper: yes).
        wait_for_both_classes: fit an initiation set only once it has a positive and a
            negative example (default: fit after every new example, as the paper). Measured
            on 20 agents: with it, options whose executions never succeeded stayed available
            everywhere with their optimistic Q(s, o), and agents spent episodes of 20,000-35,000
            steps re-running them; without it such an option drops out after its failures.
    """

    def __init__(
        self,
        bank: OptionBank,
        events: Sequence[TerminationPredicate] = (GoalEvent(),),
        gestation: int = GESTATION_EPISODES,
        max_branching: int = MAX_BRANCHING,
        convergence_threshold: float = CONVERGENCE_THRESHOLD,
        convergence_episodes: int = CONVERGENCE_EPISODES,
        max_option_steps: int = MAX_OPTION_STEPS,
        overlap: bool = True,
        wait_for_both_classes: bool = False,
    ):
        if gestation < 0 or max_branching < 1 or max_option_steps < 1:
            raise ValueError("need gestation >= 0, max_branching >= 1, max_option_steps >= 1")
        self.bank = bank
        self.events = tuple(events)
        self.gestation, self.max_branching = int(gestation), int(max_branching)
        self.max_option_steps, self.overlap = int(max_option_steps), bool(overlap)
        self.wait_for_both_classes = bool(wait_for_both_classes)
        P, K, E = bank.population, bank.slots, len(self.events)
        device = bank.status.device
        self.convergence = ConvergenceTest(P, K, convergence_threshold, convergence_episodes,
                                           device=device)  # fmt: skip
        self.trace = ExecutionTrace(P, self.max_option_steps, bank.q_head, device=device)
        self.episode = torch.zeros(P, dtype=torch.int64, device=device)  # 0-based, running
        self.base_now = torch.zeros(P, E, dtype=torch.bool, device=device)  # events at s
        self.gestation_q = torch.full((P, K), -torch.inf, dtype=torch.float64, device=device)
        self.fitted = torch.zeros(P, K, dtype=torch.bool, device=device)  # this episode
        self.episode_weights = bank.classifier.snapshot()  # at each agent's episode start
        self.slots_full_logged = torch.zeros(P, dtype=torch.bool, device=device)
        self.log: list[DiscoveryEvent] = []
        self._base_next = self.base_now
        self._exclusion: Tensor | None = None
        # Reused CPU arrays for what the compiled outcomes and triggers write and the step
        # reads once (never kept), so they are not allocated every step.
        b = dict(dtype=torch.bool)
        self._outcomes_out = (torch.empty(P, dtype=torch.int64), torch.empty(P, **b),
                              torch.empty(P, **b))  # fmt: skip
        self._triggers_out = (torch.empty(P, E, **b), torch.empty(P, K, **b))

    # ------------------------------------------------------------------ evaluation
    def membership(self, contains: Tensor) -> Tensor:
        """The effective initiation sets ``[P, K]`` from the classifiers' ``contains``."""
        if not self.overlap:
            return contains
        if self._exclusion is None:  # changes only when options are created
            self._exclusion = overlap_exclusion(self.bank)
        return exclude_overlap(contains, self._exclusion, self.bank.classifier.trained)

    def targets(self, next_obs: Tensor, terminated: Tensor, contains: Tensor) -> Tensor:
        """Every option's target event at ``s'`` ``[P, K]``; keeps the base events' values."""
        self._base_next = evaluate_base_events(self.events, next_obs, terminated)
        return target_indicator(self.bank, self._base_next, contains)

    def start_episodes(self, obs: Tensor, rows: Tensor) -> None:
        """Agents ``rows [P]`` start an episode at ``obs [P, 4]``."""
        fired = evaluate_base_events(self.events, obs, torch.zeros_like(rows))
        self.base_now = torch.where(rows[:, None], fired, self.base_now)

    # ------------------------------------------------------------------ per step
    def record(self, executing: Tensor, step: Tensor, obs: Tensor) -> None:
        """Before a transition: executing agents act in ``obs`` as step ``step`` of it."""
        self.trace.record(executing, step, obs)  # (rows outside executing are skipped)

    def start_executions(self, rows: Tensor, slot: Tensor) -> None:
        """Agents ``rows [P]`` start executing ``slot [P]`` (after this step's updates)."""
        self.trace.start(rows, slot)  # (nothing when no row starts)

    def after_transition(self, *, contains: Tensor, option: Tensor, value: Tensor,
                         contains_next: Tensor, reached: Tensor, duration: Tensor,
                         decision_ended: Tensor, terminated: Tensor,
                         stepped: Tensor) -> Tensor:  # fmt: skip
        """Apply the rules to the transitions ``s -> s'`` of the rows in ``stepped [P]``.

        Args:
            contains, option, value: at ``s``: memberships ``[P, K]``, the executing slot
                (-1 none), and the top-level ``Q(s, d) [P]`` of the decision d in force.
            contains_next, reached: at ``s'``: memberships and each option's target ``[P, K]``.
            duration, decision_ended: the decision's steps so far and whether it ended now.
            terminated: the episode terminated at ``s'`` ``[P]``.

        Returns:
            ``BoolTensor [P]``: agents that created an option (their memberships at ``s'``
            must be re-evaluated by the caller: the new slot changed them).
        """
        bank = self.bank
        self._finish_executions(option, reached, duration, decision_ended & stepped,
                                terminated)  # fmt: skip
        sample = value  # Q(s, d) of the decision in force
        if native_discovery.applies(contains, stepped):  # the same rules, compiled
            self.gestation_q, base_trig, slot_trig, self.base_now, any_listed = (
                native_discovery.triggers(bank.parent, bank.target_event, bank.status,
                                          self.base_now, self._base_next, contains,
                                          contains_next, reached, stepped, sample,
                                          self.gestation_q, self.max_branching,
                                          self._triggers_out))  # fmt: skip
            if not any_listed:  # only listed events create
                return torch.zeros_like(stepped)
            return self._create(base_trig, slot_trig, contains, option, sample)
        gestating = bank.status == OptionStatus.GESTATING
        if bool(gestating.any()):
            before = target_indicator(bank, self.base_now, contains)
            fired = entered(before, reached) & gestating & stepped[:, None]
            self.gestation_q = torch.where(fired, torch.maximum(self.gestation_q, sample[:, None]),
                                           self.gestation_q)  # fmt: skip
        base_trig = entered(self.base_now, self._base_next) & stepped[:, None]
        slot_trig = entered(contains, contains_next) & stepped[:, None]
        slot_trig = slot_trig & (bank.status == OptionStatus.LEARNED)
        self.base_now = torch.where(stepped[:, None], self._base_next, self.base_now)
        created = torch.zeros_like(stepped)
        if bool(base_trig.any()) or bool(slot_trig.any()):
            created = self._create(base_trig, slot_trig, contains, option, sample)
        return created

    def _finish_executions(self, option: Tensor, reached: Tensor, duration: Tensor,
                           ended: Tensor, terminated: Tensor) -> None:  # fmt: skip
        """Examples, refits and dropped updates of the executions that ended."""
        if native_discovery.applies(option, reached):  # the same outcomes, compiled
            slot, success, failure, any_ended, any_failure = native_discovery.outcomes(
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
        base_trig, slot_trig = base_trig & base_on, slot_trig & slot_on
        if not (bool(base_trig.any()) or bool(slot_trig.any())):  # only unlisted events fired
            return torch.zeros(bank.population, dtype=torch.bool, device=base_trig.device)
        base_cov, slot_cov = covered_start(bank, len(self.events), contains, option)
        create, target_event, parent = choose_creation(base_trig, slot_trig, base_cov, slot_cov)
        if not bool(create.any()):
            return create
        full = bank.full()
        self._log_slots_full(create & full)
        create = create & ~full
        slot = bank.allocate(create, target_event=target_event, parent=parent,
                             episode=self.episode)  # fmt: skip
        new = slot_mask(create, slot, bank.slots)
        self.gestation_q = torch.where(new, sample[:, None], self.gestation_q)
        self.convergence.reset(new)
        self.fitted &= ~new
        self.episode_weights = torch.where(new[..., None], bank.classifier.snapshot(),
                                           self.episode_weights)  # fmt: skip
        self._exclusion = None
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

    # ------------------------------------------------------------------ per episode
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
            value = torch.nan_to_num(self.gestation_q, neginf=0.0)
            bank.set_status(join, OptionStatus.LEARNING)
            initialise_option_values(q_head, join, value)
            for p, k in join.nonzero().tolist():
                self._emit("joined", p, k, target=self.target_name(p, k),
                           value=float(value[p, k]))  # fmt: skip
        self.episode = self.episode + rows.to(torch.int64)
        self.episode_weights = torch.where(rows[:, None, None], classifier.snapshot(),
                                           self.episode_weights)  # fmt: skip
        self.fitted = self.fitted & ~rows[:, None]

    # ------------------------------------------------------------------ reading
    def target_name(self, agent: int, slot: int) -> str:
        """``"goal"`` (a base event's name) or ``"slot j"`` for slot ``slot`` of ``agent``."""
        parent = int(self.bank.parent[agent, slot])
        if parent >= 0:
            return f"slot {parent}"
        event = int(self.bank.target_event[agent, slot])
        return self.events[event].name if 0 <= event < len(self.events) else "none"

    def depth(self) -> Tensor:
        """``LongTensor [P, K]``: each live option's depth in its skill tree (1: targets a
        base event, 2: targets a depth-1 option's set, ...); 0 for empty slots."""
        bank = self.bank
        live = bank.live()
        depth = torch.where(live & (bank.parent < 0), 1, 0)
        for _ in range(bank.slots):  # a chain is at most K long
            parent_depth = depth.gather(1, bank.parent.clamp(min=0))
            chained = live & (bank.parent >= 0)
            depth = torch.where(chained, torch.where(parent_depth > 0, parent_depth + 1, 0), depth)
        return depth

    def _emit(self, kind: str, agent: int, slot: int, **fields) -> None:
        episode = int(self.episode[agent])
        self.log.append(DiscoveryEvent(kind, agent, slot, episode, **fields))

    def drain(self) -> list[DiscoveryEvent]:
        """The events since the last call (and forget them)."""
        events, self.log = self.log, []
        return events

    # ------------------------------------------------------------------ state
    _STATE = ("episode", "base_now", "gestation_q", "fitted", "episode_weights",
              "slots_full_logged")

    def state_dict(self) -> dict:
        state = {name: getattr(self, name).clone() for name in self._STATE}
        state["convergence"] = self.convergence.state_dict()
        state["trace"] = self.trace.state_dict()
        return state

    def load_state_dict(self, state: dict) -> None:
        device = self.episode.device
        for name in self._STATE:
            setattr(self, name, state[name].to(device).clone())
        self.convergence.load_state_dict(state["convergence"])
        self.trace.load_state_dict(state["trace"])
        self._exclusion = None
        self.log = []

    def __repr__(self) -> str:
        return (f"SkillChaining(events={[e.name for e in self.events]}, "
                f"gestation={self.gestation}, max_branching={self.max_branching}, "
                f"convergence={self.convergence.threshold}x{self.convergence.episodes}, "
                f"max_option_steps={self.max_option_steps}, overlap={self.overlap})")
