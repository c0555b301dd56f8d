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

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from skillchain_torch.backends import discovery as backend
from skillchain_torch.options import (
    GoalEvent,
    InitiationClassifier,
    OptionBank,
    OptionStatus,
    TerminationPredicate,
)
from skillchain_torch.options.initiation_fit import check_fittable

from .convergence import CONVERGENCE_EPISODES, CONVERGENCE_THRESHOLD, ConvergenceTest
from .episode_rules import EpisodeRules
from .events import MAX_BRANCHING, entered, evaluate_base_events, target_indicator
from .executions import ExecutionCounts, ExecutionTrace
from .gestation import (
    GESTATION_EPISODES,
    POLICY_STARTS,
    VALUE_STARTS,
    RecentStates,
)
from .overlap import exclude_overlap, overlap_exclusion
from .readings import FIRST_READING, InitiationReading
from .step_rules import StepRules

__all__ = ["SkillChaining", "DiscoveryEvent"]

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


class SkillChaining(StepRules, EpisodeRules):
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
            worth ``completion_reward``, :mod:`~.value_scale`). Both need ``top_basis`` and a
            Fourier option head.
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
        completion_reward: float = 10_000.0,
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
        if policy_start != "zero" and (top_basis is None
                                       or getattr(bank.q_head, "basis", None) is None):
            raise ValueError(f"policy_start {policy_start!r} needs the agent's Fourier basis "
                             "(top_basis) and a Fourier option head (FourierOptionQHead)")
        self.policy_start, self.top_basis = policy_start, top_basis
        self.completion_reward = float(completion_reward)
        self._projection: Tensor | None = None
        if gestation < 0 or max_branching < 0 or max_option_steps < 1:
            raise ValueError("need gestation >= 0, max_branching >= 0, max_option_steps >= 1")
        self.bank = bank
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
        # How executions ended, per agent-episode and slot (read by the trainer's monitors)
        self.counts = ExecutionCounts(P, K, device=device)
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
        if backend.NATIVE and backend.applies(contains, stepped):  # the same rules, compiled
            self.gestation_q, base_trig, slot_trig, self.base_now, any_listed, hits = (
                backend.triggers(bank.parent, bank.target_event, bank.status,
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
                f"reading={self.reading.name}, policy_start={self.policy_start!r})")
