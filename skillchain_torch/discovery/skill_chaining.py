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
from .gestation import (
    GESTATION_EPISODES,
    POLICY_STARTS,
    VALUE_STARTS,
    RecentStates,
    cached_projection,
    gestation_over,
    initialise_option_policies,
    initialise_option_values,
    state_value_fit,
)
from .overlap import exclude_overlap, overlap_exclusion
from .readings import FIRST_READING, InitiationReading

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
        reading: how the initiation sets start (:class:`~.readings.InitiationReading`:
            gestation positives, the set at the end of gestation, when the 0.1 distance
            constraint applies, one-class fits). Default: the first reading (no gestation
            positives, true everywhere, constrained once learned, one-class fits).
        wait_for_both_classes: shorthand for ``reading.one_class_fits = False``: fit an
            initiation set only once it has a positive and a negative example. Measured on
            20 agents of the first reading: options whose executions never succeeded stayed
            available everywhere with their optimistic Q(s, o), and agents spent episodes of
            20,000-35,000 steps re-running them.
        policy_start: how a joining option's policy starts (:data:`~.gestation.POLICY_STARTS`):
            ``"zero"`` keeps what gestation's off-policy updates made of zero weights (the
            paper is silent); ``"top-level"`` sets it to the agent's own primitive values
            projected onto the option's basis (:func:`~.gestation.initialise_option_policies`),
            as deep skill chaining starts options from the global agent. Needs ``top_basis``
            and a Fourier option head.
        value_start: how ``Q(s, o)`` starts when the option joins
            (:data:`~.gestation.VALUE_STARTS`): ``"max-sample"`` (the paper: the best value
            sampled when its target fired in gestation, everywhere) or ``"agent"`` (the agent's
            own ``max_a Q(s, a)`` fitted in its basis, plus ``value_bonus``). Needs ``top_basis``.
        value_bonus: added to ``Q(s, o)`` everywhere under ``value_start="agent"``.
        top_basis: the agent's top-level :class:`~skillchain_torch.features.FourierBasis`.
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
        reading: InitiationReading = FIRST_READING,
        policy_start: str = "zero",
        value_start: str = "max-sample",
        value_bonus: float = 0.0,
        top_basis=None,
    ):
        if value_start not in VALUE_STARTS:
            raise ValueError(f"value_start must be one of {', '.join(VALUE_STARTS)}, "
                             f"got {value_start!r}")  # fmt: skip
        if value_start == "agent" and top_basis is None:
            raise ValueError("value_start 'agent' needs the agent's Fourier basis (top_basis)")
        self.value_start, self.value_bonus = value_start, float(value_bonus)
        self._value_fit = None
        if policy_start not in POLICY_STARTS:
            raise ValueError(f"policy_start must be one of {', '.join(POLICY_STARTS)}, "
                             f"got {policy_start!r}")  # fmt: skip
        if policy_start == "top-level" and (top_basis is None
                                            or getattr(bank.q_head, "basis", None) is None):
            raise ValueError("policy_start 'top-level' needs the agent's Fourier basis "
                             "(top_basis) and a Fourier option head (FourierOptionQHead)")
        self.policy_start, self.top_basis = policy_start, top_basis
        self._projection: Tensor | None = None
        if gestation < 0 or max_branching < 1 or max_option_steps < 1:
            raise ValueError("need gestation >= 0, max_branching >= 1, max_option_steps >= 1")
        self.bank = bank
        self.events = tuple(events)
        self.gestation, self.max_branching = int(gestation), int(max_branching)
        self.max_option_steps, self.overlap = int(max_option_steps), bool(overlap)
        if wait_for_both_classes:
            reading = reading.replace(one_class_fits=False)
        self.reading = reading
        self.wait_for_both_classes = not reading.one_class_fits
        P, K, E = bank.population, bank.slots, len(self.events)
        device = bank.status.device
        self.convergence = ConvergenceTest(P, K, convergence_threshold, convergence_episodes,
                                           device=device)  # fmt: skip
        self.trace = ExecutionTrace(P, self.max_option_steps, bank.q_head, device=device)
        self.episode = torch.zeros(P, dtype=torch.int64, device=device)  # 0-based, running
        self.base_now = torch.zeros(P, E, dtype=torch.bool, device=device)  # events at s
        # The classifiers' own sets at s, and at the state last evaluated (membership).
        self.raw_now = torch.zeros(P, K, dtype=torch.bool, device=device)
        self.last_raw = self.raw_now
        self.gestation_q = torch.full((P, K), -torch.inf, dtype=torch.float64, device=device)
        self.fitted = torch.zeros(P, K, dtype=torch.bool, device=device)  # this episode
        self.episode_weights = bank.classifier.snapshot()  # at each agent's episode start
        self.slots_full_logged = torch.zeros(P, dtype=torch.bool, device=device)
        self.log: list[DiscoveryEvent] = []
        # The states each agent acted in this episode, for gestation positives (if any).
        n = reading.gestation_positives
        self.recent = RecentStates(P, n, device=device, obs_dim=bank.obs_dim) if n > 0 else None
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
        """The effective initiation sets ``[P, K]`` from the classifiers' ``contains``.

        The classifiers' own sets (``contains``) are kept as :attr:`last_raw`: target events
        are those sets, while choice and the covered-start rule use the effective ones (a
        child's set minus its parent's and older siblings'). Were targets the effective sets,
        an option leaving its parent's set into a region its child's target covers would
        "enter" that target without moving towards it, and create a child there."""
        self.last_raw = contains
        if not self.overlap:
            return contains
        if self._exclusion is None:  # changes only when options are created
            self._exclusion = overlap_exclusion(self.bank)
        return exclude_overlap(contains, self._exclusion, self.bank.classifier.trained)

    def targets(self, next_obs: Tensor, terminated: Tensor, contains: Tensor) -> Tensor:
        """Every option's target event at ``s'`` ``[P, K]``; keeps the base events' values.

        ``contains``: the classifiers' own sets at ``s'`` (:attr:`last_raw`), not the
        effective ones (see :meth:`membership`)."""
        self._base_next = evaluate_base_events(self.events, next_obs, terminated)
        return target_indicator(self.bank, self._base_next, contains)

    def start_episodes(self, obs: Tensor, rows: Tensor) -> None:
        """Agents ``rows [P]`` start an episode at ``obs [P, 4]``."""
        fired = evaluate_base_events(self.events, obs, torch.zeros_like(rows))
        self.base_now = torch.where(rows[:, None], fired, self.base_now)
        self.raw_now = torch.where(rows[:, None], self.last_raw, self.raw_now)
        if self.recent is not None:
            self.recent.start_episodes(rows)

    def record_states(self, stepped: Tensor, obs: Tensor) -> None:
        """Before a transition: agents ``stepped [P]`` act in ``obs [P, 4]`` (kept for the
        gestation positives of the reading; nothing to do without them)."""
        if self.recent is not None:
            self.recent.record(stepped, obs)

    # ------------------------------------------------------------------ per step
    def record(self, executing: Tensor, step: Tensor, obs: Tensor) -> None:
        """Before a transition: executing agents act in ``obs`` as step ``step`` of it."""
        self.trace.record(executing, step, obs)  # (rows outside executing are skipped)

    def start_executions(self, rows: Tensor, slot: Tensor) -> None:
        """Agents ``rows [P]`` start executing ``slot [P]`` (after this step's updates)."""
        self.trace.start(rows, slot)  # (nothing when no row starts)

    def after_transition(self, *, contains: Tensor, option: Tensor, value: Tensor,
                         reached: Tensor, duration: Tensor,
                         decision_ended: Tensor, terminated: Tensor,
                         stepped: Tensor) -> Tensor:  # fmt: skip
        """Apply the rules to the transitions ``s -> s'`` of the rows in ``stepped [P]``.

        Args:
            contains, option, value: at ``s``: memberships ``[P, K]``, the executing slot
                (-1 none), and the top-level ``Q(s, d) [P]`` of the decision d in force.
            reached: at ``s'``: each option's target ``[P, K]`` (in the classifiers' own sets).
            duration, decision_ended: the decision's steps so far and whether it ended now.
            terminated: the episode terminated at ``s'`` ``[P]``.

        Target events are entered and reached in the classifiers' own sets (:attr:`raw_now`
        at ``s``, :attr:`last_raw` at ``s'``); ``contains`` (effective) decides coverage.

        Returns:
            ``BoolTensor [P]``: agents that created an option (their memberships at ``s'``
            must be re-evaluated by the caller: the new slot changed them, and
            :meth:`created_rows_evaluated` then takes their own sets).
        """
        bank = self.bank
        raw_now, raw_next = self.raw_now, self.last_raw
        self.raw_now = torch.where(stepped[:, None], raw_next, raw_now)
        self._finish_executions(option, reached, duration, decision_ended & stepped,
                                terminated)  # fmt: skip
        sample = value  # Q(s, d) of the decision in force
        if native_discovery.applies(contains, stepped):  # the same rules, compiled
            self.gestation_q, base_trig, slot_trig, self.base_now, any_listed, hits = (
                native_discovery.triggers(bank.parent, bank.target_event, bank.status,
                                          self.base_now, self._base_next, raw_now,
                                          raw_next, reached, stepped, sample,
                                          self.gestation_q, self.max_branching,
                                          self._triggers_out))  # fmt: skip
            if self.recent is not None and hits is not None:  # (the hits of _gestation_hits)
                self._gestation_positives(hits)
            if not any_listed:  # only listed events create
                return torch.zeros_like(stepped)
            return self._create(base_trig, slot_trig, contains, option, sample)
        if self.recent is not None:  # before base_now moves on to s'
            self._gestation_positives(self._gestation_hits(raw_now, reached, stepped))
        gestating = bank.status == OptionStatus.GESTATING
        if bool(gestating.any()):
            before = target_indicator(bank, self.base_now, raw_now)
            fired = entered(before, reached) & gestating & stepped[:, None]
            self.gestation_q = torch.where(fired, torch.maximum(self.gestation_q, sample[:, None]),
                                           self.gestation_q)  # fmt: skip
        base_trig = entered(self.base_now, self._base_next) & stepped[:, None]
        slot_trig = entered(raw_now, raw_next) & stepped[:, None]
        slot_trig = slot_trig & (bank.status == OptionStatus.LEARNED)
        self.base_now = torch.where(stepped[:, None], self._base_next, self.base_now)
        created = torch.zeros_like(stepped)
        if bool(base_trig.any()) or bool(slot_trig.any()):
            created = self._create(base_trig, slot_trig, contains, option, sample)
        return created

    def created_rows_evaluated(self, created: Tensor) -> None:
        """The caller re-evaluated the memberships at ``s'`` of the agents in ``created [P]``
        (:meth:`membership`): keep those rows' own sets as the current ones."""
        self.raw_now = torch.where(created[:, None], self.last_raw, self.raw_now)

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
            self._start_sets(join)
            value = torch.nan_to_num(self.gestation_q, neginf=0.0)
            bank.set_status(join, OptionStatus.LEARNING)
            initialise_option_values(q_head, join, value, q_head.num_decisions - bank.slots)
            if self.value_start == "agent":
                self._agent_values(q_head, join)
            if self.policy_start == "top-level":
                if self._projection is None:  # once per run: a fixed grid, no random numbers
                    self._projection = cached_projection(self.top_basis, bank.q_head.basis)
                initialise_option_policies(bank.q_head, q_head, join, self._projection,
                                           bank.num_actions)  # fmt: skip
            for p, k in join.nonzero().tolist():
                self._emit("joined", p, k, target=self.target_name(p, k),
                           value=float(value[p, k]))  # fmt: skip
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
    _STATE = ("episode", "base_now", "raw_now", "gestation_q", "fitted", "episode_weights",
              "slots_full_logged")

    def state_dict(self) -> dict:
        state = {name: getattr(self, name).clone() for name in self._STATE}
        state["convergence"] = self.convergence.state_dict()
        state["trace"] = self.trace.state_dict()
        if self.recent is not None:
            state["recent"] = self.recent.state_dict()
        return state

    def load_state_dict(self, state: dict) -> None:
        device = self.episode.device
        for name in self._STATE:
            setattr(self, name, state[name].to(device).clone())
        self.convergence.load_state_dict(state["convergence"])
        self.trace.load_state_dict(state["trace"])
        if self.recent is not None:
            if "recent" not in state:
                raise ValueError("the saved discovery state has no recent states: it was "
                                 "saved by a reading without gestation positives")
            self.recent.load_state_dict(state["recent"])
        self._exclusion = None
        self.log = []

    def __repr__(self) -> str:
        return (f"SkillChaining(events={[e.name for e in self.events]}, "
                f"gestation={self.gestation}, max_branching={self.max_branching}, "
                f"convergence={self.convergence.threshold}x{self.convergence.episodes}, "
                f"max_option_steps={self.max_option_steps}, overlap={self.overlap}, "
                f"reading={self.reading.name}, policy_start={self.policy_start!r})")
