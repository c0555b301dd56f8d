"""A Gymnasium view of one Pinball environment, registered once per shipped map.

Ids: ``skillchain_torch/Pinball-SimpleSingle-v0``, ``-HardSingle-v0``, ``-HardTwoStarts-v0``,
``-Medium-v0``, ``-Box-v0`` and ``-Empty-v0`` (``import skillchain_torch`` registers them:
see :mod:`skillchain_torch.envs.registration`).

Observations are the Java descriptor (x, y, (xdot + 1) / 2, (ydot + 1) / 2) in
``Box(0, 1, (4,), float64)``. Why clipped: right after a reflection a velocity component can
exceed 1 in magnitude until the next step's clip, so the raw descriptor can leave [0, 1] by up
to 0.21; the adapter clips it to honour the declared space. The unclipped raw state is in
``info["state"]``, and :class:`~.env.PinballEnv` reports it unclipped.

Example:
    >>> import gymnasium as gym
    >>> import skillchain_torch  # registers the ids
    >>> env = gym.make("skillchain_torch/Pinball-SimpleSingle-v0")
    >>> obs, info = env.reset(seed=0)
    >>> obs.tolist()
    [0.2, 0.9, 0.5, 0.5]
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces

from ..registration import GYM_IDS, register_gym_envs
from .grid import check_grid_size
from .maps import PinballMap, load_map
from .physics import NUM_ACTIONS, pinball_step
from .render import render_frame

__all__ = ["GymPinballEnv", "GYM_IDS", "register_gym_envs"]




class GymPinballEnv(gym.Env):
    """One Pinball environment with the Gymnasium API (CPU, float64).

    Args:
        map: a shipped map name or a :class:`~.maps.PinballMap`.
        render_mode: ``"rgb_array"`` or ``None``.
        max_episode_steps: use ``gym.make(..., max_episode_steps=N)`` (TimeLimit) instead.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, map: str | PinballMap = "pinball_simple_single", render_mode=None):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.pinball_map = map if isinstance(map, PinballMap) else load_map(map)
        check_grid_size(self.pinball_map)  # refuse a map too large to simulate, up front
        self.render_mode = render_mode
        self.observation_space = spaces.Box(0.0, 1.0, shape=(4,), dtype=np.float64)
        self.action_space = spaces.Discrete(NUM_ACTIONS)
        # None until the first reset: step() refuses to move a ball that was never placed
        # (gym.make's OrderEnforcing wrapper says so too, but the unwrapped env is public).
        self._state = None

    def _obs(self) -> np.ndarray:
        x, y, vx, vy = self._state[0].tolist()
        obs = np.array([x, y, (vx + 1.0) / 2.0, (vy + 1.0) / 2.0], dtype=np.float64)
        return np.clip(obs, 0.0, 1.0)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        starts = self.pinball_map.starts
        start = starts[int(self.np_random.integers(starts.shape[0]))]
        self._state = torch.cat([start, torch.zeros(2, dtype=torch.float64)])[None]
        return self._obs(), {"state": self._state[0].numpy().copy()}

    def step(self, action):
        if self._state is None:
            raise RuntimeError(
                "GymPinballEnv: call reset() before step(): the ball has not been placed yet"
            )
        act = torch.tensor([_check_action(action)], dtype=torch.int64)
        self._state, reward, terminated = pinball_step(self._state, act, self.pinball_map)
        info = {"state": self._state[0].numpy().copy()}
        return self._obs(), float(reward[0]), bool(terminated[0]), False, info

    def render(self):
        if self.render_mode == "rgb_array":
            if self._state is None:
                raise RuntimeError("GymPinballEnv: call reset() before render()")
            return render_frame(self.pinball_map, self._state[0])
        return None


def _check_action(action) -> int:
    """The action as an int in 0..4; ``TypeError`` for anything but an integer (a Python or
    NumPy integer, or a 0-d integer array), ``ValueError`` out of range.

    Why bools are refused although ``True == 1``: ``Discrete.contains(True)`` accepts them, and
    a bool reaching ``step`` is almost always a mask or a done flag passed by mistake.

    Example:
        >>> _check_action(np.int64(3))
        3
        >>> _check_action(True)
        Traceback (most recent call last):
        ...
        TypeError: action must be an integer in 0..4, got True (bool)
    """
    if isinstance(action, np.ndarray) and action.shape == ():
        action = action[()]
    if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
        raise TypeError(
            f"action must be an integer in 0..{NUM_ACTIONS - 1}, got {action!r} "
            f"({type(action).__name__})"
        )
    if not 0 <= action < NUM_ACTIONS:
        raise ValueError(
            f"action must be an integer in 0..{NUM_ACTIONS - 1}, got {action!r} (out of range)"
        )
    return int(action)


