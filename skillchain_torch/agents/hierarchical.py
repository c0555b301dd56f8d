"""The hierarchical agent and skill chaining, one step read top to bottom (sections 2, 4, 5.1).

This file is the algorithm. :class:`HierarchicalAgent` is SMDP Sarsa over primitives and a
given set of options; :class:`SkillChainingAgent` is the same agent discovering its options.
One step of either is one call, :meth:`HierarchicalAgent.transition` (which
:meth:`SkillChainingAgent.transition` follows with discovery's per-step record, one call), and
reads in the paper's order as plain calls into the pieces:

======================================  =====================================  =======
the step                                call                                   section
======================================  =====================================  =======
memberships: sets that hold s'          :meth:`membership` (the classifiers)   2, 4.3
targets: the options' events at s'      :meth:`targets` (the predicates)       4.2
intra-option update of the options      ``option_update``                      2
option stops: target, 250 steps, end    ``option_stops`` (:meth:`transition`)  2, 5.1
the next decision at s'                 :meth:`_choose` (epsilon-greedy)       2
SMDP update of the decision that ended  :meth:`learn` (:class:`SarsaUpdate`)   2
the action: option policy or primitive  :meth:`_act`                           2
discovery's per-step record             ``discovery.after_transition``         4, 5.1
======================================  =====================================  =======

When episodes end, :meth:`SkillChainingAgent.episodes_ended` applies discovery's episode rules
(learned sets become targets, gestation ends). The trainer drives the agent through the
episode protocol at the end of the class (``begin``, ``observe``, ``observe_ends``,
``compact``): compact rows of the active agents in, actions out.

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

The per-step state is declared once (:class:`~.step_state.StepState`, ``agent.step_state``);
its fields read as the agent's attributes (``agent.obs is agent.step_state.obs``).

Two paths compute the rest of a step after the memberships, targets and uniforms
(``native``): the torch path in :meth:`HierarchicalAgent.transition`, and a compiled one
(:func:`skillchain_torch.backends.hierarchical.transition`, the default where every piece is
the built-in one): the same decisions, sums in an order of their own.

Example:
    >>> from skillchain_torch.options import OptionBank
    >>> bank = OptionBank.build(population=2, slots=3, order=1)
    >>> agent = HierarchicalAgent(bank, order=1, seed=0)
    >>> agent.q_head.weight.shape                 # [P, 5 + K, F]
    torch.Size([2, 8, 16])
    >>> obs = torch.tensor([[0.2, 0.9, 0.5, 0.5]] * 2, dtype=torch.float64)
    >>> agent.begin(obs).shape
    torch.Size([2])
    >>> sc = SkillChainingAgent.build(population=2, slots=4, order=1, seed=0)
    >>> sc.bank.live().any().item()                 # no options until the goal is reached
    False
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from functools import partial
from operator import attrgetter

import torch
from tensordict import TensorDict
from torch import Tensor, nn
from torch.utils.hooks import RemovableHandle

from skillchain_torch.backends.select import (
    check_same_kernels,
    discovery_rules,
    hierarchical_step,
)
from skillchain_torch.discovery import (
    CONVERGENCE_EPISODES,
    CONVERGENCE_THRESHOLD,
    GESTATION_EPISODES,
    MAX_BRANCHING,
    InitiationReading,
)
from skillchain_torch.discovery.readings import FIRST_READING
from skillchain_torch.discovery.skill_chaining import overlap_exclusion
from skillchain_torch.discovery.subgoals import SUBGOALS, random_subgoals
from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.objectives import (
    IntraOptionQLearning,
    SarsaUpdate,
    SMDPSarsaLoss,
    discount,
    option_update_mask,
)
from skillchain_torch.objectives.option_replay import OptionReplay
from skillchain_torch.options import (
    FourierOptionQHead,
    GoalEvent,
    InitiationClassifier,
    OptionBank,
    OptionStatus,
    TerminationPredicate,
)
from skillchain_torch.options.goals import goal_event
from skillchain_torch.options.termination import evaluate_base_events
from skillchain_torch.policies import checked_epsilon, epsilon_greedy
from skillchain_torch.presets import (
    PRESET_FIELDS,
    Preset,
    env_values,
    instance_defaults,
    instance_slots,
    preset_named,
)
from skillchain_torch.rng import CounterRNG

from .step_state import STEP_FIELDS, StepState

__all__ = ["HierarchicalAgent", "SkillChainingAgent", "shared_fourier_columns", "NUM_PRIMITIVES",
           "MAX_OPTION_STEPS", "UNIFORMS_PER_STEP", "FAILURE_BOOTSTRAPS", "INTRA_OPTION_TARGETS",
           "END_OUTSIDE_SET"]

NUM_PRIMITIVES = 5
OBS_DIM = 4
MAX_OPTION_STEPS = 250
UNIFORMS_PER_STEP = 4  # top-level (explore, pick), option (explore, pick)
AGENT_STREAM = 0


def as_bool(x: Tensor) -> Tensor:
    """``x`` as a BoolTensor, without a call when it is one already (``Tensor.to`` costs a
    few microseconds even then, and per-step flags pass through here)."""
    return x if x.dtype == torch.bool else x.to(torch.bool)


FAILURE_BOOTSTRAPS = ("decision", "primitives")
INTRA_OPTION_TARGETS = ("decisions", "primitives")
# Which executions end where they leave their option's own set: none (the paper), those of
# options whose sets are learned (OptionStatus.LEARNED), or every one.
END_OUTSIDE_SET = {"off": None, "learned": OptionStatus.LEARNED, "always": OptionStatus.LEARNING}


def shared_fourier_columns(basis: FourierBasis, q_head) -> Tensor | None:
    """Where the option heads' Fourier features sit among ``basis``'s, or ``None``.

    A :class:`~skillchain_torch.options.FourierOptionQHead` of order ``o <= basis.order`` over
    the same observation has coefficient vectors ``c in {0..o}^4``, a subset of ``basis``'s,
    and :class:`FourierBasis` computes each ``cos(pi c . s)`` the same way whatever the order
    (``c . s`` summed over the dims in order from the same products ``s_j * c_j``, then an
    elementwise cosine), so ``q_head.encode(s)`` equals ``basis(s)[:, columns]`` bit for bit.

    Example:
        >>> from skillchain_torch.options import FourierOptionQHead
        >>> columns = shared_fourier_columns(FourierBasis(4, 4), FourierOptionQHead(1, 1, order=3))
        >>> columns.shape, columns[:3].tolist()
        (torch.Size([256]), [0, 1, 2])
    """
    inner = getattr(q_head, "basis", None)
    if type(q_head) is not FourierOptionQHead:  # a subclass may encode its own way
        return None
    if (not isinstance(inner, FourierBasis) or inner.dim != basis.dim
            or inner.order > basis.order or inner.coefficients.dtype != basis.coefficients.dtype
            or inner.coefficients.device != basis.coefficients.device):  # fmt: skip
        return None
    radix = basis.order + 1
    places = radix ** torch.arange(basis.dim - 1, -1, -1, device=inner.coefficients.device)
    return (inner.coefficients.to(torch.int64) * places).sum(-1)


def _field(name: str) -> property:
    """``agent.<name>``: the field of ``agent.step_state`` (read through ``attrgetter``, which
    runs in C: the torch path reads a dozen fields a step)."""

    def write(agent, value: Tensor) -> None:
        setattr(agent.step_state, name, value)

    return property(attrgetter(f"step_state.{name}"), write,
                    doc=f"``step_state.{name}`` (:class:`StepState`).")  # fmt: skip


class HierarchicalAgent(nn.Module):
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
        # The step's three calls, bound once: the torch path of this file, or a compiled step
        # where every piece is the built-in one (backends.select.hierarchical_step).
        self._bind_step(hierarchical_step(
            native, option_head=self.bank.q_head, top_head=self.q_head,
            top_features=self.features, device=self.bank.status.device, obs_dim=self.obs_dim,
            num_primitives=NUM_PRIMITIVES, completion_reward=completion_reward))
        # Memberships and refits go with the step where the classifier is the built-in one;
        # a classifier of the user's own keeps its torch path under a compiled step (and
        # native=True asks it for C, which it refuses, naming itself).
        classifier = self.bank.classifier
        if type(classifier) is InitiationClassifier:
            classifier.set_native(self.native)
        elif hasattr(classifier, "set_native"):
            classifier.set_native(bool(native) and self.native)
        # Discovery's rules, and the target and no-overlap booleans the step reads: the torch
        # path's, or with a compiled step their compiled twins (the same bits), chosen once.
        self.rules = discovery_rules(self.native)
        self._exclusion = overlap_exclusion(self.bank) if overlap else None
        # register_transition_hook's (an OrderedDict: torch's RemovableHandle holds a weakref)
        self._transition_hooks: OrderedDict[int, object] = OrderedDict()
        self.epsilon, self.option_epsilon = float(epsilon), float(option_epsilon)
        self.gamma = float(gamma)
        self.max_option_steps = int(max_option_steps)
        self.events = tuple(events)
        self._check_target_events()
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
            self._bind_step(None)
        return out

    def _bind_step(self, kernel) -> None:
        """Bind the step's three calls to ``kernel`` (a compiled step), or with ``None`` to
        this file's torch path: the choice is made here, once, never inside the step."""
        self.kernel, self.native = kernel, kernel is not None
        if kernel is None:
            self._decide, self._actions = self._torch_decide, self._torch_actions
            self._transition_rest = self._torch_transition_rest
        else:
            self._decide = partial(kernel.decide, self)
            self._actions = partial(kernel.actions, self)
            self._transition_rest = self._compiled_transition_rest

    # Per-step state is reassigned every step; nn.Module.__setattr__ (which looks for
    # parameters, buffers and submodules) costs more than the tensor maths for these.
    _PLAIN = frozenset({"step_state", "active", "last_q", "last_phi", "last_value", "_index",
                        "_raw_contains", "last_available", "last_events"})
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
        reached = self.targets(next_obs, terminated, contains_next, reward)
        u = self.rng.uniform(UNIFORMS_PER_STEP, mask=stepped)
        own_next = torch.where(stepped[:, None], self._raw_contains, self.own_contains)
        return self._transition_rest(next_obs, reward, terminated, truncated, stepped,
                                     contains_next, reached, u, own_next)  # fmt: skip

    def _torch_transition_rest(self, next_obs: Tensor, reward: Tensor, terminated: Tensor,
                               truncated: Tensor, stepped: Tensor, contains_next: Tensor,
                               reached: Tensor, u: Tensor, own_next: Tensor) -> dict:  # fmt: skip
        """The rest of :meth:`transition` after the memberships, targets and uniforms of
        ``s'``: the paper's updates and the next decision and action, in this order."""
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
        if self.WANTS_VALUE:  # Q(s', d) of the decision in force, for discovery's samples
            self.last_value = self._value_in_force(stepped, decision_ended)
        return info

    def _compiled_transition_rest(self, next_obs: Tensor, reward: Tensor, terminated: Tensor,
                                  truncated: Tensor, stepped: Tensor, contains_next: Tensor,
                                  reached: Tensor, u: Tensor, own_next: Tensor) -> dict:
        """:meth:`_torch_transition_rest` in the compiled step's one pass (bound by
        :meth:`_bind_step` when the agent is built): the kernel computes, the agent adopts the
        new state it returns."""
        state, phi, q, value, started, info = self.kernel.transition(
            self, next_obs, reward, terminated, truncated, stepped, contains_next, reached, u,
            own_next)  # fmt: skip
        self.step_state = state
        self.last_phi, self.last_q, self.last_value = phi, q, value
        self.own_contains = own_next
        self._options_starting(started)
        return info

    def _value_in_force(self, stepped: Tensor, decision_ended: Tensor) -> Tensor:
        """``[P]``: ``Q(s', d)`` of the decision in force after the step. New decisions were
        valued before this step's update; an agent going on with its option had no update this
        step, so its value now is the value then.

        A value, not a graph: it is kept from step to step (``q_decision``, merged with
        ``torch.where`` while some agents no longer step), so a value that carried a neural
        head's autograd graph would chain one graph onto the next and hold every step's
        activations (23 GB within half an hour on Pinball)."""
        with torch.no_grad():
            value = self.last_q.gather(1, self.decision[:, None])[:, 0]
            going_on = (stepped & ~decision_ended).nonzero()[:, 0]
            if going_on.numel() > 0:
                value[going_on] = self.q_head.q_value(self.last_phi, self.decision, going_on)
        return value

    def extra_repr(self) -> str:
        return (f"population={self.population}, slots={self.slots}, epsilon={self.epsilon}, "
                f"option_epsilon={self.option_epsilon}, gamma={self.gamma}, max_option_steps="
                f"{self.max_option_steps}, failure_bootstrap={self.failure_bootstrap}, "
                f"intra_option_primitives={self.intra_option_primitives} "
                f"({self.intra_option_target}), interruption={self.interruption}, end_outside_set="
                f"{self.end_outside_set}, "
                f"active={int(self._index.numel())}, native={self.native}")

    # ==========================================================================================
    # The top level: its choice among primitives and options, and how it learns (section 2)
    # ==========================================================================================
    def top_level_available(self, obs: Tensor, contains: Tensor | None = None) -> Tensor:
        """``[P, 5 + K]``: the primitives (always) and the available options at ``obs``."""
        options = self.bank.available(obs, contains)
        primitives = torch.ones(self.population, self.num_primitives, dtype=torch.bool,
                                device=options.device)
        return torch.cat([primitives, options], dim=-1)

    def _encode(self, obs: Tensor, index: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """``(phi(s), option code of s)``: the top-level features and the option heads' code
        (of the rows ``index`` of ``obs [P, 4]`` only, when given: ``[len(index), .]``).

        When the option heads use a Fourier basis of the same observation and no higher order
        (the paper: order 3 under order 4), their features are columns of the top level's,
        computed with the same arithmetic (see :func:`shared_fourier_columns`), so they are
        picked rather than computed again."""
        phi = self.features(obs if index is None else obs[index])
        if self._code_columns is not None:
            return phi, phi[:, self._code_columns]
        code = self.bank.q_head.encode(obs)  # a head's code may need every row (its checks)
        return phi, code if index is None else code[index]

    def _choose(self, obs: Tensor, phi: Tensor, contains: Tensor, uniforms: Tensor,
                rows: Tensor | None = None) -> tuple[Tensor, Tensor]:  # fmt: skip
        """Top-level epsilon-greedy decision at ``obs``; ``(phi, decision)``.

        Only the agents in ``rows [P]`` (default all) need a decision: an executing option that
        goes on needs none, and the 5 + K values are the top level's largest cost. Other rows'
        decisions are meaningless. ``phi`` and ``Q(obs, .)`` stay in ``last_phi`` and
        ``last_q`` for subclasses (``last_q`` valid on ``rows`` for the available decisions,
        0 for the others). ``phi``: ``features(obs)``, from :meth:`_encode`."""
        available = self.top_level_available(obs, contains)
        rows = torch.ones_like(self.active) if rows is None else rows
        q, decision = self._decide(phi, available, rows, uniforms)
        self.last_phi, self.last_q, self.last_available = phi, q, available
        return phi, decision

    def _torch_decide(self, phi: Tensor, available: Tensor, rows: Tensor,
                      uniforms: Tensor) -> tuple[Tensor, Tensor]:  # fmt: skip
        """``(Q [P, D], decision [P])``: the top level's values on ``rows`` and its
        epsilon-greedy choice among the ``available`` decisions."""
        # Value only what can be chosen: the primitives, and the few options whose initiation
        # set holds the state (each value is the same row sum as a full forward).
        if self.closed_form:  # (a buffer: no graph; the hot path skips the context)
            q = self.q_head.forward_mask(phi, available & rows[:, None], dense=self.num_primitives)
        else:  # a head of the user's own: acting values are never differentiated
            with torch.no_grad():
                q = self.q_head.forward_mask(phi, available & rows[:, None],
                                             dense=self.num_primitives)  # fmt: skip
        return q, epsilon_greedy(q, available, self.epsilon, uniforms,
                                 check=False)  # primitives are always available

    def learn(self, phi: Tensor, decision: Tensor, ret: Tensor, duration: Tensor,
              next_value: Tensor, terminated: Tensor, active: Tensor,
              **next_state: Tensor) -> Tensor:  # fmt: skip
        """One SMDP Sarsa step of the top-level head toward ``ret + gamma^k next_value``
        for the ``active`` agents; their TD errors ``[P]``. The built-in linear head steps in
        closed form (:class:`SarsaUpdate`); any other by its loss and optimizer, or by the
        agent's ``top_learner`` (which also reads ``next_state``: ``next_phi``,
        ``next_decision``, ``next_available``, and ``stepped``: the agents still running)."""
        if self.closed_form:
            return self.update(self.q_head, phi, decision, ret, duration, phi, decision,
                               terminated, active=active, next_value=next_value)
        with torch.enable_grad():
            return self._loss_step(phi, decision, ret, duration, next_value, terminated, active,
                                   next_state)  # fmt: skip

    def _loss_step(self, phi, decision, ret, duration, next_value, terminated, active,
                   next_state=None) -> Tensor:  # fmt: skip
        extra = next_state if self.top_learner is not None and next_state else {}
        td = TensorDict(phi=phi, decision=decision, decision_return=ret, duration=duration,
                        next_value=next_value, terminated=terminated, active=active, **extra,
                        batch_size=[self.population])  # fmt: skip
        if self.top_learner is not None:
            return self.top_learner(td)
        self.optimizer.zero_grad()
        out = self.loss(td)
        out["loss"].backward()
        self.optimizer.step()
        return out["td_error"]

    # ==========================================================================================
    # The options: memberships, targets, the executing option's action, and the readings of an
    # ==========================================================================================
    # execution the paper leaves open (interruption, what the primitives learn inside options)
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
        return self.rules.exclude_overlap(contains, self._exclusion,
                                          self.bank.classifier.trained)  # fmt: skip

    def targets(self, next_obs: Tensor, terminated: Tensor, contains: Tensor,
                reward: Tensor | None = None) -> Tensor:  # fmt: skip
        """``[P, K]``: each live option's termination predicate (target event) at ``s'``
        (``reward``: the transition's, for a goal over the transition).

        A chained option's target is its parent's own initiation set (the classifier's, as in
        discovery), not the parent's set narrowed by the no-overlap rule."""
        raw = contains if self._exclusion is None else self._raw_contains
        # OptionBank.target_reached's answer from the events' values (compiled where built):
        # this runs every step, and target_reached costs ~140 us of small torch ops. The
        # base events' values at s' stay in last_events (skill chaining's triggers).
        self.last_events = evaluate_base_events(self.events, next_obs, terminated, reward)
        return self.rules.target_indicator(self.bank, self.last_events, raw)

    def _check_target_events(self) -> None:
        """Refuse a bank whose slots target an event the agent lacks (checked when the bank
        arrives, at construction and when a state is loaded, not every step: discovery
        only ever gives its slots the agent's own events)."""
        bank = self.bank
        if bank.slots and int(bank.target_event.max()) >= len(self.events):
            used = int(bank.target_event.max())
            raise ValueError(f"target event {used} used by a slot, but only {len(self.events)} "
                             f"given")  # fmt: skip

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
        self.action = self._actions(rows, uniforms)

    def _torch_actions(self, rows: Tensor, uniforms: Tensor) -> Tensor:
        """``[P]``: the new ``action`` (rows outside ``rows`` keep theirs)."""
        action = self.decision.clamp(max=self.num_primitives - 1)
        executing = rows & (self.option >= 0)
        index = executing.nonzero()[:, 0]
        if index.numel() > 0:  # only the executing rows' option values (a row's own sums)
            q_opt = self.bank.q_head.slot_values_rows(self.option_code, self.option, index)
            all_actions = torch.ones_like(q_opt, dtype=torch.bool)
            by_option = epsilon_greedy(q_opt, all_actions, self.option_epsilon, uniforms[index],
                                       check=False)  # fmt: skip
            action = action.index_put((index,), by_option)
        return torch.where(rows, action, self.action)

    # ==========================================================================================
    # The episode protocol every agent of a trainer follows (rows = active agents, ascending id)
    # ==========================================================================================
    def all_active(self) -> bool:
        """Every agent is active: rows are agents (a check without a call into torch)."""
        return self._index.numel() == self.population

    def all_stepped(self, stepped: Tensor) -> bool:
        """``stepped`` is the agent's own ``active`` mask with every agent active (what
        :meth:`observe` passes): per-row masking by it changes nothing, so it can be skipped."""
        return stepped is self.active and self.all_active()

    # ------------------------------------------------------------------ protocol
    def _full(self, rows_value: Tensor, fill: Tensor) -> Tensor:
        if self.all_active():  # rows are agents
            return rows_value if rows_value.dtype == fill.dtype else rows_value.to(fill.dtype)
        out = fill.clone()
        out[self._index] = rows_value if rows_value.dtype == out.dtype else rows_value.to(out.dtype)
        return out

    def begin(self, obs: Tensor) -> Tensor:
        """First decisions of every active agent at its start observation ``[n, 4]``."""
        self._start_decisions(self._full(obs, self.obs), self.active.clone())
        return self.actions

    def register_transition_hook(self, hook) -> RemovableHandle:
        """Call ``hook(info, next_obs, terminated, stepped)`` after each step the agents learn
        from (:meth:`observe`, :meth:`observe_ends`), with :meth:`transition`'s monitoring
        dict and its ``[P]`` arguments; ``handle.remove()`` stops it (torch's hook
        convention). The option monitor counts executions this way for agents that keep no
        counts of their own.

            >>> from skillchain_torch.options import OptionBank
            >>> agent = HierarchicalAgent(OptionBank.build(population=1, slots=1, order=1),
            ...                           order=1, seed=0)
            >>> seen = []
            >>> handle = agent.register_transition_hook(lambda info, *_: seen.append(info))
            >>> s = torch.tensor([[0.2, 0.9, 0.5, 0.5]], dtype=torch.float64)
            >>> _ = agent.begin(s); _ = agent.observe(s, torch.tensor([-1.0]))
            >>> handle.remove(); _ = agent.observe(s, torch.tensor([-1.0]))
            >>> len(seen), sorted(seen[0])[:2]
            (1, ['decision', 'decision_ended'])
        """
        handle = RemovableHandle(self._transition_hooks)
        self._transition_hooks[handle.id] = hook
        return handle

    def observe(self, obs: Tensor, reward: Tensor) -> Tensor:
        """Learn from a step in which no episode ended; the next actions ``[n]``."""
        none = torch.zeros_like(self.active)
        self._learn_step(obs, reward, none, none)
        return self.actions

    def _learn_step(self, obs: Tensor, reward: Tensor, terminated: Tensor,
                    truncated: Tensor) -> None:  # fmt: skip
        """:meth:`transition` of every active row (compact ``obs``/``reward`` widened to
        ``[P]``), then the registered transition hooks."""
        next_obs = self._full(obs, self.obs)
        info = self.transition(next_obs, self._full(reward, self.decision_return), terminated,
                               truncated, self.active)  # fmt: skip
        for hook in self._transition_hooks.values():
            hook(info, next_obs, terminated, self.active)

    def observe_ends(self, obs: Tensor, reward: Tensor, terminated: Tensor, truncated: Tensor,
                     restart_rows: Tensor, start_obs: Tensor | None) -> Tensor:
        """Like :meth:`observe` when some episodes ended (see ``FlatSarsaAgent``): terminal
        updates do not bootstrap, truncated ones do; rows in ``restart_rows`` then decide at
        ``start_obs``."""
        none = torch.zeros_like(self.active)
        terminated, truncated = self._full(terminated, none), self._full(truncated, none)
        self._learn_step(obs, reward, terminated, truncated)
        self.episodes_ended(self.active & (terminated | truncated))
        if restart_rows.numel() > 0:
            restart = torch.zeros_like(self.active)
            restart[self._index[restart_rows]] = True
            start = self.obs.clone()
            start[self._index[restart_rows]] = start_obs.to(start.dtype)
            self._start_decisions(start, restart)
        return self.actions

    def episodes_ended(self, rows: Tensor) -> None:
        """Agents ``rows [P]`` just ended an episode (before any restart); nothing to do here,
        skill chaining runs its per-episode rules."""

    def compact(self, keep: Tensor) -> None:
        """Keep the active rows where ``keep [n]``; the others stop for good."""
        self._index = self._index[keep]
        active = torch.zeros_like(self.active)
        active[self._index] = True
        self.active = active

    @property
    def index(self) -> Tensor:
        """Ids of the active agents, ascending ``[n]``."""
        return self._index

    @property
    def actions(self) -> Tensor:
        """The primitive action of each active row ``[n]``."""
        if self.all_active():  # (action is replaced, never written)
            return self.action
        return self.action[self._index]

    @property
    def decisions(self) -> Tensor:
        """The top-level decision in force for each active row ``[n]`` (5 + k: option k)."""
        return self.decision[self._index]

    @property
    def options(self) -> Tensor:
        """The executing option slot of each active row ``[n]`` (-1: none)."""
        return self.option[self._index]

    def flush(self) -> None:
        """Nothing to write back: the state is held for all agents."""

    def set_epsilon(self, epsilon: float) -> None:
        """The top level's exploration from the next decision on; an annealing schedule
        (``TrainConfig.epsilon_init``) calls it each population step. Executing options keep
        ``option_epsilon``.

            >>> from skillchain_torch.options import OptionBank
            >>> agent = HierarchicalAgent(OptionBank.build(population=2, slots=1, order=1),
            ...                           order=1, seed=0)
            >>> agent.set_epsilon(0.5); agent.epsilon
            0.5
        """
        self.epsilon = checked_epsilon(epsilon)

    # ------------------------------------------------------------------ state
    _EPISODE = ("obs", "contains", "own_contains", "decision", "option", "decision_return",
                "duration", "active")

    def state_dict(self, *args, **kwargs):
        """Top-level weights, options, streams, and every agent's episode state.

        Laid out like ``FlatSarsaAgent``'s (``q_head``, ``rng``, ``index``, ``action``,
        ``phi``: the features of the state where the decision in force was taken), plus
        ``bank`` and ``episode`` (the per-agent option state).
        """
        return {
            "q_head": self.q_head.state_dict(),
            "rng": self.rng.state_dict(),
            "index": self._index.clone(),
            "action": self.action.clone(),
            "phi": self.decision_phi.clone(),
            "bank": self.bank.state_dict(),
            "episode": {name: getattr(self, name).clone() for name in self._EPISODE},
            "native": self.native,
            **({} if self.optimizer is None else {"optimizer": self.optimizer.state_dict()}),
            **({"top_learner": self.top_learner.state_dict()}
               if hasattr(getattr(self, "top_learner", None), "state_dict") else {}),
            **({"option_replay": self.bank.q_head.replay.state_dict()}
               if getattr(self.bank.q_head, "replay", None) is not None else {}),
        }

    def load_state_dict(self, state, strict: bool = True, assign: bool = False):
        device = self.obs.device
        check_same_kernels(state, self.native)
        self.q_head.load_state_dict(state["q_head"])
        if self.optimizer is not None and "optimizer" in state:
            self.optimizer.load_state_dict(state["optimizer"])
        if "top_learner" in state:
            self.top_learner.load_state_dict(state["top_learner"])
        if "option_replay" in state:
            replay = self.bank.q_head.replay  # (the built-in one moves to the bank's device)
            if isinstance(replay, OptionReplay):
                replay.load_state_dict(state["option_replay"], device=self.bank.status.device)
            else:
                replay.load_state_dict(state["option_replay"])
        self.bank.load_state_dict(state["bank"])
        self._check_target_events()
        self.rng.load_state_dict(state["rng"])
        self.rng.to(device)
        self._index = state["index"].to(device)
        self.action = state["action"].to(device).clone()
        self.decision_phi = state["phi"].to(device).clone()
        episode = state["episode"]
        if "own_contains" not in episode:  # saved before the own sets were kept (issue 30):
            episode = {**episode, "own_contains": episode["contains"]}  # what it learned by
        for name in self._EPISODE:
            setattr(self, name, episode[name].to(device).clone())
        phi, self.option_code = self._encode(self.obs)  # pure functions of s
        if self.intra_option_primitives:
            self.state_phi = phi


# Every StepState field reads and writes as the agent's attribute (agent.obs is
# agent.step_state.obs), so the torch path reads as the paper's rules.
for _name in STEP_FIELDS:
    setattr(HierarchicalAgent, _name, _field(_name))


class SkillChainingAgent(HierarchicalAgent):
    """Population-batched skill chaining: P agents, K option slots each, discovered on-line.

    Args:
        bank: an :class:`OptionBank` (usually empty; :meth:`build` makes a preset's).
        events: the base target events, goal first (section 4.4).
        gestation, max_branching, convergence_threshold, convergence_episodes, overlap,
            wait_for_both_classes: the discovery rules (paper: 10, 3, 0.15, 2, on, off); see
            :class:`~skillchain_torch.discovery.SkillChaining`. The constructor's defaults are
            the paper's discovery rules; :meth:`build` takes every value from a preset.
        reading: the initiation-set reading (:class:`~skillchain_torch.discovery.
            InitiationReading`; default the first one, true everywhere until the first fit).
        policy_start: ``"zero"``, ``"top-level"`` or ``"top-level-shifted"``: how a joining
            option's policy starts
            (see :class:`~skillchain_torch.discovery.SkillChaining`).
        **kwargs: the :class:`HierarchicalAgent` arguments (``order``, ``alpha``, ``gamma``,
            ``epsilon``, ``seed``, ``option_epsilon``, ``max_option_steps``, ...).

    Attributes:
        discovery: the :class:`SkillChaining` state; its ``log`` holds the discovery events.
    """

    _PLAIN = HierarchicalAgent._PLAIN | {"q_decision", "_starts"}
    WANTS_VALUE = True  # gestation samples Q(s, d) of the decision in force

    def __init__(self, bank: OptionBank, events: Sequence[TerminationPredicate] = (GoalEvent(),),
                 gestation: int = GESTATION_EPISODES, max_branching: int = MAX_BRANCHING,
                 convergence_threshold: float = CONVERGENCE_THRESHOLD,
                 convergence_episodes: int = CONVERGENCE_EPISODES, overlap: bool = True,
                 wait_for_both_classes: bool = False,
                 reading: InitiationReading = FIRST_READING, policy_start: str = "zero",
                 value_start: str = "max-sample", value_bonus: float = 0.0,
                 chaining: bool = True, **kwargs):  # fmt: skip
        super().__init__(bank, events=events, **kwargs)
        # Two starts read the agent's values: the linear head's weights in its Fourier basis,
        # or any head's values on a grid of states, which the written head fits (fit_values).
        linear = self.closed_form and type(self.features) is FourierBasis
        name = type(self.q_head).__name__
        # (a head's values on the grid are read per agent: select_agents, or the linear weights)
        readable = isinstance(self.q_head, LinearQHead) or hasattr(self.q_head, "select_agents")
        if value_start == "agent" and not (linear or (
                readable and hasattr(self.q_head, "fit_values"))):  # fmt: skip
            raise ValueError(f"value_start='agent' fits the agent's own values in the top head, "
                             f"which {name} cannot take (it needs fit_values and "
                             "select_agents): use value_start='max-sample' (the paper's)")
        if policy_start != "zero" and not readable:
            raise ValueError(f"policy_start={policy_start!r} copies the agent's values into an "
                             f"option, which needs them read from {name} (select_agents): use "
                             "policy_start='zero' (the paper's)")
        if policy_start == "top-level-shifted" and not (
                linear and getattr(bank.q_head, "basis", None) is not None):  # fmt: skip
            raise ValueError("policy_start='top-level-shifted' reads the linear values (a "
                             "LinearQHead over a FourierBasis, Fourier option heads): use "
                             "policy_start='top-level'")
        self.discovery = self.rules(
            self.bank, self.events, gestation=gestation, max_branching=max_branching,
            convergence_threshold=convergence_threshold,
            convergence_episodes=convergence_episodes,
            max_option_steps=kwargs.get("max_option_steps", MAX_OPTION_STEPS), overlap=overlap,
            wait_for_both_classes=wait_for_both_classes, reading=reading,
            policy_start=policy_start, value_start=value_start, value_bonus=value_bonus,
            top_basis=self.features, completion_reward=self.option_update.completion_reward,
            chaining=chaining,
        )  # fmt: skip
        # Q(s, d) of the decision d in force at the current state s, valued when s was reached
        # (before that step's update): the samples of gestation.
        self.q_decision = torch.zeros(self.population, dtype=torch.float64,
                                      device=self.obs.device)  # fmt: skip
        self._starts: Tensor | None = None  # agents whose option started this step, if any

    @classmethod
    def build(cls, population: int, preset: str | Preset = "default", seed: int | Tensor = 0,
              device: torch.device | str | None = None, map: str | None = None,
              **kwargs) -> SkillChainingAgent:  # fmt: skip
        """The agent of a named preset, with an empty bank of Fourier options per agent.

        Args:
            population: P, the number of independent agents.
            preset: ``"default"`` (the library's, which ``skillchain train`` builds) or
                ``"paper"`` (section 5.1's values); see :mod:`skillchain_torch.presets`.
            seed: agent p's random streams are keyed by ``seed + p``.
            map: the Pinball map whose paper ``order`` / ``alpha`` and library ``slots`` apply
                where the preset leaves them to the instance (``None``: the first instance's, 4,
                0.001 and 12 slots; the hard instance has 48).
            **kwargs: any :class:`~skillchain_torch.presets.Preset` field (``slots``,
                ``gestation``, ``option_alpha``, ``balanced``, ...) overrides the preset's
                value; ``top_head``, ``option_head``, ``initiation`` name the pieces
                (:mod:`~skillchain_torch.agents.pieces`: the paper's ``"fourier"``,
                ``"fourier"``, ``"logistic"`` by default, or ``"mlp"``); ``top_learner`` (a dict)
                goes to the top-level piece's builder (``"mlp"``: ``lr``, ``target_update``,
                ``bootstrap``); ``goal`` (``"terminated-positive"``, ``"MODULE:FUNCTION"`` or
                an event: :mod:`~skillchain_torch.options.goals`) replaces the env's
                ``terminated`` as the goal; the rest go to the
                constructor (``events``, ``native``, ``reading``, ...) and win over the preset.

        Example:
            >>> paper = SkillChainingAgent.build(2, preset="paper", order=1, gestation=5)
            >>> paper.discovery.gestation, paper.discovery.policy_start
            (5, 'zero')
            >>> SkillChainingAgent.build(2, order=1).discovery.policy_start  # "default"
            'top-level'
        """
        bank, arguments = cls.build_arguments(population, preset, seed=seed, device=device,
                                              map=map, **kwargs)  # fmt: skip
        return cls(bank, **arguments)

    @staticmethod
    def build_arguments(population: int, preset: str | Preset = "default",
                        seed: int | Tensor = 0, device: torch.device | str | None = None,
                        map: str | None = None, **kwargs) -> tuple[OptionBank, dict]:  # fmt: skip
        """``(bank, constructor keyword arguments)`` of :meth:`build` (the trainer's
        ``SkillChainingRunAgent`` builds through this too, so both build the same agent)."""
        from .pieces import assemble_bank, top_level_arguments  # (they import the modules)

        fields = {k: kwargs.pop(k) for k in list(kwargs) if k in PRESET_FIELDS}
        names = {k: kwargs.pop(k, d) for k, d in (("top_head", "fourier"),
                                                  ("option_head", "fourier"),
                                                  ("initiation", "logistic"))}  # fmt: skip
        learner = kwargs.pop("top_learner", None)
        # The env's sizes (its specs; None: Pinball's 4 and 5).
        sizes = {k: v for k in ("obs_dim", "num_actions") if (v := kwargs.pop(k, None)) is not None}
        p = preset_named(preset).replace(**fields)
        order, alpha = instance_defaults(map)
        if p.slots is None:  # the library's for the map (off Pinball, map None: 12)
            p = p.replace(slots=instance_slots(map))
        if "obs_dim" in sizes:  # off Pinball: from the env's size, as TrainConfig.resolved
            order, alpha, scaled = env_values(p, sizes["obs_dim"], p.order)
            if "option_alpha" not in fields:
                p = p.replace(option_alpha=scaled)
        bank = OptionBank.build(population, p.slots, order=p.option_order, alpha=p.option_alpha,
                                seed=seed, device=device, degree=p.degree, lr=p.lr,
                                sweeps=p.sweeps, capacity=p.capacity, distance=p.distance,
                                balanced=p.balanced, keep_negatives=p.keep_negatives,
                                store_failures=p.store_failures,
                                constrain_nearest=p.constrain_nearest,
                                initial_bias=p.initiation_bias,
                                centered=p.initiation_centered, **sizes)  # fmt: skip
        bank = assemble_bank(bank, names["option_head"], names["initiation"], seed=seed)
        top = top_level_arguments(names["top_head"], population, bank.obs_dim,
                                  bank.num_actions + p.slots, p.gamma, seed, device,
                                  learner)  # fmt: skip
        reading = InitiationReading(p.gestation_positives, p.initiation_start,
                                    p.initiation_constrain, p.one_class_fits)  # fmt: skip
        if p.subgoals not in SUBGOALS:
            raise ValueError(f"subgoals must be one of {', '.join(SUBGOALS)}, got {p.subgoals!r}")
        goal = kwargs.pop("goal", None)  # an event or its name; None: the env's terminated
        goal = goal_event(goal) if isinstance(goal, str) else goal
        if goal is not None and "events" in kwargs:
            raise ValueError("give the goal as goal= or as the first of events=, not both")
        if p.subgoals == "random":  # the control: the goal, and random discs for the rest
            if "events" in kwargs:
                raise ValueError("subgoals 'random' draws its own events; leave events out")
            kwargs["events"] = (goal or GoalEvent(), *random_subgoals(
                population, p.slots - 1, seed, map, device=device))
            kwargs["chaining"] = False
        elif goal is not None:
            kwargs["events"] = (goal,)
        arguments = dict(
            order=order if p.order is None else p.order,
            alpha=alpha if p.alpha is None else p.alpha, gamma=p.gamma, epsilon=p.epsilon,
            seed=seed, device=device, scale_step_size=p.scale_step_size,
            failure_bootstrap=p.failure_bootstrap, completion_reward=p.completion_reward,
            intra_option_primitives=p.intra_option_primitives,
            intra_option_target=p.intra_option_target,
            interruption=p.option_interruption, end_outside_set=p.end_outside_set,
            option_epsilon=p.option_epsilon,
            max_option_steps=p.max_option_steps, gestation=p.gestation,
            max_branching=p.max_branching, convergence_threshold=p.convergence_threshold,
            convergence_episodes=p.convergence_episodes, overlap=p.overlap, reading=reading,
            policy_start=p.policy_start, value_start=p.value_start, value_bonus=p.value_bonus,
        )  # fmt: skip
        return bank, {**arguments, **top, **kwargs}

    # ------------------------------------------------------------------ hooks
    def narrow(self, contains: Tensor) -> Tensor:
        return self.discovery.membership(contains)

    def targets(self, next_obs: Tensor, terminated: Tensor, contains: Tensor,
                reward: Tensor | None = None) -> Tensor:  # fmt: skip
        # Targets are the classifiers' own sets at s' (kept by membership), not the effective
        # ones in ``contains`` (see SkillChaining.membership).
        return super().targets(next_obs, terminated, self._raw_contains, reward)

    def _start_decisions(self, obs: Tensor, rows: Tensor) -> None:
        super()._start_decisions(obs, rows)
        self.discovery.start_episodes(self.obs, rows)
        chosen = self.last_q.gather(1, self.decision[:, None])[:, 0]
        self.q_decision = torch.where(rows, chosen, self.q_decision)
        self._begin_executions()

    def _options_starting(self, rows: Tensor) -> None:
        # Snapshots wait until the step's updates (and any dropped ones) are done.
        self._starts = rows if self._starts is None else self._starts | rows

    def _begin_executions(self) -> None:
        # (The compiled step reports its starts every step; most steps start none.)
        if self._starts is not None and bool(self._starts.any()):
            self.discovery.start_executions(self._starts, self.option)
        self._starts = None

    def transition(self, next_obs: Tensor, reward: Tensor, terminated: Tensor,
                   truncated: Tensor, stepped: Tensor) -> dict[str, Tensor]:  # fmt: skip
        # At s: what discovery's record of this step reads, before the step replaces it.
        obs, contains, option, value = self.obs, self.contains, self.option, self.q_decision
        step = self.duration
        info = super().transition(next_obs, reward, terminated, truncated, stepped)
        every = self.all_stepped(stepped)  # masks by stepped are then skipped
        executing = option >= 0
        terminated = as_bool(terminated)
        starts, self._starts = self._starts, None
        created = self.discovery.after_transition(
            obs=obs, executing=executing if every else stepped & executing, contains=contains,
            option=option, value=value, step=step, events=self.last_events,
            reached=info["reached"], duration=info["duration"],
            decision_ended=info["decision_ended"],
            terminated=terminated if every else terminated & stepped, stepped=stepped,
            starts=starts, option_next=self.option,
        )  # fmt: skip
        if bool(created.any()):  # the new slot changes the memberships at s'
            self.contains = torch.where(created[:, None], self.membership(self.obs),
                                        self.contains)  # fmt: skip
            self.own_contains = torch.where(created[:, None], self._raw_contains,
                                            self.own_contains)  # fmt: skip
            self.discovery.created_rows_evaluated(created)
        value_next = self.last_value  # Q(s', d) of the decision in force (_value_in_force)
        self.q_decision = value_next if every else torch.where(stepped, value_next,
                                                                 self.q_decision)  # fmt: skip
        return info

    def episodes_ended(self, rows: Tensor) -> None:
        self.discovery.end_episodes(rows, self.q_head)

    # ------------------------------------------------------------------ state
    def state_dict(self, *args, **kwargs):
        state = super().state_dict()
        state["discovery"] = self.discovery.state_dict()
        state["q_decision"] = self.q_decision.clone()
        return state

    def load_state_dict(self, state, strict: bool = True, assign: bool = False):
        super().load_state_dict(state)
        self.discovery.load_state_dict(state["discovery"])
        self.q_decision = state["q_decision"].to(self.obs.device).clone()

    def extra_repr(self) -> str:
        return super().extra_repr() + f", discovery={self.discovery!r}"
