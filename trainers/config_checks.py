"""What :class:`~.config.TrainConfig` checks with, apart from the config itself: field types
(a ``config.json`` may hold anything), devices, and the sizes of a run's largest arrays.

Example:
    >>> type_problem("float | None", "0.1")
    'a number or null'
    >>> type_problem("int", 3) is None
    True
"""

from __future__ import annotations

import numbers
import os
from typing import Any

from skillchain_torch.resources import device_problem
from skillchain_torch.resources import format_bytes as _size

__all__ = ["ConfigError", "short", "type_problem", "check_device", "check_memory",
           "memory_estimate"]


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
