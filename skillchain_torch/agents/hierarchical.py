"""``HierarchicalAgent``: SMDP Sarsa over primitives and options, for a population of agents.

The agent of paper sections 2, 4 and 5.1 with a given set of options (no discovery here):

* **Top level.** Epsilon-greedy (``epsilon = 0.01``) over ``D = 5 + K`` decisions: the five
  primitive actions and every option slot ``k`` (decision ``5 + k``) that is executable and
  whose initiation set holds the state (:meth:`OptionBank.available`). Values are a
  :class:`~skillchain_torch.modules.LinearQHead` over a Fourier basis (order 4 on the simple
  maps, 5 on the hard ones), learned by SMDP Sarsa (:class:`~skillchain_torch.objectives.
  SarsaUpdate`): a decision taken in ``s`` that lasted ``k`` steps and earned
  ``R = sum_i gamma^i r_i`` is moved toward ``R + gamma^k Q(s', d')``, ``d'`` being the next
  top-level decision drawn at ``s'`` (no bootstrap when the episode terminated at ``s'``).
* **Options.** An executing option acts epsilon-greedily (``option_epsilon = 0.01``) by its own
  Q-head until its termination predicate fires at the new state, it has run
  ``max_option_steps = 250`` steps, or the episode ends. Every option's Q-head learns by
  intra-option Q-learning (:class:`~skillchain_torch.objectives.IntraOptionQLearning`) from
  *every* primitive transition whose start state lies in its initiation set, whoever acted.

Random numbers: each active agent draws 4 uniforms per step from its own
:class:`~skillchain_torch.rng.CounterRNG` stream (2 for the top level, 2 for the option's
action), and 4 more at a restart, whatever it decides; every operation is row-independent, so
agent ``p`` of a population is bit-identical to the same agent alone.

The per-step state (:class:`~.step_state.StepState`) is held for all P agents.

Two paths compute a step (``native``): the torch path below, and a compiled one
(:mod:`.compiled_step`, the default where every piece is the built-in one): the same decisions,
sums in an order of its own. The top level's rules: :mod:`.top_level`; the trainer's protocol:
:mod:`.episode_protocol`.

Example:
    >>> from skillchain_torch.options import OptionBank
    >>> bank = OptionBank.build(population=2, slots=3, order=1)
    >>> agent = HierarchicalAgent(bank, order=1, seed=0)
    >>> agent.q_head.weight.shape                 # [P, 5 + K, F]
    torch.Size([2, 8, 16])
    >>> obs = torch.tensor([[0.2, 0.9, 0.5, 0.5]] * 2, dtype=torch.float64)
    >>> agent.begin(obs).shape
    torch.Size([2])
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from skillchain_torch.agents.compiled_step import CompiledStep
from skillchain_torch.agents.episode_protocol import EpisodeProtocol
from skillchain_torch.agents.option_execution import (
    FAILURE_BOOTSTRAPS,
    INTRA_OPTION_TARGETS,
    OptionExecution,
)
from skillchain_torch.agents.step_state import STEP_FIELDS, StepState, StepStateFields
from skillchain_torch.agents.top_level import TopLevel, shared_fourier_columns
from skillchain_torch.backends import hierarchical as backend
from skillchain_torch.discovery.overlap import overlap_exclusion
from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.objectives import (
    IntraOptionQLearning,
    SarsaUpdate,
    SMDPSarsaLoss,
    discount,
    option_update_mask,
)
from skillchain_torch.options import (
    GoalEvent,
    InitiationClassifier,
    OptionBank,
    TerminationPredicate,
)
from skillchain_torch.rng import CounterRNG

__all__ = ["HierarchicalAgent", "shared_fourier_columns", "NUM_PRIMITIVES", "MAX_OPTION_STEPS",
           "UNIFORMS_PER_STEP", "FAILURE_BOOTSTRAPS", "INTRA_OPTION_TARGETS"]

NUM_PRIMITIVES = 5
OBS_DIM = 4
MAX_OPTION_STEPS = 250
UNIFORMS_PER_STEP = 4  # top-level (explore, pick), option (explore, pick)
AGENT_STREAM = 0


def as_bool(x: Tensor) -> Tensor:
    """``x`` as a BoolTensor, without a call when it is one already (``Tensor.to`` costs a
    few microseconds even then, and per-step flags pass through here)."""
    return x if x.dtype == torch.bool else x.to(torch.bool)


class HierarchicalAgent(TopLevel, OptionExecution, EpisodeProtocol, CompiledStep,
                        StepStateFields, nn.Module):
    """Population-batched SMDP Sarsa agent over primitive actions and the options of a bank.

    Args:
        bank: the agents' :class:`OptionBank` (P agents, K slots); its Q-heads keep learning.
        order: Fourier order of the top-level basis (paper: 4 simple maps, 5 hard maps).
        alpha: top-level step size (paper: 0.001 at order 4, 0.0005 at order 5).
        gamma: discount of both levels (paper: 1).
        epsilon: top-level exploration.
        seed: agent p uses seed ``seed + p`` (int), or a ``LongTensor [P]`` of seeds.
        events: the base target events indexed by ``bank.target_event`` (default: the goal).
        option_epsilon: exploration of an executing option (paper: 0.01).
        max_option_steps: an option is interrupted after this many steps (paper: 250).
        completion_reward: ``C`` of :class:`IntraOptionQLearning`.
        scale_step_size: per-feature top-level step sizes (Konidaris et al. 2011).
        overlap: apply skill chaining's no-overlap rule to memberships (an option stays out
            of its parent's and older siblings' sets), for options discovered under it; the
            bank's tree must not change afterwards (discovery itself uses ``SkillChaining``).
        failure_bootstrap: what the SMDP target of a *timed-out* execution bootstraps on:
            ``"decision"`` (Sarsa, the paper: ``Q(s', d')``) or ``"primitives"``
            (``max_a Q(s', a)``: under ``gamma = 1`` an optimistic option re-chosen at ``s'``
            loses only its own cost per timeout; this charges the failure against what the
            agent can do without options).
        intra_option_primitives: each step ``(s, a, r, s')`` inside an option also moves the
            top-level ``Q(s, a)`` toward ``r + gamma max_d Q(s', d)`` (intra-option value
            learning, Sutton, Precup & Singh 1999, section 7). Off (the paper's SMDP Sarsa).
        intra_option_target: what those steps bootstrap on: ``"decisions"`` (``max_d`` over
            every available decision, options included) or ``"primitives"`` (``max_a Q(s', a)``
            over the primitives only, so an option's optimistic value is never copied into
            the primitives' values along its route).
        interruption: an executing option stops at ``s'`` where ``Q(s', o) < max_d Q(s', d)``
            (Sutton, Precup & Singh 1999, section 5); neither a success nor a failure. Off
            (the paper: options run until their target fires or they time out).
        end_outside_set: an executing option also ends at an ``s'`` outside its own
            initiation set, where its policy need not be defined; neither a success nor a
            failure. ``"off"`` (the paper), ``"learned"`` (options whose sets are learned)
            or ``"always"``.
        q_head: the top-level value head (a :class:`~skillchain_torch.interfaces.ValueHead`
            over ``5 + K`` decisions, on ``features``); default the paper's
            :class:`~skillchain_torch.modules.LinearQHead`, stepped in closed form by
            :class:`~skillchain_torch.objectives.SarsaUpdate`. Any other head learns by
            :class:`~skillchain_torch.objectives.SMDPSarsaLoss` and ``optimizer``.
        features: the top level's features of the observation (default the paper's
            :class:`~skillchain_torch.features.FourierBasis` of ``order``); any module
            ``obs [P, 4] -> [P, F]``, e.g. ``nn.Identity()`` for a head on the raw observation.
        optimizer: for a head of the user's own: a ``torch.optim.Optimizer`` over its
            parameters (default SGD at ``alpha``).
        top_learner: for a head of the user's own, instead of one loss step per decision: a
            callable ``td [P] -> td_error [P]`` (e.g. :class:`~skillchain_torch.objectives.
            ReplayTD`), which also reads ``next_phi``, ``next_decision``, ``next_available``.
        device: torch device (default: the bank's).
        native: run the per-step arithmetic in C (:mod:`~skillchain_torch.backends.
            hierarchical`, :mod:`~skillchain_torch.backends.initiation`). Default: when built,
            on the CPU in float64 with the built-in pieces. Sums in an order of their own:
            equal to ``native=False`` to rounding (each reproducible and P-invariant).
    """

    def __init__(
        self,
        bank: OptionBank,
        order: int = 4,
        alpha: float = 0.001,
        gamma: float = 1.0,
        epsilon: float = 0.01,
        seed: int | Tensor = 0,
        events: Sequence[TerminationPredicate] = (GoalEvent(),),
        option_epsilon: float = 0.01,
        max_option_steps: int = MAX_OPTION_STEPS,
        completion_reward: float | Tensor = 10_000.0,
        scale_step_size: bool = False,
        overlap: bool = False,
        failure_bootstrap: str = "decision",
        intra_option_primitives: bool = False,
        intra_option_target: str = "decisions",
        interruption: bool = False,
        end_outside_set: str = "off",
        q_head: nn.Module | None = None,
        features: nn.Module | None = None,
        optimizer: torch.optim.Optimizer | None = None,
        top_learner=None,
        device: torch.device | str | None = None,
        native: bool | None = None,
    ):
        super().__init__()
        self._set_readings(failure_bootstrap, intra_option_primitives, intra_option_target,
                           interruption, end_outside_set)  # fmt: skip
        device = torch.device(bank.status.device if device is None else device)
        self.bank = bank.to(device)
        self.population, self.slots = bank.population, bank.slots
        # The environment's sizes, as the option bank was built for them (its specs).
        self.obs_dim, self.num_primitives = bank.obs_dim, bank.num_actions
        self.num_decisions = self.num_primitives + self.slots
        self.order = int(order)
        self.features = (FourierBasis(self.obs_dim, order) if features is None
                         else features).to(device)  # fmt: skip
        num_features = self.features(torch.zeros(self.population, self.obs_dim,
                                                 dtype=torch.float64, device=device)).shape[-1]
        self.q_head = (LinearQHead(num_features, self.num_decisions, self.population,
                                   device=device) if q_head is None else q_head.to(device))
        self.native = backend.resolve(
            native, option_head=self.bank.q_head, top_head=self.q_head,
            top_features=self.features, device=self.bank.status.device, obs_dim=self.obs_dim,
            num_primitives=NUM_PRIMITIVES, completion_reward=completion_reward)
        # Memberships and refits go with the step where the classifier is the built-in one;
        # a classifier of the user's own keeps its torch path under a compiled step (and
        # native=True asks it for C, which it refuses, naming itself).
        classifier = self.bank.classifier
        if type(classifier) is InitiationClassifier:
            classifier.set_native(self.native)
        elif hasattr(classifier, "set_native"):
            classifier.set_native(bool(native) and self.native)
        self._exclusion = overlap_exclusion(self.bank) if overlap else None
        self.epsilon, self.option_epsilon = float(epsilon), float(option_epsilon)
        self.gamma = float(gamma)
        self.max_option_steps = int(max_option_steps)
        self.events = tuple(events)
        columns = (shared_fourier_columns(self.features, self.bank.q_head)
                   if type(self.features) is FourierBasis else None)  # fmt: skip
        self.register_buffer("_code_columns", columns, persistent=False)
        scale = self.features.step_size_scale() if scale_step_size else None
        # The built-in linear head steps in closed form; any other head by its loss.
        self.update = SarsaUpdate(alpha, gamma, step_size_scale=scale).to(device)
        self.closed_form = type(self.q_head) is LinearQHead
        self.loss = None if self.closed_form else SMDPSarsaLoss(self.q_head, gamma)
        if not self.closed_form and optimizer is None:
            optimizer = torch.optim.SGD(self.q_head.parameters(), lr=alpha)
        self.optimizer, self.top_learner = optimizer, top_learner
        if top_learner is not None and (self.closed_form or intra_option_primitives):
            raise ValueError("top_learner needs a parametric head, no intra_option_primitives")
        self.option_update = IntraOptionQLearning(gamma, completion_reward)
        if isinstance(seed, Tensor):
            self.rng = CounterRNG(seed.to(device), stream=AGENT_STREAM)
        else:
            self.rng = CounterRNG.from_seed(int(seed), self.population, stream=AGENT_STREAM,
                                            device=device)
        P = self.population
        # Per-agent episode state (all P rows; only the active ones change), declared once
        # (StepState) and saved by ``state_dict`` explicitly; its fields read as attributes.
        zeros = torch.zeros(P, self.obs_dim, dtype=torch.float64, device=device)
        self.step_state = StepState.start(P, self.slots, self.obs_dim, num_features,
                                          option_code=bank.q_head.encode(zeros),
                                          state_phi=self.intra_option_primitives)
        self.active = torch.ones(P, dtype=torch.bool, device=device)
        self._index = torch.arange(P, device=device)

    def _apply(self, fn, *args, **kwargs):
        # Moved off the CPU or out of float64 (.to, .cuda, .float): C must not read the
        # weights any more (a device pointer would crash it); the torch path applies.
        out = super()._apply(fn, *args, **kwargs)
        weights = (self.q_head.weight, self.bank.q_head.weight) if self.native else ()
        if any(w.device.type != "cpu" or w.dtype != torch.float64 for w in weights):
            self.native = False
        return out

    # Per-step state is reassigned every step; nn.Module.__setattr__ (which looks for
    # parameters, buffers and submodules) costs more than the tensor maths for these.
    _PLAIN = frozenset({"step_state", "active", "last_q", "last_phi", "last_value", "_index",
                        "_raw_contains", "last_available"})
    _STEP = frozenset(STEP_FIELDS)  # written into the declared StepState
    # The compiled transition also returns Q(s', d) of the decision in force (last_value).
    WANTS_VALUE = False

    def __setattr__(self, name, value):
        if name in self._STEP:
            setattr(self.step_state, name, value)
        elif name in self._PLAIN:
            object.__setattr__(self, name, value)
        else:
            super().__setattr__(name, value)

    # ------------------------------------------------------------------ pieces
    def _start_decisions(self, obs: Tensor, rows: Tensor) -> None:
        """Rows ``rows [P]`` start an episode at ``obs [P, 4]`` (other rows of ``obs`` are
        ignored): fresh decision and action, 4 uniforms drawn.

        Episodes end a few agents at a time, so only those rows' features are computed (a
        row's features are its own: the same bits in any batch) and copied into
        ``option_code`` and ``decision_phi``; ``last_phi`` holds them, zeros elsewhere.
        """
        u = self.rng.uniform(UNIFORMS_PER_STEP, mask=rows)
        obs = torch.where(rows[:, None], obs, self.obs)
        contains = self.membership(obs)
        index = rows.nonzero()[:, 0]
        phi_rows, code_rows = self._encode(obs, index)
        phi = obs.new_zeros(self.population, phi_rows.shape[1])
        phi[index] = phi_rows
        phi, decision = self._choose(obs, phi, contains, u[:, :2], rows=rows)
        self.obs = obs
        self.option_code = self.option_code.index_copy(0, index, code_rows)
        if self.intra_option_primitives:
            self.state_phi = self.state_phi.index_copy(0, index, phi_rows)
        self.contains = torch.where(rows[:, None], contains, self.contains)
        self.own_contains = torch.where(rows[:, None], self._raw_contains, self.own_contains)
        self._new_decisions(rows, phi_rows, decision, index=index)
        self._act(rows, u[:, 2:])

    def _new_decisions(self, rows: Tensor, phi: Tensor, decision: Tensor,
                       index: Tensor | None = None) -> None:  # fmt: skip
        """Rows ``rows [P]`` take ``decision [P]`` with features ``phi [P, F]``, or with
        ``index`` (the rows' ids) ``phi [len(index), F]``."""
        self.decision = torch.where(rows, decision, self.decision)
        option = torch.where(decision >= self.num_primitives, decision - self.num_primitives,
                             torch.full_like(decision, -1))
        self.option = torch.where(rows, option, self.option)
        if index is None:
            self.decision_phi = torch.where(rows[:, None], phi, self.decision_phi)
        else:
            self.decision_phi = self.decision_phi.index_copy(0, index, phi)
        self.decision_return = torch.where(rows, torch.zeros_like(self.decision_return),
                                           self.decision_return)
        self.duration = torch.where(rows, torch.zeros_like(self.duration), self.duration)
        self._options_starting(rows & (decision >= self.num_primitives))

    def _options_starting(self, rows: Tensor) -> None:
        """Agents ``rows [P]`` just took an option as their new decision (a hook: skill
        chaining snapshots the option's weights once the step's updates are done)."""

    def transition(self, next_obs: Tensor, reward: Tensor, terminated: Tensor,
                   truncated: Tensor, stepped: Tensor) -> dict[str, Tensor]:
        """Learn from ``(s, a, r, s')`` for the rows in ``stepped [P]`` and pick their next
        actions (all arguments ``[P]`` / ``[P, 4]``; other rows are left untouched).

        Returns a dict of ``[P]`` tensors for monitoring: ``decision`` and ``option`` in force
        during this step, ``decision_ended`` (the SMDP update happened), the decision's
        ``duration`` k and ``decision_return`` R so far, ``smdp_delta`` (0 where no update),
        ``option_delta [P, K]`` (intra-option TD errors, 0 outside the initiation sets) and
        ``reached [P, K]`` (each option's target event at ``s'``).
        """
        # What a subclass or the user may change (memberships, targets) runs here, both paths.
        terminated, truncated = as_bool(terminated), as_bool(truncated)
        reward = reward if reward.dtype == torch.float64 else reward.to(torch.float64)
        if not self.all_stepped(stepped):  # (with every agent stepped the masks change nothing)
            terminated, truncated = terminated & stepped, truncated & stepped
            next_obs = torch.where(stepped[:, None], next_obs, self.obs)
        contains_next = self.membership(next_obs)
        reached = self.targets(next_obs, terminated, contains_next)
        u = self.rng.uniform(UNIFORMS_PER_STEP, mask=stepped)
        own_next = torch.where(stepped[:, None], self._raw_contains, self.own_contains)
        if self.native:  # the rest in one compiled pass, on the declared StepState
            info = self._compiled_transition(backend.AtNext(
                next_obs, reward, terminated, truncated, stepped, contains_next, reached, u,
                *self._encode_next(next_obs), own=own_next))
            self.own_contains = own_next
            return info
        bank = self.bank
        ended = terminated | truncated
        reward = torch.where(stepped, reward, torch.zeros_like(reward))
        # Intra-option Q-learning: the executing option, and those whose own sets hold s
        phi_next, next_code = self._encode(next_obs)
        learn = option_update_mask(self.own_contains, self.option, bank.live() & stepped[:, None])
        option_delta = self.option_update(
            bank.q_head, self.obs, self.action, reward, next_obs, terminated, learn, reached,
            code=self.option_code, next_code=next_code, stepped=stepped,
        )
        # The decision in force accumulates the (discounted) reward.
        if self.gamma == 1.0:  # gamma^k = 1 exactly: skip the power
            ret = self.decision_return + reward
        else:
            ret = self.decision_return + discount(self.gamma, self.duration) * reward
        self.decision_return = torch.where(stepped, ret, self.decision_return)
        self.duration = torch.where(stepped, self.duration + 1, self.duration)
        executing = self.option >= 0
        slot = self.option.clamp(min=0)
        hit = reached.gather(1, slot[:, None])[:, 0]  # the executing option's target at s'
        option_stops = executing & (hit | (self.duration >= self.max_option_steps))
        decision_ended = stepped & (~executing | option_stops | ended | self._leaves(own_next))
        # Next top-level decision at s' (also the bootstrap decision d'). With intra-option
        # primitives or interruption, the rows inside an option value s' too.
        inside = stepped & executing
        valued = decision_ended | inside if self.intra_option_primitives or self.interruption \
            else decision_ended  # fmt: skip
        phi_next, d_next = self._choose(next_obs, phi_next, contains_next, u[:, :2], rows=valued)
        if self.interruption:  # the option stops where it is no longer greedy
            decision_ended = decision_ended | self._interrupted(inside & ~decision_ended, phi_next)
        # Q(s', d') was valued when d' was chosen, with the same (not yet updated) weights.
        q_next = self.last_q.gather(1, d_next[:, None])[:, 0]
        if self.failure_bootstrap == "primitives":  # a timeout: the best primitive at s'
            q_next = torch.where(option_stops & ~hit, self._best_primitive(), q_next)
        if self.intra_option_primitives:  # the option's primitive, one Q-learning step at s
            self._learn_inside(reward, terminated, inside, stepped, phi_next)
        smdp_delta = self.learn(self.decision_phi, self.decision, self.decision_return,
                                self.duration.clamp(min=1), q_next, terminated, decision_ended,
                                next_phi=phi_next, next_decision=d_next,  # (a top_learner's)
                                next_available=self.last_available, stepped=stepped)
        # The state tensors are replaced, never written in place, so no copies are needed.
        info = {"decision_ended": decision_ended, "duration": self.duration,
                "decision_return": self.decision_return, "option_delta": option_delta,
                "smdp_delta": smdp_delta, "decision": self.decision,
                "option": self.option, "reached": reached}
        continuing = stepped & ~ended
        self.obs = next_obs
        self.option_code = torch.where(stepped[:, None], next_code, self.option_code)
        self.contains = torch.where(stepped[:, None], contains_next, self.contains)
        self.own_contains = own_next
        self._new_decisions(decision_ended & ~ended, phi_next, d_next)
        self.option = torch.where(ended, torch.full_like(self.option, -1), self.option)
        self._act(continuing, u[:, 2:])
        return info

    def extra_repr(self) -> str:
        return (f"population={self.population}, slots={self.slots}, epsilon={self.epsilon}, "
                f"option_epsilon={self.option_epsilon}, gamma={self.gamma}, max_option_steps="
                f"{self.max_option_steps}, failure_bootstrap={self.failure_bootstrap}, "
                f"intra_option_primitives={self.intra_option_primitives} "
                f"({self.intra_option_target}), interruption={self.interruption}, end_outside_set="
                f"{self.end_outside_set}, "
                f"active={int(self._index.numel())}, native={self.native}")
