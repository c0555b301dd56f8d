"""The Pinball domain (Konidaris & Barto, 2009), faithful to the original Java implementation.

Example:
    >>> import torch
    >>> from skillchain_torch.envs.pinball import PinballEnv
    >>> env = PinballEnv("pinball_simple_single", batch_size=[4], seed=0)
    >>> td = env.rollout(10)
    >>> td["next", "state"].shape
    torch.Size([4, 10, 4])
"""

from .env import PinballEnv
from .gym_adapter import GYM_IDS, GymPinballEnv, register_gym_envs
from .maps import MAP_NAMES, PinballMap, load_map
from .physics import ACTION_NAMES, NUM_ACTIONS, observation, pinball_step, pinball_step_events
from .render import plot_trajectories, render_frame

register_gym_envs()

__all__ = [
    "PinballEnv",
    "GymPinballEnv",
    "GYM_IDS",
    "render_frame",
    "plot_trajectories",
    "MAP_NAMES",
    "PinballMap",
    "load_map",
    "pinball_step",
    "pinball_step_events",
    "observation",
    "NUM_ACTIONS",
    "ACTION_NAMES",
]
