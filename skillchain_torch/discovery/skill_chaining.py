"""``SkillChaining``: the discovery rules of paper sections 4 and 5.1 for a population, in one file.

One object holds the discovery state of P agents and applies the rules, in the order the agent
calls them. Each rule is a named method or function of this file with the paper's value as
its default; only what runs when an episode ends and is long stays in its own module.

=========================  ==================================================  ==============
rule                       where                                               paper value
=========================  ==================================================  ==============
target events              :func:`targeting`, :func:`event_list`,              goal
                           :func:`entered` (at a state: the option bank's
                           :func:`~skillchain_torch.options.bank.target_indicator`)
no overlap                 :func:`overlap_exclusion`, :func:`exclude_overlap`  siblings, parent
initiation-set examples,   :class:`ExecutionTrace`,                            250 steps
dropped failed updates     :meth:`SkillChaining._finish_executions`
creation, covered start    :meth:`SkillChaining._create`, :func:`covered_start`  -
branching limit            :func:`event_list`                                  3
slots full                 :meth:`SkillChaining._log_slots_full`               logged once
gestation, Q(s, o) init    :meth:`SkillChaining.end_episodes`, :mod:`.gestation`  10 episodes
learned (convergence)      :mod:`.convergence`                                 0.15, twice
chaining + distance        :meth:`SkillChaining.end_episodes`                  0.1
constraint
=========================  ==================================================  ==============

The agent (:class:`~skillchain_torch.agents.SkillChainingAgent`) calls it at three points, and
they read here in that order: :meth:`~SkillChaining.membership` while it evaluates a state,
:meth:`~SkillChaining.after_transition` once per step after its updates (the step's record,
executions that ended, gestation samples, creation, executions that start), and
:meth:`~SkillChaining.end_episodes` when episodes end (learned sets become targets, gestation
ends). The target events at a state are the agent's to evaluate (the termination predicates,
then the bank's :func:`~skillchain_torch.options.bank.target_indicator`); it hands their values
to :meth:`~SkillChaining.after_transition`. Every operation is row-wise (no reduction across
agents), so agent p's options are created, learned and chained identically alone or in a
population.

Discovery events (``created``, ``joined``, ``learned``, ``slots_full``) are appended to
:attr:`~SkillChaining.log` as :class:`DiscoveryEvent` for loggers to drain.

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

from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import (
    GoalEvent,
    InitiationClassifier,
    OptionBank,
    OptionQHead,
    OptionStatus,
    TerminationPredicate,
)
from skillchain_torch.options.bank import target_indicator
from skillchain_torch.options.initiation_fit import check_fittable
from skillchain_torch.options.status import slot_mask
from skillchain_torch.options.termination import evaluate_base_events

from .convergence import CONVERGENCE_EPISODES, CONVERGENCE_THRESHOLD, ConvergenceTest
from .gestation import (
    GESTATION_EPISODES,
    POLICY_STARTS,
    VALUE_STARTS,
    cached_projection,
    fit_grid,
    fitted_starts,
    gestation_over,
    initialise_option_policies,
    initialise_option_values,
    state_value_fit,
)
from .readings import FIRST_READING, InitiationReading
from .value_scale import shift_option_values, target_levels

__all__ = ["SkillChaining", "DiscoveryEvent", "MAX_BRANCHING", "OUTCOMES", "targeting",
           "event_list", "evaluate_base_events", "target_indicator", "entered",
           "overlap_exclusion", "exclude_overlap", "covered_start", "choose_creation",
           "execution_outcome", "ExecutionTrace", "ExecutionCounts", "RecentStates"]

logger = logging.getLogger("skillchain_torch.discovery")

MAX_OPTION_STEPS = 250

MAX_BRANCHING = 3  # paper 5.1: "a maximum branching factor of 3"
# How an execution ends, as counted per agent-episode (ExecutionCounts, the run's
# option_outcomes.npy): its target fired; it ran max_steps; the episode terminated elsewhere.
# (An execution cut by a truncated episode is neither success nor failure: its steps count,
# its outcome does not.)
OUTCOMES = ("success", "timeout", "episode_end")


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
            as deep skill chaining starts options from the global agent;
            ``"top-level-shifted"`` moves that copy onto the option's own scale (its target
            worth ``completion_reward``, :mod:`~.value_scale`). With heads that are not linear
            in a Fourier basis (an MLP top level or option head) ``"top-level"`` is the same
            copy fitted in the option head's last layer on a grid of states
            (:func:`~.gestation.fitted_starts`); ``"top-level-shifted"`` needs Fourier heads.
        value_start: how ``Q(s, o)`` starts when the option joins
            (:data:`~.gestation.VALUE_STARTS`): ``"max-sample"`` (the paper: the best value
            sampled when its target fired in gestation, everywhere) or ``"agent"`` (the agent's
            own ``max_a Q(s, a)`` fitted in its basis, plus ``value_bonus``; an MLP top level
            fits it in its last layer). Needs ``top_basis``.
        value_bonus: added to ``Q(s, o)`` everywhere under ``value_start="agent"``.
        top_basis: the agent's top-level features (a :class:`~skillchain_torch.features.
            FourierBasis`, or ``nn.Identity()`` under an MLP top level).
        chaining: a learned initiation set becomes a target event (section 4.3: the chain
            grows backwards from the goal). ``False``: the controls of :mod:`.subgoals`; only
            base events are targets, and base event n >= 1 is listed once the agent has n
            learned sets (where chaining would have added its n-th target).
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
        completion_reward: float = 10_000.0,
        chaining: bool = True,
    ):
        if value_start not in VALUE_STARTS:
            raise ValueError(f"value_start must be one of {', '.join(VALUE_STARTS)}, "
                             f"got {value_start!r}")  # fmt: skip
        if value_start == "agent" and top_basis is None:
            raise ValueError("value_start 'agent' needs the agent's top-level features "
                             "(top_basis)")  # fmt: skip
        self.value_start, self.value_bonus = value_start, float(value_bonus)
        self._value_fit = None
        if policy_start not in POLICY_STARTS:
            raise ValueError(f"policy_start must be one of {', '.join(POLICY_STARTS)}, "
                             f"got {policy_start!r}")  # fmt: skip
        fourier_options = getattr(bank.q_head, "basis", None) is not None
        if policy_start != "zero" and (top_basis is None or not (
                fourier_options or hasattr(bank.q_head, "fit_values"))):  # fmt: skip
            raise ValueError(f"policy_start {policy_start!r} needs the agent's top-level "
                             "features (top_basis) and an option head that can take the "
                             "agent's values (FourierOptionQHead, or one with fit_values such "
                             "as MLPOptionQHead): use policy_start='zero' (--policy-start zero) "
                             "with any other head")  # fmt: skip
        if policy_start == "top-level-shifted" and not (
                fourier_options and isinstance(top_basis, FourierBasis)):  # fmt: skip
            raise ValueError("policy_start 'top-level-shifted' needs Fourier heads (its shift "
                             "reads the linear values): use policy_start='top-level'")
        self.policy_start, self.top_basis = policy_start, top_basis
        self._grid: Tensor | None = None  # the neural starts' fit states (fit_grid), once
        self.completion_reward = float(completion_reward)
        self._projection: Tensor | None = None
        if gestation < 0 or max_branching < 0 or max_option_steps < 1:
            raise ValueError("need gestation >= 0, max_branching >= 0, max_option_steps >= 1")
        self.bank, self.chaining = bank, bool(chaining)
        if isinstance(bank.classifier, InitiationClassifier):  # discovery fits every set it
            check_fittable(bank.classifier)  # learns: refuse one that cannot, before the run
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
        self.trace = self.trace_class(P, self.max_option_steps, bank.q_head, device=device)
        self.episode = torch.zeros(P, dtype=torch.int64, device=device)  # 0-based, running
        self.base_now = torch.zeros(P, E, dtype=torch.bool, device=device)  # events at s
        # The classifiers' own sets at s, and at the state last evaluated (membership).
        self.raw_now = torch.zeros(P, K, dtype=torch.bool, device=device)
        self.last_raw = self.raw_now
        self.gestation_q = torch.full((P, K), -torch.inf, dtype=torch.float64, device=device)
        self.fitted = torch.zeros(P, K, dtype=torch.bool, device=device)  # this episode
        self.episode_weights = bank.classifier.snapshot()  # at each agent's episode start
        self.slots_full_logged = torch.zeros(P, dtype=torch.bool, device=device)
        # How executions ended, per agent-episode and slot (read by the trainer's monitors)
        self.counts = ExecutionCounts(P, K, device=device)
        self.log: list[DiscoveryEvent] = []
        # The states each agent acted in this episode, for gestation positives (if any).
        n = reading.gestation_positives
        self.recent = (self.recent_class(P, n, device=device, obs_dim=bank.obs_dim)
                       if n > 0 else None)  # fmt: skip
        self._exclusion: Tensor | None = None

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
        return self.exclude_overlap(contains, self._exclusion, self.bank.classifier.trained)

    def start_episodes(self, obs: Tensor, rows: Tensor) -> None:
        """Agents ``rows [P]`` start an episode at ``obs [P, 4]``."""
        fired = evaluate_base_events(self.events, obs, torch.zeros_like(rows))
        self.base_now = torch.where(rows[:, None], fired, self.base_now)
        self.raw_now = torch.where(rows[:, None], self.last_raw, self.raw_now)
        if self.recent is not None:
            self.recent.start_episodes(rows)

    # ------------------------------------------------------------------ per step
    def start_executions(self, rows: Tensor, slot: Tensor) -> None:
        """Agents ``rows [P]`` start executing ``slot [P]`` (after this step's updates)."""
        self.trace.start(rows, slot)  # (nothing when no row starts)

    def after_transition(self, *, obs: Tensor, executing: Tensor, contains: Tensor,
                         option: Tensor, value: Tensor, step: Tensor, events: Tensor,
                         reached: Tensor, duration: Tensor, decision_ended: Tensor,
                         terminated: Tensor, stepped: Tensor, starts: Tensor | None = None,
                         option_next: Tensor | None = None) -> Tensor:  # fmt: skip
        """Discovery's record of the transitions ``s -> s'`` of the rows in ``stepped [P]``,
        and its rules applied to them: one call per step, after the agent's updates.

        Args:
            obs, executing, contains, option, value, step: at ``s``: the state ``[P, 4]``, the
                agents executing an option (``[P]``, within ``stepped``), memberships
                ``[P, K]``, the executing slot (-1 none), the top-level ``Q(s, d) [P]`` of the
                decision d in force, and the execution's step count there.
            events, reached: at ``s'``: the base events ``[P, E]`` and each option's target
                ``[P, K]`` (in the classifiers' own sets).
            duration, decision_ended: the decision's steps, this one included, and whether it
                ended now.
            terminated: the episode terminated at ``s'`` ``[P]``.
            starts, option_next: the agents that took an option as their new decision at
                ``s'`` (``None``: none) and the slot each executes from there.

        In order: the record (the state, kept for a reading's gestation positives, and each
        executing agent's state as a step of its execution, its examples); the executions that
        ended (examples, refits, dropped updates); the gestation samples and the triggered
        creations; the executions that start. Target events are entered and reached in the
        classifiers' own sets (:attr:`raw_now` at ``s``, :attr:`last_raw` at ``s'``);
        ``contains`` (effective) decides coverage.

        Returns:
            ``BoolTensor [P]``: agents that created an option (their memberships at ``s'``
            must be re-evaluated by the caller: the new slot changed them, and
            :meth:`created_rows_evaluated` then takes their own sets).
        """
        if self.recent is not None:
            self.recent.record(stepped, obs)
        self.trace.record(executing, step, obs)  # (rows outside executing are skipped)
        raw_now, raw_next = self.raw_now, self.last_raw
        self.raw_now = torch.where(stepped[:, None], raw_next, raw_now)
        self._finish_executions(option, reached, duration, decision_ended & stepped,
                                terminated)  # fmt: skip
        sample = value.detach()  # Q(s, d) of the decision in force (a value, no graph)
        created = self._triggers(contains, option, sample, reached, stepped, raw_now, raw_next,
                                 events)  # fmt: skip
        if starts is not None and bool(starts.any()):  # (their slots existed before creation)
            self.trace.start(starts, option_next)
        return created

    def _triggers(self, contains: Tensor, option: Tensor, sample: Tensor, reached: Tensor,
                  stepped: Tensor, raw_now: Tensor, raw_next: Tensor,
                  events: Tensor) -> Tensor:  # fmt: skip
        """Gestation samples and positives, the target events this transition entered, and
        the creations they trigger (:meth:`after_transition`); the agents that created."""
        bank = self.bank
        if self.recent is not None:  # before base_now moves on to s'
            self._gestation_positives(self._gestation_hits(raw_now, reached, stepped))
        gestating = bank.status == OptionStatus.GESTATING
        if bool(gestating.any()):
            before = self.target_indicator(bank, self.base_now, raw_now)
            fired = entered(before, reached) & gestating & stepped[:, None]
            self.gestation_q = torch.where(fired, torch.maximum(self.gestation_q, sample[:, None]),
                                           self.gestation_q)  # fmt: skip
        base_trig = entered(self.base_now, events) & stepped[:, None]
        slot_trig = entered(raw_now, raw_next) & stepped[:, None]
        slot_trig = slot_trig & (bank.status == OptionStatus.LEARNED)
        self.base_now = torch.where(stepped[:, None], events, self.base_now)
        created = torch.zeros_like(stepped)
        if bool(base_trig.any()) or bool(slot_trig.any()):
            created = self._create(base_trig, slot_trig, contains, option, sample)
        return created

    def created_rows_evaluated(self, created: Tensor) -> None:
        """The caller re-evaluated the memberships at ``s'`` of the agents in ``created [P]``
        (:meth:`membership`): keep those rows' own sets as the current ones."""
        self.raw_now = torch.where(created[:, None], self.last_raw, self.raw_now)

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
        state["counts"] = self.counts.state_dict()
        if self.recent is not None:
            state["recent"] = self.recent.state_dict()
        return state

    def load_state_dict(self, state: dict) -> None:
        device = self.episode.device
        for name in self._STATE:
            setattr(self, name, state[name].to(device).clone())
        self.convergence.load_state_dict(state["convergence"])
        self.trace.load_state_dict(state["trace"])
        if "counts" in state:  # (saved before the counts were kept: they start at 0)
            self.counts.load_state_dict(state["counts"])
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
                f"reading={self.reading.name}, policy_start={self.policy_start!r}"
                + ("" if self.chaining else ", chaining=False") + ")")

    # ------------------------------------------------------------------ per-step rules
    def _gestation_hits(self, raw_now: Tensor, reached: Tensor, stepped: Tensor) -> Tensor:
        """``[P, K]``: gestating options whose target was entered by this transition."""
        gestating = self.bank.status == OptionStatus.GESTATING
        hit = reached & gestating
        if not bool(hit.any()):  # the usual step: no target of a gestating option at s'
            return hit
        before = self.target_indicator(self.bank, self.base_now, raw_now)
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
        outcomes = self._outcomes(option, reached, duration, ended, terminated)
        if outcomes is None:
            return
        slot, success, failure, any_failure = outcomes
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

    def _outcomes(self, option: Tensor, reached: Tensor, duration: Tensor, ended: Tensor,
                  terminated: Tensor) -> tuple[Tensor, Tensor, Tensor, bool] | None:  # fmt: skip
        """``(slot, success, failure [P], any failure)`` of the executions that ended, or
        ``None`` where none did (:func:`execution_outcome`)."""
        ended = ended & (option >= 0)
        if not bool(ended.any()):
            return None
        slot = option.clamp(min=0)
        hit = reached.gather(1, slot[:, None])[:, 0]
        success, failure = execution_outcome(hit, duration, terminated, self.max_option_steps)
        success, failure = success & ended, failure & ended
        return slot, success, failure, bool(failure.any())

    def _create(self, base_trig: Tensor, slot_trig: Tensor, contains: Tensor, option: Tensor,
                sample: Tensor) -> Tensor:  # fmt: skip
        bank = self.bank
        base_on, slot_on = self.event_list(bank, len(self.events), self.max_branching)
        # An agent whose slots are full creates nothing; once its first blocked creation is
        # logged its triggers need no more work. (Late in a run every agent is full, and some
        # agent enters a learned option's set at nearly every step.)
        full = bank.full()
        open_ = (~(full & self.slots_full_logged))[:, None]
        base_trig, slot_trig = base_trig & base_on & open_, slot_trig & slot_on & open_
        if not self.chaining:  # the controls of .subgoals: base events in place of the chain
            # Where chaining would add a learned set as a target, base event n (n >= 1) is
            # listed once the agent has n learned sets: the same moments, another target.
            learned = (bank.status == OptionStatus.LEARNED).sum(1, keepdim=True)
            base_trig = base_trig & (torch.arange(base_trig.shape[1],
                                                  device=learned.device) <= learned)
            slot_trig = torch.zeros_like(slot_trig)
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

    # ------------------------------------------------------------------ episode-end rules
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
            linear = type(q_head) is LinearQHead and isinstance(self.top_basis, FourierBasis)
            fourier_options = linear and getattr(bank.q_head, "basis", None) is not None
            if self.value_start == "agent" and linear:
                self._agent_values(q_head, join)
            if self.policy_start != "zero" and fourier_options:  # the top level's values
                if self._projection is None:  # once per run: a fixed grid, no random numbers
                    self._projection = cached_projection(self.top_basis, bank.q_head.basis)
                initialise_option_policies(bank.q_head, q_head, join, self._projection,
                                           bank.num_actions)  # fmt: skip
            neural_value = self.value_start == "agent" and not linear
            neural_policy = self.policy_start != "zero" and not fourier_options
            if neural_value or neural_policy:  # the same starts, fitted in the heads' last layers
                if self._grid is None:  # once per run: a fixed grid, no random numbers
                    self._grid = fit_grid(bank.obs_dim, device=bank.status.device)
                fitted_starts(join, q_head, bank.q_head, self.top_basis, self._grid,
                              q_head.num_decisions - bank.slots,
                              self.value_bonus if neural_value else None, neural_policy)
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


# ----------------------------------------------------------------------------------------------
# Target events (sections 4.2-4.4)
# ----------------------------------------------------------------------------------------------
#
# An agent's target events are the *base* events, shared by all agents and indexed ``0..E-1``
# (the end-of-episode goal first, then any indicator the user adds, e.g. a novelty event), and
# the initiation sets of its LEARNED options (slot ``j``: the chaining step). An event leaves the
# list once ``max_branching`` options target it (section 4.3); a learned set joins it.
#
# Which option targets what is read from the :class:`~skillchain_torch.options.OptionBank`:
# slot ``k`` with ``parent[k] = j >= 0`` targets slot j's initiation set; with ``parent[k] < 0``
# it targets base event ``target_event[k]``. Everything here is a pure function of the bank's
# ``[P, K]`` metadata and elementwise, so agent p's answers never depend on the other agents.


def targeting(bank: OptionBank, num_base: int) -> tuple[Tensor, Tensor]:
    """Which live option targets which event.

    Returns:
        ``base [P, K, E]``: slot k targets base event e; ``slot [P, K, K]``: slot k targets
        slot j's initiation set (``[p, k, j]``, i.e. j is k's parent in the skill tree).

    Example:
        >>> import torch
        >>> from skillchain_torch.options import OptionBank, OptionStatus
        >>> bank = OptionBank.build(population=1, slots=4, order=1, capacity=8)
        >>> _ = bank.allocate(torch.tensor([True]), target_event=0)      # slot 0 -> goal
        >>> _ = bank.allocate(torch.tensor([True]), parent=0)            # slot 1 -> I(slot 0)
        >>> base, slot = targeting(bank, num_base=1)
        >>> base.sum(1).tolist(), slot.sum(1).tolist()                   # options per event
        ([[1]], [[1, 0, 0, 0]])
        >>> bank.set_status(torch.tensor([[True, False, False, False]]), OptionStatus.LEARNED)
        >>> [t.tolist() for t in event_list(bank, num_base=1)]           # goal, I(slot 0) listed
        [[[True]], [[True, False, False, False]]]
    """
    live = bank.live()
    chained = bank.parent >= 0
    events = torch.arange(num_base, device=live.device)
    base = (live & ~chained)[..., None] & (bank.target_event[..., None] == events)
    slots = torch.arange(bank.slots, device=live.device)
    slot = (live & chained)[..., None] & (bank.parent[..., None] == slots)
    return base, slot


def event_list(bank: OptionBank, num_base: int,
               max_branching: int = MAX_BRANCHING) -> tuple[Tensor, Tensor]:  # fmt: skip
    """The target events on each agent's list: ``(base [P, E], slot [P, K])``.

    A base event is listed until ``max_branching`` options target it; slot j's initiation set
    is listed once the option is LEARNED, until ``max_branching`` options target it.
    """
    base, slot = targeting(bank, num_base)
    base_on = base.sum(1) < max_branching
    slot_on = (bank.status == OptionStatus.LEARNED) & (slot.sum(1) < max_branching)
    return base_on, slot_on


def entered(before: Tensor, after: Tensor) -> Tensor:
    """An event is *triggered* by a transition that enters it: false at ``s``, true at ``s'``.

    For the goal (only ever true at the last state) this is the event itself; for an
    initiation set it is the first step inside it, not every step spent there.
    """
    return after & ~before


# ----------------------------------------------------------------------------------------------
# Creation (sections 4.1, 4.3): a triggered target event spawns an option, unless covered
# ----------------------------------------------------------------------------------------------
#
# When a transition ``s -> s'`` triggers (enters) a target event on the agent's list, the agent
# creates an option whose termination condition is that event, *unless* ``s`` already lies in
# the initiation set of an option targeting that event (the covered-start exception). An
# executing option that reaches its own target does not count as uncovered either: it was
# started inside its initiation set, and reaching the target is its success, not a new event.
#
# At most one option is created per agent and step; when several listed events fire at once
# the first base event wins (the goal before user events), then the lowest slot.


def covered_start(bank: OptionBank, num_base: int, contains: Tensor,
                  executing: Tensor) -> tuple[Tensor, Tensor]:  # fmt: skip
    """Events whose trigger at this transition is *covered*: ``(base [P, E], slot [P, K])``.

    Args:
        bank: the options (their targets).
        num_base: E, the number of base events.
        contains: ``[P, K]`` initiation-set membership of ``s``, the state the trigger came
            from (computed for action selection at ``s``: no classifier runs again).
        executing: ``LongTensor [P]`` the option executing during the transition, -1 none.
    """
    base, slot = targeting(bank, num_base)  # [P, K, E], [P, K, K]
    base_cov = (base & contains[..., None]).any(1)
    slot_cov = (slot & contains[..., None]).any(1)
    # The executing option's own target: its start state was in its initiation set.
    agents = torch.arange(bank.population, device=contains.device)
    running = (executing >= 0)[:, None]
    k = executing.clamp(min=0)
    base_cov = base_cov | (running & base[agents, k])
    slot_cov = slot_cov | (running & slot[agents, k])
    return base_cov, slot_cov


def choose_creation(base_trig: Tensor, slot_trig: Tensor, base_cov: Tensor,
                    slot_cov: Tensor) -> tuple[Tensor, Tensor, Tensor]:  # fmt: skip
    """Which agents create an option now, and what it targets.

    Args:
        base_trig, slot_trig: ``[P, E]`` / ``[P, K]`` listed events triggered by this
            transition (on the list *and* entered).
        base_cov, slot_cov: the covered events of :func:`covered_start`.

    Returns:
        ``(create [P], target_event [P], parent [P])``: the new option targets base event
        ``target_event`` (``parent = -1``) or slot ``parent``'s initiation set
        (``target_event = -1``).

    Example:
        >>> import torch
        >>> base_trig = torch.tensor([[True], [True], [False]])   # the goal fired for 0 and 1
        >>> slot_trig = torch.zeros(3, 2, dtype=torch.bool)
        >>> covered = (torch.tensor([[False], [True], [False]]),
        ...            torch.zeros(3, 2, dtype=torch.bool))
        >>> create, event, parent = choose_creation(base_trig, slot_trig, *covered)
        >>> create.tolist(), event.tolist(), parent.tolist()
        ([True, False, False], [0, -1, -1], [-1, -1, -1])
    """
    candidates = torch.cat([base_trig & ~base_cov, slot_trig & ~slot_cov], dim=-1)
    create = candidates.any(-1)
    first = candidates.to(torch.int64).argmax(-1)
    num_base = base_trig.shape[1]
    none = torch.full_like(first, -1)
    target_event = torch.where(create & (first < num_base), first, none)
    parent = torch.where(create & (first >= num_base), first - num_base, none)
    return create, target_event, parent


# ----------------------------------------------------------------------------------------------
# No overlap (section 4.3)
# ----------------------------------------------------------------------------------------------
#
# "We require that the initiation set of an option does not overlap that of its siblings or
# parents." Applied where membership is decided, from the classifier outputs already computed for
# action selection (the paper's remark: at most one run of each classifier per visited state):
# option k's effective initiation set is its classifier's set minus the sets of
#
# * its parent, the option whose initiation set k targets, and
# * its *older* siblings, the options created earlier to target the same event.
#
# Older siblings keep what they hold and a younger one gets the rest, so two siblings never
# exclude each other's shared region from both. Only trained classifiers exclude: an untrained
# one is "true everywhere" and would empty its relatives. In discovery slots fill in order and
# are never freed, so the lower slot of two siblings is the older.


def overlap_exclusion(bank: OptionBank) -> Tensor:
    """``BoolTensor [P, K, K]``: ``[p, k, j]`` when option k must stay out of j's set
    (j is k's parent, or an older sibling: same target, lower slot)."""
    live = bank.live()
    K = bank.slots
    slots = torch.arange(K, device=live.device)
    parent = bank.parent[..., None] == slots  # [P, K, K]: j is k's parent
    chained = bank.parent >= 0
    same_parent = chained[..., None] & (bank.parent[..., None] == bank.parent[:, None, :])
    same_event = (~chained & (bank.target_event >= 0))[..., None] & (~chained)[:, None, :] & (
        bank.target_event[..., None] == bank.target_event[:, None, :]
    )
    older = slots[None, :] < slots[:, None]  # [k, j]: j < k
    sibling = (same_parent | same_event) & older
    both_live = live[..., None] & live[:, None, :]
    return (parent | sibling) & both_live


def exclude_overlap(contains: Tensor, exclusion: Tensor, trained: Tensor) -> Tensor:
    """The effective memberships ``[P, K]``: ``contains`` minus the trained sets each option
    must avoid (``exclusion`` from :func:`overlap_exclusion`).

    Example:
        >>> import torch
        >>> from skillchain_torch.options import OptionBank
        >>> bank = OptionBank.build(population=1, slots=3, order=1, capacity=8)
        >>> for _ in range(2):
        ...     _ = bank.allocate(torch.tensor([True]), target_event=0)   # two goal options
        >>> bank.classifier.trained[:] = True
        >>> raw = torch.tensor([[True, True, True]])
        >>> exclude_overlap(raw, overlap_exclusion(bank), bank.classifier.trained).tolist()
        [[True, False, True]]
    """
    blocking = contains & trained  # [P, J]
    excluded = (exclusion & blocking[:, None, :]).any(-1)
    return contains & ~excluded


# ----------------------------------------------------------------------------------------------
# Executions (sections 4.1, 5.1): initiation-set examples, dropped updates of failures
# ----------------------------------------------------------------------------------------------
#
# "When the agent executed the option, states on trajectories that reached its goal within 250
# steps were used as positive examples, and the start states of trajectories that did not were
# used as negative examples." And: "updates from unsuccessful on-policy trajectories" were
# ignored, "because their start states were then removed from the initiation set".
#
# :class:`ExecutionTrace` follows the execution in progress of every agent: the states it acted
# in (at most ``max_steps``) and a copy of the option's Q-head slot taken when it started. When
# the execution ends:
#
# * *success*, the option's target event fired at ``s'``: every state it acted in is a
#   positive example;
# * *failure*, it ran ``max_steps`` steps, or the episode terminated elsewhere than at its
#   target: its start state is a negative example, and the option's Q-head slot is put back as
#   it was at the start, dropping the updates of the failed trajectory;
# * neither, when an episode *truncation* (a step limit of the environment, not of the option)
#   cut it short: it was not given its 250 steps, so it teaches nothing either way.



def execution_outcome(reached: Tensor, duration: Tensor, terminated: Tensor,
                      max_steps: int) -> tuple[Tensor, Tensor]:  # fmt: skip
    """``(success, failure)`` of executions that just ended (all ``[P]``).

    Args:
        reached: the executing option's target fired at ``s'``.
        duration: steps the execution ran, this one included.
        terminated: the episode terminated at ``s'``.
        max_steps: the option's step limit (paper: 250).

    Example:
        >>> import torch
        >>> success, failure = execution_outcome(
        ...     reached=torch.tensor([True, False, False, False]),
        ...     duration=torch.tensor([3, 250, 7, 7]),
        ...     terminated=torch.tensor([False, False, True, False]), max_steps=250)
        >>> success.tolist(), failure.tolist()     # target, timeout, episode over, truncated
        ([True, False, False, False], [False, True, True, False])
    """
    success = reached
    failure = ~reached & ((duration >= max_steps) | terminated)
    return success, failure


class ExecutionTrace:
    """The states of every agent's execution in progress, and its option's starting weights.

    Args:
        population: P; max_steps: the longest execution (paper: 250).
        q_head: the options' :class:`~skillchain_torch.options.OptionQHead` (for the snapshot).

    State (:meth:`state_dict`): ``states [P, max_steps, D]`` and ``snapshot`` (the Q-head
    slot of the executing option at its start, per agent).
    """

    def __init__(self, population: int, max_steps: int, q_head: OptionQHead,
                 dtype=torch.float64, device=None):  # fmt: skip
        self.max_steps = int(max_steps)
        self.q_head = q_head
        self.states = torch.zeros(population, self.max_steps, q_head.obs_dim, dtype=dtype,
                                  device=device)  # fmt: skip
        slot = torch.zeros(population, dtype=torch.int64, device=device)
        self.snapshot = q_head.read_slots(slot)
        self._agents = torch.arange(population, device=device)

    def start(self, rows: Tensor, slot: Tensor) -> None:
        """Agents in ``rows [P]`` start executing option ``slot [P]``: keep its weights."""
        tensors = self.q_head.slot_tensors()
        index = rows.nonzero()[:, 0]
        if index.numel() == 0:
            return
        # Copy just the starting agents' slots (a few rows of [P, ...] weights).
        k = slot[index].clamp(min=0)
        for name, value in tensors.items():
            self.snapshot[name][index] = value[index, k].to(self.snapshot[name].dtype)

    def record(self, rows: Tensor, step: Tensor, obs: Tensor) -> None:
        """Agents in ``rows [P]`` act in ``obs [P, 4]`` as step ``step [P]`` (0-based)."""
        index = rows.nonzero()[:, 0]
        self.states[index, step[index].clamp(max=self.max_steps - 1)] = obs[index].to(
            self.states.dtype)

    def examples(self, slot: Tensor, duration: Tensor, success: Tensor,
                 failure: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:  # fmt: skip
        """Initiation-set examples of ended executions, in agent order.

        Returns ``(agents [N], slots [N], obs [N, 4], labels [N])``: the ``duration`` states
        of each successful execution (positive), the start state of each failed one (negative).
        """
        steps = torch.arange(self.max_steps, device=slot.device)
        positive = success[:, None] & (steps < duration[:, None])
        negative = failure[:, None] & (steps == 0)
        take = positive | negative  # [P, T]
        agents, step = take.nonzero().unbind(-1)
        return agents, slot[agents], self.states[agents, step], positive[agents, step]

    def store_examples(self, classifier: InitiationClassifier, slot: Tensor, duration: Tensor,
                       success: Tensor, failure: Tensor) -> Tensor:  # fmt: skip
        """Add the :meth:`examples` of ended executions to ``classifier`` (slot ``slot [P]``
        of each agent); the ``[P, K]`` mask of slots that received data."""
        agents, slots, obs, labels = self.examples(slot, duration, success, failure)
        if agents.numel() == 0:  # (trained: the [P, K] mask every InitiationSet declares)
            return torch.zeros_like(classifier.trained)
        return classifier.add_examples(agents, slots, obs, labels)

    def drop_updates(self, slot: Tensor, failure: Tensor) -> None:
        """Put the options of failed executions back as they were when they started."""
        self.q_head.write_slots(slot, self.snapshot, failure)

    def state_dict(self) -> dict:
        return {"states": self.states.clone(),
                "snapshot": {k: v.clone() for k, v in self.snapshot.items()}}

    def load_state_dict(self, state: dict) -> None:
        device = self.states.device
        self.states = state["states"].to(device).clone()
        self.snapshot = {k: v.to(device).clone() for k, v in state["snapshot"].items()}


class ExecutionCounts:
    """How each agent's option executions ended this episode, per slot: ``outcomes [P, K, 3]``
    (:data:`OUTCOMES`) and ``steps [P, K]`` (their durations). At an agent's episode end they
    become its ``last_outcomes`` / ``last_steps`` (what the trainer's monitors read) and start
    again. Kept by discovery, where executions end anyway, so monitoring needs no per-step work.

    Example:
        >>> counts = ExecutionCounts(population=2, slots=2)
        >>> counts.add(torch.tensor([True, False]), torch.tensor([1, 0]),
        ...            torch.tensor([True, False]), torch.tensor([False, False]),
        ...            torch.tensor([False, False]), torch.tensor([12, 3]))
        >>> counts.end_episodes(torch.tensor([True, True]))
        >>> counts.last_outcomes[0, 1].tolist(), counts.last_steps.tolist()
        ([1, 0, 0], [[0, 12], [0, 0]])
        >>> int(counts.steps.sum())  # the new episodes' counts start at 0
        0
    """

    def __init__(self, population: int, slots: int, device=None):
        i64 = dict(dtype=torch.int64, device=device)
        self.outcomes = torch.zeros(population, slots, len(OUTCOMES), **i64)
        self.steps = torch.zeros(population, slots, **i64)
        self.last_outcomes, self.last_steps = self.outcomes.clone(), self.steps.clone()

    def add(self, done: Tensor, slot: Tensor, success: Tensor, timeout: Tensor,
            episode_end: Tensor, duration: Tensor) -> None:  # fmt: skip
        """Rows ``done [P]`` ended an execution of ``slot [P]`` after ``duration [P]`` steps,
        with the outcome flags given (all ``[P]``; none set: a truncated episode)."""
        rows = done.nonzero()[:, 0]
        if rows.numel() == 0:
            return
        k = slot[rows]
        kinds = torch.stack([success, timeout, episode_end], 1)[rows].to(torch.int64)
        self.outcomes[rows, k] += kinds
        self.steps[rows, k] += duration[rows].to(torch.int64)

    def end_episodes(self, rows: Tensor) -> None:
        """Agents ``rows [P]`` ended an episode: their counts become the last episode's."""
        keep = rows[:, None]
        self.last_steps = torch.where(keep, self.steps, self.last_steps)
        self.last_outcomes = torch.where(keep[..., None], self.outcomes, self.last_outcomes)
        self.steps = torch.where(keep, torch.zeros_like(self.steps), self.steps)
        self.outcomes = torch.where(keep[..., None], torch.zeros_like(self.outcomes),
                                    self.outcomes)  # fmt: skip

    _STATE = ("outcomes", "steps", "last_outcomes", "last_steps")

    def state_dict(self) -> dict:
        return {name: getattr(self, name).clone() for name in self._STATE}

    def load_state_dict(self, state: dict) -> None:
        device = self.steps.device
        for name in self._STATE:
            setattr(self, name, state[name].to(device).clone())


# ----------------------------------------------------------------------------------------------
# Gestation positives: the states each agent acted in this episode
# ----------------------------------------------------------------------------------------------


class RecentStates:
    """The last ``length`` states of every agent's current episode, for gestation positives.

    Deep skill chaining (Bagaria & Konidaris) makes a new option's initiation set local from
    the start: during gestation, each time the option's target fires, the states that led to it
    become positive examples. :meth:`record` keeps a ring of the states each agent acted in
    this episode; :meth:`window` reads the last ``n`` of them, oldest first.

    Example:
        >>> import torch
        >>> recent = RecentStates(population=2, length=3)
        >>> for t in range(4):
        ...     recent.record(torch.tensor([True, t < 1]), torch.full((2, 4), float(t)))
        >>> agents, obs = recent.window(torch.tensor([True, True]), 3)
        >>> agents.tolist(), obs[:, 0].tolist()           # agent 0: t = 1..3; agent 1: t = 0
        ([0, 0, 0, 1], [1.0, 2.0, 3.0, 0.0])
    """

    def __init__(self, population: int, length: int, dtype=torch.float64, device=None,
                 obs_dim: int = 4):  # fmt: skip
        if length < 1:
            raise ValueError(f"RecentStates needs length >= 1, got {length}")
        self.length = int(length)
        self.states = torch.zeros(population, self.length, obs_dim, dtype=dtype, device=device)
        self.steps = torch.zeros(population, dtype=torch.int64, device=device)  # this episode

    def record(self, rows: Tensor, obs: Tensor) -> None:
        """Agents in ``rows [P]`` act in ``obs [P, 4]`` (the state a transition starts from)."""
        index = rows.nonzero()[:, 0]
        if index.numel() == 0:
            return
        self.states[index, self.steps[index] % self.length] = obs[index].to(self.states.dtype)
        self.steps[index] += 1

    def start_episodes(self, rows: Tensor) -> None:
        """Agents in ``rows [P]`` start an episode: their earlier states no longer count."""
        self.steps = torch.where(rows, torch.zeros_like(self.steps), self.steps)

    def window(self, rows: Tensor, n: int) -> tuple[Tensor, Tensor]:
        """``(agents [M], obs [M, 4])``: the last ``min(n, length, steps)`` states of each agent
        in ``rows [P]``, oldest first, agents in ascending order."""
        n = min(int(n), self.length)
        index = rows.nonzero()[:, 0]
        taken = self.steps[index].clamp(max=n)  # [A]
        back = torch.arange(n, 0, -1, device=self.steps.device)  # n .. 1 steps back
        keep = back[None, :] <= taken[:, None]  # [A, n]
        place = (self.steps[index, None] - back[None, :]) % self.length
        agent = index[:, None].expand(-1, n)
        return agent[keep], self.states[agent[keep], place[keep]]

    def state_dict(self) -> dict:
        return {"states": self.states.clone(), "steps": self.steps.clone()}

    def load_state_dict(self, state: dict) -> None:
        device = self.steps.device
        self.states = state["states"].to(device).clone()
        self.steps = state["steps"].to(device).clone()



# The rules' bookkeeping, one implementation per class. These are the torch path's;
# skillchain_torch.backends.discovery.CompiledSkillChaining replaces them (the same bits), and
# the agent's one call to skillchain_torch.backends.select.discovery_rules picks the class.
SkillChaining.trace_class = ExecutionTrace
SkillChaining.recent_class = RecentStates
SkillChaining.target_indicator = staticmethod(target_indicator)
SkillChaining.event_list = staticmethod(event_list)
SkillChaining.exclude_overlap = staticmethod(exclude_overlap)
