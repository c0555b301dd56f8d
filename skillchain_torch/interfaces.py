"""The pieces a researcher replaces, each declared once with every method it must provide.

Skill chaining (paper sections 2, 4, 5.1) is assembled from five pieces. The agent, the
discovery rules, the convergence test, the monitoring and the checkpoints reach them only
through the methods below; the paper's Fourier/logistic pieces are one implementation of each,
and a compiled backend (:mod:`skillchain_torch.backends`) runs only where a piece is *exactly*
the built-in class it replaces (a subclass, or any other class, takes the torch path, so an
override is never bypassed).

============================== ======================================== ===========================
interface                      the paper's implementation               shapes
============================== ======================================== ===========================
:class:`InitiationSet`         :class:`~.options.InitiationClassifier`  ``obs [P, D] -> [P, K]``
                               (logistic, 5.1)
:class:`OptionHead`            :class:`~.options.FourierOptionQHead`    ``obs [P, D] -> [P, K, A]``
                               (Fourier, Q-learning)
:class:`ValueHead`             :class:`~.modules.LinearQHead`           ``phi [P, F] -> [P, 5 + K]``
                               (the top level, SMDP Sarsa)
:class:`TerminationPredicate`  :class:`~.options.GoalEvent`,            ``obs [P, D] -> [P]``
                               ``InitiationSetEvent``
:class:`Learner`               :class:`~.objectives.SarsaUpdate`,       a TD step on a head
                               ``IntraOptionQLearning``
============================== ======================================== ===========================

``P`` agents of a population, ``K`` option slots per agent, ``D`` observation dims, ``A``
primitive actions, ``F`` features.

Two seams join the pieces to the trainer: :class:`EpisodeAgent`, the protocol every agent of a
trainer follows (:class:`~skillchain_torch.agents.FlatSarsaAgent`,
:class:`~skillchain_torch.agents.HierarchicalAgent` and
:class:`~skillchain_torch.agents.SkillChainingAgent`, or a researcher's own), and
:class:`EnvStepper`, what steps the population's envs for it (Pinball's
:class:`~skillchain_torch.envs.pinball.stepper.ActiveEnvStepper`, or
:class:`~skillchain_torch.trainers.loop.env_stepper.EnvStepper` over TorchRL envs).

The protocols are ``runtime_checkable`` (``isinstance`` tests that the methods exist, not their
shapes); :func:`missing_methods` names what a candidate lacks.

Example:
    >>> from skillchain_torch.options import InitiationClassifier
    >>> clf = InitiationClassifier(population=1, slots=2, capacity=8)
    >>> isinstance(clf, InitiationSet), missing_methods(clf, InitiationSet)
    (True, [])
    >>> missing_methods(object(), InitiationSet)[:3]
    ['add_examples', 'config', 'constrain']
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

from torch import Tensor

from skillchain_torch.options.q_head import OptionQHead as OptionHead
from skillchain_torch.options.termination import TerminationPredicate

__all__ = ["InitiationSet", "Learner", "OptionHead", "TerminationPredicate", "ValueHead",
           "EpisodeAgent", "EnvStepper", "missing_methods"]


@runtime_checkable
class InitiationSet(Protocol):
    """Per-slot initiation sets ``I_k`` of P agents, learned from labelled example stores.

    A subclass of :class:`~skillchain_torch.options.InitiationClassifier` that overrides
    :meth:`logit` (for instance with an ``nn.Module`` of its own) gets everything else from the
    base class: the stores, the distance constraint, a gradient fit of its own parameters, a
    convergence measure from its outputs, images, and save/load through the registry
    (:func:`~skillchain_torch.options.register_classifier`).

    A class of the user's own that implements the methods below without subclassing it works
    too (``tests/test_seams.py`` trains one under skill chaining): the option set takes its
    device from ``trained`` and its observation size from the option head, and the compiled
    paths (``native``, the stores' kernels) are only ever asked of the built-in class.

    Attributes:
        population, slots: P and K.
        trained: ``BoolTensor [P, K]``, fitted at least once (an untrained set holds everything).
        config: the constructor's keyword arguments (rebuilds it on load).
    """

    population: int
    slots: int
    trained: Tensor
    config: dict[str, Any]

    def logit(self, obs: Tensor) -> Tensor:
        """``obs [P, *B, D] -> [P, *B, K]``: every slot's log-odds that ``obs`` is in its set."""

    def contains(self, obs: Tensor) -> Tensor:
        """``obs [P, D] -> BoolTensor [P, K]``: membership, one state per agent (every step)."""

    def contains_points(self, agent: int, slot: int, obs: Tensor) -> Tensor:
        """``obs [N, D] -> BoolTensor [N]``: one slot's membership of many states (images)."""

    def add_examples(self, agents: int | Tensor, slots: int | Tensor, obs: Tensor,
                     labels: Tensor) -> Tensor:  # fmt: skip
        """Store ``obs [N, D]`` with ``labels [N]``; ``[P, K]`` mask of the slots given data."""

    def stored_classes(self) -> tuple[Tensor, Tensor]:
        """``(positive, negative)`` ``[P, K]``: the slot stores an example of that class."""

    def has_both_classes(self) -> Tensor:
        """``[P, K]``: the slot stores both classes."""

    def fit(self, mask: Tensor | None = None) -> Tensor:
        """Fit the slots in ``mask [P, K]`` (default: those with new data); the mask fitted."""

    def constrain(self, mask: Tensor) -> None:
        """Turn on the distance constraint for the slots in ``mask [P, K]`` (learned sets)."""

    def reset_slots(self, mask: Tensor) -> None:
        """Forget the slots in ``mask [P, K]`` (a new option takes the slot)."""

    def snapshot(self) -> Tensor:
        """``[P, K, M]``: what the convergence test compares between episodes."""

    def weight_change(self, before: Tensor, after: Tensor | None = None) -> Tensor:
        """``[P, K]``: mean absolute change between two :meth:`snapshot` s (paper: < 0.15)."""

    def select_agents(self, index, seeds: Tensor | None = None) -> InitiationSet:
        """A new set holding agents ``index`` (repeats allowed)."""

    def state_dict(self, *args, **kwargs) -> dict[str, Any]: ...

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False): ...


@runtime_checkable
class ValueHead(Protocol):
    """The top level's action values over ``5 + K`` decisions (primitives, then option slots).

    Attributes:
        population (P), num_decisions (D), num_features (F).
    """

    population: int
    num_decisions: int
    num_features: int

    def forward(self, phi: Tensor) -> Tensor:
        """``phi [P, F] -> Q [P, D]``."""

    def forward_mask(self, phi: Tensor, mask: Tensor, dense: int = 0) -> Tensor:
        """``Q [P, D]`` on ``mask [P, D]`` only (0 elsewhere); the first ``dense`` columns
        of every row always."""

    def q_value(self, phi: Tensor, decision: Tensor, index: Tensor | None = None) -> Tensor:
        """``Q(s_p, decision_p)``: ``[P]`` (or the rows ``index``)."""

    def set_values(self, mask: Tensor, value: Tensor) -> None:
        """``Q(s, d) = value[p, d]`` everywhere for the ``(p, d)`` in ``mask [P, D]`` (how
        discovery starts a joining option's value, with :meth:`fit_values` the only writes
        discovery makes)."""

    # Optional, for the default preset's ``value_start="agent"`` (``policy_start="top-level"``
    # asks the same of the option head): ``fit_values(mask [P, D], phi [N, F], values [P, N,
    # D])`` fits ``Q(s, d)`` to ``values`` on the states ``phi`` for the ``(p, d)`` in ``mask``
    # (MLPQHead, MLPOptionQHead and FourierOptionQHead have it). Both starts also read the
    # agent's values on the grid one agent at a time, through ``select_agents(index)`` (a head
    # of those agents). Without them, only ``value_start="max-sample"`` and
    # ``policy_start="zero"``, the paper's, take the head.

    def parameters(self, recurse: bool = True):
        """What an optimizer trains (``nn.Module``'s); the built-in linear head has none and
        is stepped in closed form by :class:`~skillchain_torch.objectives.SarsaUpdate`."""


@runtime_checkable
class Learner(Protocol):
    """A TD learning rule applied to a head: ``learner(head, ...) -> TD errors``.

    :class:`~skillchain_torch.objectives.SarsaUpdate` (SMDP Sarsa, the top level) and
    :class:`~skillchain_torch.objectives.IntraOptionQLearning` (each option) are the paper's.
    """

    def __call__(self, head: Any, *args: Tensor, **kwargs: Any) -> Tensor: ...


@runtime_checkable
class EpisodeAgent(Protocol):
    """P agents as a trainer drives them: compact rows of the active agents (ascending ids) in,
    primitive actions ``[n]`` out.

    The trainer calls :meth:`begin` at the start observations, then :meth:`observe` after each
    step in which no episode ended, or :meth:`observe_ends` after one in which some did (terminal
    updates do not bootstrap, truncated ones do; ``restart_rows`` then start again at
    ``start_obs``), and :meth:`compact` when agents finish their last episode. An agent run
    with an exploration schedule (``TrainConfig.epsilon_init``) also needs
    ``set_epsilon(epsilon)``, which the collector calls each population step; the built-in
    agents have it, and the collector refuses an agent without it in one line.

    Attributes:
        population (P).
    """

    population: int

    def begin(self, obs: Tensor) -> Tensor:
        """First actions ``[n]`` of the active agents at their start observations ``[n, D]``."""

    def observe(self, obs: Tensor, reward: Tensor) -> Tensor:
        """Learn from a step in which no episode ended (``obs [n, D]``, ``reward [n]``); the
        next actions ``[n]``."""

    def observe_ends(self, obs: Tensor, reward: Tensor, terminated: Tensor, truncated: Tensor,
                     restart_rows: Tensor, start_obs: Tensor | None) -> Tensor:
        """Learn from a step in which episodes ended; restart ``restart_rows`` (compact rows) at
        ``start_obs``; the next actions ``[n]``."""

    def compact(self, keep: Tensor) -> None:
        """Keep the active rows where ``keep [n]``; the others stop for good."""

    @property
    def actions(self) -> Tensor:
        """The primitive action of each active row ``[n]``."""

    @property
    def index(self) -> Tensor:
        """Ids of the active agents, ascending ``[n]``."""

    def flush(self) -> None:
        """Write back whatever a compiled step keeps apart (before reading the weights)."""

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> Any: ...


@runtime_checkable
class EnvStepper(Protocol):
    """The population's envs as the trainer steps them: compact rows of the active envs.

    Attributes:
        num_active: how many envs still step.
    """

    num_active: int

    def start(self) -> Tensor:
        """Reset every env; all active; observations ``[P, D]``."""

    def step(self, action: Tensor) -> tuple[Tensor, Tensor, tuple[Tensor, Tensor] | None]:
        """Step the active rows: ``(observation [n, D], reward [n], ends)``; ``ends`` is
        ``None`` when no episode ended, else ``(terminated, truncated)`` bool ``[n]``."""

    def reset(self, rows: Tensor) -> Tensor:
        """Restart the envs of compact ``rows``; their observations ``[len(rows), D]``."""

    def compact(self, keep: Tensor) -> None:
        """Keep only the rows where ``keep`` (bool ``[n]``); the others stop stepping."""

    def sync(self) -> None:
        """Write back whatever a compiled step keeps apart (before a checkpoint)."""

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


def missing_methods(piece: object, interface: type) -> list[str]:
    """The methods and attributes of ``interface`` that ``piece`` lacks, sorted.

    Example:
        >>> missing_methods(object(), ValueHead)
        ['forward', 'forward_mask', 'num_decisions', 'num_features', 'parameters', \
'population', 'q_value', 'set_values']
    """
    names = set(getattr(interface, "__protocol_attrs__", ()))
    if not names:  # Python < 3.12 keeps them elsewhere
        names = {n for n in vars(interface) if not n.startswith("_")}
        names |= set(getattr(interface, "__annotations__", {}))
    return sorted(n for n in names if not hasattr(piece, n))
