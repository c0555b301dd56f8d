"""Environments for skillchain_torch (installed as ``skillchain_torch.envs``).

The Pinball domain's public names are importable from here; they load on first use, so
``import skillchain_torch`` (which registers the Gymnasium ids through :mod:`.registration`)
does not import torch.

Example:
    >>> from skillchain_torch.envs import PinballEnv
    >>> PinballEnv("pinball_box", batch_size=[2], seed=0).batch_size
    torch.Size([2])
"""

from __future__ import annotations

import importlib

__all__ = [
    "pinball",
    "PinballEnv",
    "GymPinballEnv",
    "GYM_IDS",
    "MAP_NAMES",
    "PinballMap",
    "load_map",
    "pinball_step",
    "render_frame",
    "plot_trajectories",
]


def __getattr__(name: str):
    if name == "pinball":
        return importlib.import_module(".pinball", __name__)
    if name in __all__:
        return getattr(importlib.import_module(".pinball", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
