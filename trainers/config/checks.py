"""What :class:`~.config.TrainConfig` checks with, apart from the config itself: field types
(a ``config.json`` may hold anything), devices, and the sizes of a run's largest arrays.

Example:
    >>> type_problem("float | None", "0.1")
    'a number or null'
    >>> type_problem("int", 3) is None
    True
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
from pathlib import Path
from typing import Any

from skillchain_torch.discovery.subgoals import SUBGOALS
from skillchain_torch.options.goals import env_goal, goal_event
from skillchain_torch.presets import PRESET_FIELDS, preset_named
from skillchain_torch.resources import device_problem
from skillchain_torch.resources import format_bytes as _size

__all__ = ["ConfigError", "short", "type_problem", "check_values", "check_device",
           "check_memory", "memory_estimate", "INT64_MAX"]

# Integer fields are stored in int64 tensors and arrays; agent p's random streams are keyed by
# the int64 seed + p (CounterRNG, the initiation-set reservoirs, the environment's starts).
INT64_MAX = 2**63 - 1


class ConfigError(ValueError):
    """A ``ValueError`` from :meth:`TrainConfig.validate`; ``fields`` names the config fields
    at fault (so a front end can name its own flags)."""

    def __init__(self, message: str, fields: tuple[str, ...] = ()):
        super().__init__(message)
        self.fields = tuple(fields)


def short(value: Any, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def type_problem(kind: str, value: Any) -> str | None:
    """``None`` if ``value`` fits the annotation ``kind`` (``"int"``, ``"float | None"``, ...),
    else what it must be."""
    kinds = [k.strip() for k in kind.split("|")]
    optional = "None" in kinds
    base = next(k for k in kinds if k != "None")
    if value is None and optional:
        return None
    if base == "int":
        ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
        what = "an integer"
    elif base == "float":
        ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
        what = "a number"
    elif base == "bool":
        ok = isinstance(value, bool)
        what = "true or false"
    else:
        ok = isinstance(value, str) or (base == "str" and isinstance(value, os.PathLike)
                                        and optional)
        what = "a string"
    return None if ok else what + (" or null" if optional else "")


def check_device(device: str) -> None:
    """``ConfigError`` unless ``device`` names a torch device this machine has."""
    problem = device_problem(device)
    if problem is not None:
        raise ConfigError(problem, ("device",))


def memory_estimate(config) -> list[tuple[tuple[str, ...], str, int, bool]]:
    """Lower bounds of the bytes of ``config``'s largest arrays: ``(fields, what, bytes,
    on_device)`` per array family (``on_device``: torch tensors on ``device``; else numpy
    arrays in host memory). Sizes only: nothing is allocated.

    The returns and lengths (and skill chaining's option counts) are ``[runs, episodes]``
    int64/float64 arrays; the top-level Q weights and features take ``runs x (decisions
    + 1) x (order + 1)^4`` float64 (5 primitives, plus ``slots`` options in skill
    chaining); each skill-chaining option slot holds an order-3 Q-head (5 x 256 float64)
    and a 500-example initiation-set store (500 x 4 float64 and labels).
    """

    runs, episodes = int(config.runs), int(config.episodes)
    order = config.resolved().order
    chaining = config.agent == "skill-chaining"
    dim, actions = config.obs_dim or 4, config.num_actions or 5  # (None: Pinball's)
    decisions = actions + (int(config.slots) if chaining else 0)
    features = (order + 1) ** dim
    terms = [
        (("runs", "episodes"), "returns and lengths [runs, episodes]",
         runs * episodes * 8 * (3 if chaining else 2), False),
        (("runs", "order", "slots") if chaining else ("runs", "order"),
         "Q weights [runs, decisions, (order+1)^4 features]",
         runs * (decisions + 1) * features * 8 + features * 4 * 8, True),
    ]
    if chaining:
        per_slot = 5 * 256 * 8 + 500 * (4 * 8 + 1) + 15 * 8
        terms.append((("runs", "slots"), "option banks [runs, slots, ...]",
                      runs * int(config.slots) * per_slot, True))
        # the states of each agent's execution, kept for its outcome (ExecutionTrace)
        terms.append((("runs", "max_option_steps"), "execution traces [runs, max_option_steps, "
                       "obs dims]", runs * int(config.max_option_steps) * (dim + 1) * 8, True))
    return terms


def check_memory(config, available_memory, base_bytes: int) -> None:
    """``ConfigError`` naming the fields whose arrays would not fit in the memory available now
    (:func:`memory_estimate`, plus ``base_bytes`` for the interpreter on the CPU).
    ``available_memory(device)``: bytes free, or ``None`` when unknown (then no check)."""
    import torch

    terms = config.memory_estimate()
    on_cpu = torch.device(config.device).type == "cpu"
    pools = [(terms if on_cpu else [t for t in terms if not t[3]], "cpu")]
    if not on_cpu:
        pools.append(([t for t in terms if t[3]], config.device))
    for pool, device in pools:
        need = sum(t[2] for t in pool) + (base_bytes if device == "cpu" else 0)
        have = available_memory(device)
        if have is None or need <= have:
            continue
        fields, what, size, _ = max(pool, key=lambda t: t[2])
        values = config.resolved().to_dict()
        named = " x ".join(f"{f} {values[f]}" for f in fields)
        where = "memory" if device == "cpu" else f"{device} memory"
        raise ConfigError(
            f"the run needs an estimated {_size(need)} of {where} for {named} ({what}: "
            f"{_size(size)}), more than the {_size(have)} available", fields)


def check_values(config) -> None:
    """Raise :class:`ConfigError` naming the first field of ``config`` (a
    :class:`~.config.TrainConfig`) whose type or value is impossible: each field's type, its
    range (integers fit int64; agent p's seed ``seed + p`` is in [0, 2^63 - 1]), names that must
    be known, and the combinations that cannot run."""
    from skillchain_torch.agents.hierarchical import FAILURE_BOOTSTRAPS
    from skillchain_torch.agents.pieces import INITIATIONS, OPTION_HEADS, TOP_HEADS
    from skillchain_torch.discovery.gestation import POLICY_STARTS, VALUE_STARTS
    from skillchain_torch.envs.pinball import MAP_NAMES
    from skillchain_torch.trainers.config.registry import AGENTS

    preset = preset_named(config.preset)
    for field in dataclasses.fields(config):
        value, kind = getattr(config, field.name), str(field.type)
        if (field.name in PRESET_FIELDS and getattr(preset, field.name) is not None
                and not (value is None and config._per_env(field.name))):  # fmt: skip
            kind = kind.replace(" | None", "")  # None was the preset's value, filled in
        what = type_problem(kind, value)
        if what is not None:
            raise ConfigError(f"{field.name} must be {what}, got {short(value)}",
                              (field.name,))
    if config.agent not in AGENTS:
        raise ConfigError(f"agent must be one of {', '.join(AGENTS)}, got {config.agent!r}",
                          ("agent",))
    if config.env is None and config.map not in MAP_NAMES:
        raise ConfigError(f"unknown map {config.map!r}; known maps: {', '.join(MAP_NAMES)}")
    checks = [
        ("runs", config.runs, config.runs >= 1, ">= 1"),
        ("episodes", config.episodes, config.episodes >= 1, ">= 1"),
        ("epsilon", config.epsilon, 0.0 <= config.epsilon <= 1.0, "in [0, 1]"),
        ("gamma", config.gamma, 0.0 <= config.gamma <= 1.0, "in [0, 1]"),
        ("checkpoint_every", config.checkpoint_every, config.checkpoint_every >= 0, ">= 0"),
        ("checkpoint_minutes", config.checkpoint_minutes,
         math.isfinite(config.checkpoint_minutes) and config.checkpoint_minutes >= 0,
         ">= 0 and finite"),
        ("keep_checkpoints", config.keep_checkpoints, config.keep_checkpoints >= 0,
         ">= 0 (0: keep all)"),
        ("slots", config.slots, config.slots >= 1, ">= 1"),
        ("initiation_bias", config.initiation_bias, math.isfinite(config.initiation_bias),
         "finite"),
        ("failure_bootstrap", repr(config.failure_bootstrap),
         config.failure_bootstrap in FAILURE_BOOTSTRAPS,
         f"one of {', '.join(FAILURE_BOOTSTRAPS)}"),
        ("value_bonus", config.value_bonus, math.isfinite(config.value_bonus), "finite"),
        ("gestation", config.gestation, 0 <= config.gestation <= 1_000_000, "in [0, 10^6]"),
        ("max_branching", config.max_branching, config.max_branching >= 0, ">= 0"),
        ("max_option_steps", config.max_option_steps,
         1 <= config.max_option_steps <= 1_000_000, "in [1, 10^6]"),
        ("convergence_threshold", config.convergence_threshold,
         math.isfinite(config.convergence_threshold) and config.convergence_threshold > 0,
         "finite and > 0"),
        ("option_alpha", config.option_alpha, config.option_alpha is None  # (resolved later)
         or (math.isfinite(config.option_alpha) and config.option_alpha >= 0), ">= 0 and finite"),
        ("completion_reward", config.completion_reward,
         math.isfinite(config.completion_reward), "finite"),
        ("value_start", repr(config.value_start), config.value_start in VALUE_STARTS,
         f"one of {', '.join(VALUE_STARTS)}"),
        ("policy_start", repr(config.policy_start), config.policy_start in POLICY_STARTS,
         f"one of {', '.join(POLICY_STARTS)}"),
        ("top_lr", config.top_lr, math.isfinite(config.top_lr) and config.top_lr > 0,
         "> 0 and finite"),
        ("top_target_update", config.top_target_update, config.top_target_update >= 1, ">= 1"),
        ("top_bootstrap", repr(config.top_bootstrap), config.top_bootstrap in ("max", "sarsa"),
         "one of max, sarsa"),
        ("epsilon_init", config.epsilon_init, config.epsilon_init is None
         or 0.0 <= config.epsilon_init <= 1.0, "in [0, 1]"),
        ("annealing_steps", config.annealing_steps, config.annealing_steps >= 1
         if config.epsilon_init is not None else config.annealing_steps == 0,
         ">= 1 with epsilon_init and 0 without (epsilon_init and annealing_steps go together)"),
        *((name, repr(getattr(config, name)), getattr(config, name) in known,
           f"one of {', '.join(sorted(known))}") for name, known in (
            ("top_head", TOP_HEADS), ("option_head", OPTION_HEADS),
            ("initiation", INITIATIONS), ("subgoals", SUBGOALS))),
    ]
    if config.agent == "skill-chaining" and config.policy_start == "top-level-shifted" and (
            "fourier" != config.top_head or "fourier" != config.option_head):  # fmt: skip
        raise ConfigError(f"policy_start 'top-level-shifted' needs Fourier heads (its shift reads "
                          f"the linear values), got top_head {config.top_head!r} and "
                          f"option_head {config.option_head!r}: use --policy-start top-level",
                          ("policy_start", "top_head", "option_head"))  # fmt: skip
    if config.agent == "skill-chaining" and config.goal is None and env_goal(config.env) is None:
        raise ConfigError(f"env {config.env} terminates only in failure (its last reward is "
                          "positive too), so no termination is a goal for skill chaining: pass "
                          "--goal MODULE:FUNCTION, a function of the transition's TensorDict "
                          "that holds where success is", ("goal",))  # fmt: skip
    if config.goal is not None:
        try:
            goal_event(config.goal)
        except ValueError as err:
            raise ConfigError(str(err), ("goal",)) from None
    if config.options_agent is not None:
        checks.append(("options_agent", config.options_agent, config.options_agent >= 0, ">= 0"))
    if config.alpha is not None:
        ok = math.isfinite(config.alpha) and config.alpha > 0
        checks.append(("alpha", config.alpha, ok, "> 0 and finite"))
    if config.order is not None:
        checks.append(("order", config.order, config.order >= 0, ">= 0"))
    if config.max_episode_steps is not None:
        checks.append(
            ("max_episode_steps", config.max_episode_steps, config.max_episode_steps >= 1, ">= 1")
        )
    if config.agent == "given-options":
        if config.options is None:
            raise ConfigError(
                "agent 'given-options' needs options: an OptionBank file (--options)",
                ("options",),
            )
        if not Path(config.options).is_file():
            raise ConfigError(f"options file {config.options!r} does not exist", ("options",))
    for name, value, ok, rule in checks:
        if not ok:
            raise ConfigError(f"{name} must be {rule}, got {value}", (name,))
    for field in dataclasses.fields(config):
        value = getattr(config, field.name)
        if (field.name != "seed" and isinstance(value, numbers.Integral)
                and not isinstance(value, bool) and value > INT64_MAX):
            raise ConfigError(f"{field.name} must be at most 2^63 - 1 = {INT64_MAX} (an "
                              f"int64), got {value}", (field.name,))  # fmt: skip
    if not 0 <= config.seed <= INT64_MAX - (config.runs - 1):
        raise ConfigError(
            f"seed must be in [0, {INT64_MAX - (config.runs - 1)}] (agent p uses seed + p, "
            f"an int64 random-stream key, p < runs = {config.runs}), got {config.seed}",
            ("seed",),
        )
    try:
        reading = config.reading
    except ValueError as err:
        message = str(err).replace("reading start", "initiation_start").replace(
            "reading constrain", "initiation_constrain").replace(
            "reading gestation_positives", "gestation_positives")
        fields = tuple(n for n in ("initiation_start", "initiation_constrain",
                                   "gestation_positives", "one_class_fits") if n in message)
        raise ConfigError(message, fields) from None
    if reading.start == "biased" and not config.initiation_bias > 0:
        raise ConfigError(f"initiation_start 'biased' needs initiation_bias > 0, got "
                          f"{config.initiation_bias}", ("initiation_start", "initiation_bias"))
