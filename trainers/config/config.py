"""``TrainConfig``: everything that defines a training run, validated in one place.

The learning values come from a named preset (:mod:`skillchain_torch.presets`; ``preset``,
``"default"`` or ``"paper"``): every field the preset sets and the config leaves ``None`` takes
the preset's value when the config is made, and a value given explicitly wins. Both presets
take the top level from the paper's section 5.1: Sarsa (gamma = 1, epsilon = 0.01) over a
Fourier basis of order 4, alpha = 0.001, on the first instance (simple maps), order 5, alpha =
0.0005, on the second (maps named ``"hard"``). ``order`` and ``alpha`` left ``None`` (and off
Pinball ``option_alpha``) are filled per environment by :meth:`TrainConfig.resolved`.

Example:
    >>> cfg = TrainConfig(map="pinball_hard_single", runs=4, episodes=10).resolved()
    >>> cfg.order, cfg.alpha, cfg.gamma, cfg.epsilon
    (5, 0.0005, 1.0, 0.01)
    >>> TrainConfig().gestation, TrainConfig(preset="paper").gestation
    (2, 10)
    >>> TrainConfig(preset="paper", gestation=4).gestation  # explicit values win
    4
    >>> try:
    ...     TrainConfig(runs=0).validate()
    ... except ValueError as err:  # a ConfigError, naming the fields at fault
    ...     print(err, err.fields)
    runs must be >= 1, got 0 ('runs',)
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from skillchain_torch.discovery.readings import InitiationReading
from skillchain_torch.presets import (
    PRESET_FIELDS,
    TOP_LEARNER,
    env_values,
    instance_defaults,
    instance_slots,
    preset_named,
)
from skillchain_torch.resources import available_memory
from skillchain_torch.trainers.config.checks import (
    INT64_MAX,
    ConfigError,
    check_device,
    check_memory,
    check_values,
    memory_estimate,
)
from skillchain_torch.trainers.config.fields import (
    LABEL_FIELDS,
    LEGACY_FIELDS,
    MLP_TOP_FIELDS,
    RESUME_FIELDS,
    UNREAD_FIELDS,
)

__all__ = ["TrainConfig", "ConfigError", "paper_defaults", "available_memory", "RESUME_FIELDS",
           "LEGACY_FIELDS", "UNREAD_FIELDS", "LABEL_FIELDS", "PRESET_CONFIG_FIELDS", "INT64_MAX"]

DEFAULT_MAP = "pinball_simple_single"  # the map of a config that names no environment


def paper_defaults(map_name: str) -> tuple[int, float]:
    """``(order, alpha)`` of the paper for a map: (5, 0.0005) on hard maps, else (4, 0.001)."""
    return instance_defaults(map_name)


# Memory a run needs besides its largest arrays (torch, the interpreter, buffers).
_BASE_BYTES = 256 * 2**20


@dataclass(frozen=True)
class TrainConfig:
    """A population training run.

    Fields marked (preset) default to ``None``, which takes the value of ``preset`` when the
    config is made (:mod:`skillchain_torch.presets` gives both presets' values and why they
    differ); ``dataclasses.replace(cfg, preset=...)`` keeps the values already filled in.

    Args:
        agent: registry name of the agent (``"flat"``, ``"given-options"``,
            ``"skill-chaining"``; see ``skillchain_torch.trainers.AGENTS``).
        preset: ``"default"`` (the library's) or ``"paper"`` (section 5.1's values).
        map: a shipped Pinball map name (``MAP_NAMES``; ``None``: pinball_simple_single, or
            no map when ``env`` is set, so an env run's config records none).
        runs: P, the number of independent agents (each with its own environment).
        episodes: E, the episodes each agent runs.
        seed: agent ``p`` (and its environment) uses seed ``seed + p``.
        alpha: Sarsa step size (``None``: paper value for the map).
        epsilon: (preset) exploration probability of epsilon-greedy, in [0, 1].
        gamma: (preset) discount, in [0, 1].
        order: Fourier basis order over the 4-d observation (``None``: paper value).
        scale_step_size: (preset) per-feature step sizes ``alpha / ||c_i||`` (Konidaris et al.
            2011).
        max_episode_steps: truncate episodes after this many steps (``None``: never). A
            truncated episode bootstraps from its last state (it is not a termination).
        options: OptionBank file of given options (``--agent given-options``).
        options_agent: which saved agent's options every given-options agent starts with;
            ``None``: agent p takes saved agent ``p mod N`` (the paper's Figure 4 set-up,
            each agent given the options one skill-chaining run discovered).
        slots: (preset) K, option slots per agent of ``--agent skill-chaining`` (when all are
            used the agent creates no more options); the presets leave it to the map: 48 on
            the hard instance, else 12 (:func:`~skillchain_torch.presets.instance_slots`).
        initiation_bias, initiation_centered: (preset) the initiation classifiers'
            ``initial_bias`` and ``centered`` (see
            :class:`~skillchain_torch.options.InitiationClassifier`).
        gestation_positives, initiation_start, initiation_constrain, one_class_fits: (preset)
            the initiation-set reading of skill chaining (see
            :class:`~skillchain_torch.discovery.InitiationReading`; default preset
            ``pos20-fitted-cstart``, ``results/screening/README.md``).
        failure_bootstrap, intra_option_primitives, intra_option_target: (preset) see
            :class:`~skillchain_torch.agents.HierarchicalAgent`'s arguments of those names.
        option_interruption, end_outside_set: (preset) ``interruption`` and
            ``end_outside_set`` of :class:`~skillchain_torch.agents.HierarchicalAgent`.
        keep_negatives, store_failures, constrain_nearest: (preset) see
            :class:`~skillchain_torch.options.InitiationClassifier`'s arguments of those names.
        policy_start: (preset) how a joining option's policy starts (``"zero"``: gestation's
            updates of zero weights; ``"top-level"``: the agent's own primitive values
            projected onto the option's basis; ``"top-level-shifted"``: that copy on the
            option's own scale; see :class:`~skillchain_torch.discovery.
            SkillChaining`).
        option_alpha: (preset) the options' Q-learning step size (paper: ``alpha_o =
            0.0005``; off Pinball scaled to the env's option basis unless given, see
            :func:`~skillchain_torch.presets.env_option_alpha`); given options keep the step
            size of the run that discovered them.
        completion_reward: (preset) ``C``, added to an option's reward when its target fires
            (the paper does not give it; 10,000 is the task's goal reward).
        value_start, value_bonus: (preset) how ``Q(s, o)`` starts when an option joins (see
            :class:`~skillchain_torch.discovery.SkillChaining`).
        max_option_steps: (preset) an execution gives up after this many steps (paper: 250,
            section 5.1), and counts as a failure.
        gestation: (preset) episodes a new option gestates before it joins the repertoire
            (paper: 10; default 2, ``results/chain-growth/``).
        convergence_threshold: (preset) an initiation set is learned (and becomes a target
            event) when its classifier's weights moved on average less than this per episode,
            twice in a row (paper: 0.15).
        max_branching: (preset) options per target event (paper: 3; 0 creates none: the
            same agent and learners without options, a flat baseline for any head).
        goal: the goal event (:mod:`skillchain_torch.options.goals`): ``"terminated"``,
            ``"terminated-positive"`` or ``"MODULE:FUNCTION"`` of the transition's TensorDict
            (``None``: the env's own, :func:`~skillchain_torch.options.goals.env_goal`; an env
            whose termination means failure, CartPole, needs one for skill chaining).
        subgoals: (preset) where new options aim: ``"chained"`` (the paper's: the sets of the
            options already there) or ``"random"`` (issue 52's control: the goal and
            ``slots - 1`` random discs, :mod:`skillchain_torch.discovery.subgoals`).
        env: ``None`` for Pinball (``map``), else ``"gymnasium:ID"`` (a bare ``"ID"`` is
            read as Gymnasium's) or
            ``"gymnasium:MODULE:ID"``: a Gymnasium env through TorchRL's ``GymEnv`` (see
            :mod:`skillchain_torch.envs.external`).
        obs_bounds: ``"LOW:HIGH,..."`` per observation dim, where the env's spec has no
            finite bounds (``None``: the spec's).
        obs_dim, num_actions: the env's observation size and action count, read from its
            specs when the trainer starts (``None``: Pinball's 4 and 5).
        top_head, option_head, initiation: the skill-chaining agent's pieces by name
            (:mod:`skillchain_torch.agents.pieces`): the paper's ``"fourier"``, ``"fourier"``,
            ``"logistic"``, or ``"mlp"`` for each (neural).
        top_lr, top_target_update, top_bootstrap: the ``"mlp"`` top level's learner: Adam's
            step size, optimizer steps between target copies, ``"max"`` (DQN's target) or
            ``"sarsa"`` (:data:`~skillchain_torch.presets.TOP_LEARNER`).
        epsilon_init, annealing_steps: the agent (skill chaining's and given options' top level,
            flat's policy) explores at ``epsilon_init`` at its first step, annealed linearly to
            ``epsilon`` over ``annealing_steps`` agent steps
            (:class:`~skillchain_torch.policies.LinearEpsilon`); ``None``: ``epsilon``
            throughout, as the paper.
        checkpoint_every: write a checkpoint each time the slowest agent completes a multiple of
            this many episodes (0: only at the end).
        checkpoint_minutes: also write one when this many minutes of training have passed since
            the last (0: never), so a killed run loses at most that much whatever its episodes'
            lengths (hard Pinball's first episodes take an agent tens of minutes).
        keep_checkpoints: keep only the newest N checkpoints a process wrote (and the newest
            written before any agent finished, from which ``--resume --episodes`` extends the
            run); 0: keep all. A neural run's checkpoint holds its replay memories (0.2-0.7 GB
            each), so 300 episodes at one every 10 fill tens of GB.
        device: torch device of the run.
    """

    agent: str = "flat"
    preset: str = "default"
    map: str | None = None
    runs: int = 1
    episodes: int = 100
    seed: int = 0
    alpha: float | None = None
    epsilon: float | None = None
    gamma: float | None = None
    order: int | None = None
    scale_step_size: bool | None = None
    max_episode_steps: int | None = None
    checkpoint_every: int = 25
    checkpoint_minutes: float = 30.0
    keep_checkpoints: int = 0
    device: str = "cpu"
    options: str | None = None
    options_agent: int | None = 0
    slots: int | None = None
    initiation_bias: float | None = None
    initiation_centered: bool | None = None
    gestation_positives: int | None = None
    initiation_start: str | None = None
    initiation_constrain: str | None = None
    one_class_fits: bool | None = None
    failure_bootstrap: str | None = None
    keep_negatives: bool | None = None
    store_failures: bool | None = None
    constrain_nearest: bool | None = None
    intra_option_primitives: bool | None = None
    intra_option_target: str | None = None
    option_interruption: bool | None = None
    end_outside_set: str | None = None
    policy_start: str | None = None
    option_alpha: float | None = None
    completion_reward: float | None = None
    value_start: str | None = None
    value_bonus: float | None = None
    gestation: int | None = None
    max_option_steps: int | None = None
    convergence_threshold: float | None = None
    max_branching: int | None = None
    subgoals: str | None = None
    goal: str | None = None

    env: str | None = None
    obs_bounds: str | None = None
    obs_dim: int | None = None
    num_actions: int | None = None
    top_head: str = "fourier"
    option_head: str = "fourier"
    initiation: str = "logistic"
    top_lr: float = TOP_LEARNER["lr"]
    top_target_update: int = TOP_LEARNER["target_update"]
    top_bootstrap: str = TOP_LEARNER["bootstrap"]
    epsilon_init: float | None = None
    annealing_steps: int = 0

    def __post_init__(self):
        if isinstance(self.env, str) and self.env and ":" not in self.env:
            # A bare Gymnasium id (CartPole-v1) is Gymnasium's: recorded with its prefix.
            object.__setattr__(self, "env", "gymnasium:" + self.env)
        if self.env is None and self.map is None:
            object.__setattr__(self, "map", DEFAULT_MAP)
        elif self.env is not None and self.map is not None:
            raise ConfigError(f"env {self.env!r} and map {self.map!r} choose the environment "
                              "twice: give one (map is Pinball's)", ("map",))
        # Fill what the config leaves open from its preset, so every reader sees values.
        try:
            preset = preset_named(self.preset)
        except ValueError as err:
            raise ConfigError(str(err), ("preset",)) from None
        for name in PRESET_CONFIG_FIELDS:
            if getattr(self, name) is None and not self._per_env(name):
                object.__setattr__(self, name, getattr(preset, name))
        if self.slots is None:  # the presets leave it to the map (48 on the hard instance)
            object.__setattr__(self, "slots", instance_slots(self.map))

    def _per_env(self, name: str) -> bool:  # left None until resolved() knows the env's size
        return name == "option_alpha" and self.env is not None

    @property
    def env_name(self) -> str:
        """The environment, for display and for saved options: ``env`` or the Pinball map."""
        return self.map if self.env is None else self.env

    @property
    def reading(self):
        """The :class:`~skillchain_torch.discovery.InitiationReading` of these fields."""
        return InitiationReading(self.gestation_positives, self.initiation_start,
                                 self.initiation_constrain, self.one_class_fits)

    def resolved(self) -> TrainConfig:
        """A copy with ``order`` and ``alpha`` set (the paper's values where ``None``; off
        Pinball, :func:`~skillchain_torch.presets.env_values`, with ``option_alpha``)."""
        order, alpha = paper_defaults(self.map)
        option_alpha = self.option_alpha
        if self.env is not None:  # from the env's size; an option_alpha given is kept
            order, alpha, scaled = env_values(preset_named(self.preset), self.obs_dim or 4,
                                              self.order)  # fmt: skip
            option_alpha = scaled if option_alpha is None else option_alpha
        return dataclasses.replace(
            self,
            order=order if self.order is None else int(self.order),
            alpha=alpha if self.alpha is None else float(self.alpha),
            option_alpha=option_alpha,
        )

    def validate(self, memory: bool = True) -> TrainConfig:
        """Raise :class:`ConfigError` (a ``ValueError``) naming the first impossible field;
        returns ``self``.

        Checks each field's type (a ``config.json`` may hold anything), its range (integers
        fit int64; agent p's seed ``seed + p`` is in [0, 2^63 - 1]), that ``device`` exists
        here, and, with ``memory``, that the run's largest arrays (:meth:`memory_estimate`)
        fit in the memory available now.
        """
        check_values(self)
        check_device(self.device)
        if memory:
            check_memory(self, available_memory, _BASE_BYTES)  # (tests patch the reader here)
        return self

    def memory_estimate(self) -> list[tuple[tuple[str, ...], str, int, bool]]:
        """The run's largest arrays, ``(fields, what, bytes, on_device)`` each (sizes only;
        see :func:`~.config_checks.memory_estimate`)."""
        return memory_estimate(self)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        """Build from a dict (e.g. ``config.json``); unknown keys raise ``ValueError``."""
        names = {f.name for f in dataclasses.fields(cls)}
        if str(data.get("agent", "")).startswith("user:"):  # .user_agent.recorded_config
            raise ValueError(f"the run's agent ({data['agent'][5:]}) was built in Python, not "
                             "by name: rebuild it and resume with resume_checkpoint(DIR, "
                             "PopulationTrainer(config, out_dir=DIR, agent=agent))")
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"unknown config fields: {', '.join(unknown)}")
        if data.get("env") is not None:  # env runs saved the unread default map until 2026-12
            data = {**data, "map": None}
        return cls(**{**LEGACY_FIELDS, **data})

    def save_json(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load_json(cls, path: str | Path) -> TrainConfig:
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise ValueError(f"{path}: cannot read the run config ({err})") from None
        if not isinstance(data, dict):
            raise ValueError(f"{path}: the run config must be a JSON object")
        try:
            return cls.from_dict(data)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{path}: {err}") from None

    def mismatches(self, other: TrainConfig) -> list[str]:
        """Fields whose values differ between two resolved configs, leaving out
        ``RESUME_FIELDS``, the ``preset`` label (``LABEL_FIELDS``) and, when both are of one
        agent kind, the fields that kind never reads (``UNREAD_FIELDS``; with a Fourier top
        level on both, the MLP top level's learner, ``MLP_TOP_FIELDS``)."""
        a, b = self.resolved().to_dict(), other.resolved().to_dict()
        unread = UNREAD_FIELDS.get(self.agent, ()) if self.agent == other.agent else ()
        if a["top_head"] == b["top_head"] == "fourier":
            unread = (*unread, *MLP_TOP_FIELDS)
        skip = (*RESUME_FIELDS, *LABEL_FIELDS, *unread)
        return [k for k in a if k not in skip and a[k] != b[k]]


# TrainConfig's fields a preset fills when left None (order and alpha stay None in both
# presets: resolved() fills them per map).
PRESET_CONFIG_FIELDS = tuple(f.name for f in dataclasses.fields(TrainConfig)
                             if f.name in PRESET_FIELDS)
