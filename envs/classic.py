"""Batched classic-control envs: a population's envs stepped in one call, the same numbers as
Gymnasium's (issue 53).

The general stepper (:class:`~skillchain_torch.trainers.loop.env_stepper.EnvStepper`) steps one
TorchRL ``GymEnv`` per agent, and on MountainCar that loop is most of a run's time (12.5 of
20 s in ``benchmarks/neural_speed.py``). :class:`MountainCarStepper` steps every agent's car
at once, with Gymnasium's ``MountainCarEnv.step`` arithmetic in float64, and gives the same
observations, rewards and ends bit for bit (``tests/envs/test_classic.py`` checks it against
the ``GymEnv`` stepper step for step):

* ``cos(3 x)`` is NumPy's, which rounds as Python's ``math.cos`` does in Gymnasium (torch's
  vectorised ``cos`` differs in the last bit on about 0.2% of arguments);
* agent p's resets draw from its own ``np_random(seed + p)``, as ``GymEnv.set_seed`` seeds it
  (that first seeding reset draws once), so agent p alone equals agent p in a population;
* observations are cast to float32, as Gymnasium returns them, then mapped onto the unit box
  by the spec's bounds; Gymnasium's ``TimeLimit`` (200 steps) truncates.

Its state (positions, velocities, step counts and each agent's generator) is saved, so a run
on it resumes from a checkpoint, which the ``GymEnv`` stepper cannot.

:func:`batched_stepper` is the one place that picks it: for ``gymnasium:MountainCar-v0`` it
returns this stepper, for any other env ``None`` (the general stepper).

Example:
    >>> from skillchain_torch.envs.external import make_env, read_specs
    >>> sizes = read_specs(make_env("gymnasium:MountainCar-v0"))
    >>> cars = MountainCarStepper(3, sizes, seed=0)
    >>> obs = cars.start()
    >>> obs.shape, bool(((obs >= 0) & (obs <= 1)).all())
    (torch.Size([3, 2]), True)
    >>> obs, reward, ends = cars.step(torch.tensor([0, 1, 2]))
    >>> reward.tolist(), ends
    ([-1.0, -1.0, -1.0], None)
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

__all__ = ["MountainCarStepper", "batched_stepper", "BATCHED_IDS"]


class MountainCarStepper:
    """P MountainCar-v0 envs stepped as one batch (the ``EnvStepper`` protocol).

    Args:
        population: P, one car per agent.
        sizes: the env's :class:`~skillchain_torch.envs.external.EnvSizes` (from its specs).
        seed: agent p's car draws its starts from ``np_random(seed + p)``.
        max_episode_steps: truncate after this many steps as well (``None``: Gymnasium's 200
            alone).
    """

    # gymnasium.envs.classic_control.MountainCarEnv's constants
    MIN_POSITION, MAX_POSITION, MAX_SPEED = -1.2, 0.6, 0.07
    GOAL_POSITION, GOAL_VELOCITY, FORCE, GRAVITY = 0.5, 0.0, 0.001, 0.0025
    TIME_LIMIT = 200  # MountainCar-v0's TimeLimit

    def __init__(self, population: int, sizes, seed: int = 0,
                 max_episode_steps: int | None = None):  # fmt: skip
        from gymnasium.utils.seeding import np_random

        self.population, self.sizes = int(population), sizes
        self.max_episode_steps = max_episode_steps
        self.rngs = [np_random(int(seed) + p)[0] for p in range(self.population)]
        for rng in self.rngs:  # GymEnv.set_seed resets once with the seed: that draw is spent
            rng.uniform(low=-0.6, high=-0.4)
        self.position = np.zeros(self.population, dtype=np.float64)
        self.velocity = np.zeros(self.population, dtype=np.float64)
        self._count = np.zeros(self.population, dtype=np.int64)
        self.index = torch.arange(self.population)

    @property
    def num_active(self) -> int:
        return int(self.index.numel())

    def _obs(self, rows: np.ndarray) -> Tensor:
        state = np.stack([self.position[rows], self.velocity[rows]], axis=1).astype(np.float32)
        return self.sizes.scale(torch.from_numpy(state))

    def _reset_rows(self, rows: np.ndarray) -> None:
        for p in rows.tolist():  # each car from its own generator, as MountainCarEnv.reset
            self.position[p] = self.rngs[p].uniform(low=-0.6, high=-0.4)
            self.velocity[p] = 0.0
            self._count[p] = 0

    def start(self) -> Tensor:
        """Reset every car; all active; observations ``[P, 2]`` in the unit box."""
        self.index = torch.arange(self.population)
        rows = np.arange(self.population)
        self._reset_rows(rows)
        return self._obs(rows)

    def step(self, action: Tensor):
        """Step the active rows: ``(observation [n, 2], reward [n], ends)``; ``ends`` is
        ``None`` when no episode ended, else ``(terminated, truncated)`` bool ``[n]``."""
        rows = self.index.numpy()
        a = action.detach().to("cpu", torch.int64).numpy()
        x, v = self.position[rows], self.velocity[rows]
        # Gymnasium's order: v += (a - 1) * force + cos(3 x) * (-gravity), then the clips.
        v = v + ((a - 1) * self.FORCE + np.cos(3 * x) * (-self.GRAVITY))
        v = np.clip(v, -self.MAX_SPEED, self.MAX_SPEED)
        x = np.clip(x + v, self.MIN_POSITION, self.MAX_POSITION)
        v = np.where((x == self.MIN_POSITION) & (v < 0), 0.0, v)
        self.position[rows], self.velocity[rows] = x, v
        self._count[rows] += 1
        terminated = (x >= self.GOAL_POSITION) & (v >= self.GOAL_VELOCITY)
        limit = self.TIME_LIMIT if self.max_episode_steps is None else min(
            self.TIME_LIMIT, self.max_episode_steps)
        truncated = (self._count[rows] >= limit) & ~terminated
        obs = self._obs(rows)
        reward = torch.full((rows.size,), -1.0, dtype=torch.float64)
        if not (terminated.any() or truncated.any()):
            return obs, reward, None
        return obs, reward, (torch.from_numpy(terminated), torch.from_numpy(truncated))

    def reset(self, rows: Tensor) -> Tensor:
        """Restart the cars of compact ``rows``; their observations ``[len(rows), 2]``."""
        cars = self.index[rows].numpy()
        self._reset_rows(cars)
        return self._obs(cars)

    def compact(self, keep: Tensor) -> None:
        """Keep only the rows where ``keep`` (bool ``[n]``); the others stop stepping."""
        self.index = self.index[keep.nonzero().flatten()]

    def sync(self) -> None:
        """Nothing to write back: the cars' state is this object's."""

    def state_dict(self) -> dict:
        return {"kind": "mountain-car", "index": self.index.clone(),
                "position": torch.from_numpy(self.position.copy()),
                "velocity": torch.from_numpy(self.velocity.copy()),
                "step_count": torch.from_numpy(self._count.copy()),
                "rngs": [rng.bit_generator.state for rng in self.rngs]}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        if state.get("kind") != "mountain-car" or len(state["rngs"]) != self.population:
            raise ValueError(f"the saved env state is not of {self.population} batched "
                             f"MountainCar envs (kind {state.get('kind')!r})")  # fmt: skip
        self.index = state["index"].clone()
        self.position = state["position"].numpy().copy()
        self.velocity = state["velocity"].numpy().copy()
        self._count = state["step_count"].numpy().copy()
        for rng, saved in zip(self.rngs, state["rngs"]):
            rng.bit_generator.state = saved


BATCHED_IDS = ("MountainCar-v0",)


def batched_stepper(env: str, population: int, sizes, seed: int = 0,
                    max_episode_steps: int | None = None):  # fmt: skip
    """The batched stepper of ``env`` (``"gymnasium:MountainCar-v0"``), or ``None`` where
    there is none (the trainer then steps one ``GymEnv`` per agent)."""
    if env.rpartition(":")[2] != "MountainCar-v0" or env.count(":") != 1:
        return None  # (a MODULE:ID env is the user's own, whatever its name)
    return MountainCarStepper(population, sizes, seed=seed, max_episode_steps=max_episode_steps)
