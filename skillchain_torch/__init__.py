"""Skill chaining (Konidaris & Barto, 2009) as TorchRL-style PyTorch components.

Importing the package is light (no torch): it registers the Pinball maps' Gymnasium ids and
loads each subpackage on first use (``skillchain_torch.agents``, ...).

Example:
    >>> import gymnasium as gym
    >>> import skillchain_torch
    >>> env = gym.make("skillchain_torch/Pinball-SimpleSingle-v0")
    >>> env.reset(seed=0)[0].tolist()
    [0.2, 0.9, 0.5, 0.5]
    >>> skillchain_torch.agents.SkillChainingAgent.__name__
    'SkillChainingAgent'
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

# The subpackages (``envs`` and ``trainers`` come from the top-level folders of the same names,
# mapped into the package by pyproject).
__all__ = [
    "agents",
    "backends",
    "collectors",
    "discovery",
    "envs",
    "features",
    "modules",
    "objectives",
    "options",
    "policies",
    "trainers",
]


def __getattr__(name: str):
    if name in __all__:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


def _register_gym_ids() -> None:
    from .envs.registration import register_gym_envs

    try:
        register_gym_envs()
    except ModuleNotFoundError as err:
        # Gymnasium is a dependency, but the library's torch pieces work without it: an
        # environment lacking it imports the package, without the ids.
        if err.name != "gymnasium":
            raise


_register_gym_ids()
