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

:class:`AcrobotStepper` does the same for Acrobot-v1 (the "book" dynamics, one RK4 step per
action, Gymnasium's wrap and bounds, its 500-step limit); its squares go through ``pow`` as
Gymnasium's NumPy scalars do (see :meth:`AcrobotStepper._dsdt`).

:func:`batched_stepper` is the one place that picks them: for ``gymnasium:MountainCar-v0``,
``gymnasium:Acrobot-v1`` and ``gymnasium:CartPole-v1`` (:class:`CartPoleStepper`, Euler)
it returns theirs, for any other env ``None`` (the general stepper).

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

import math

import numpy as np
import torch
from torch import Tensor

__all__ = ["BatchedClassicEnv", "MountainCarStepper", "AcrobotStepper", "batched_stepper",
           "CartPoleStepper", "BATCHED_IDS"]


class BatchedClassicEnv:
    """What the batched classic-control steppers share (the ``EnvStepper`` protocol): P envs,
    agent p's starts drawn from its own ``np_random(seed + p)``, the active rows, each env's
    step count and Gymnasium's time limit. A subclass names its ``KIND``, its state arrays
    (``STATE``: attributes of ``[P, STATE_DIM]`` float64, ``[P]`` where ``STATE_DIM`` is 0;
    by default one, ``state``),
    its ``TIME_LIMIT``, and writes :meth:`_start_state` (one agent's reset draw), :meth:`_obs`
    and :meth:`step`.

    Args:
        population: P, one env per agent.
        sizes: the env's :class:`~skillchain_torch.envs.external.EnvSizes` (from its specs).
        seed: agent p's env draws its starts from ``np_random(seed + p)``.
        max_episode_steps: truncate after this many steps as well (``None``: Gymnasium's
            limit alone).
    """

    KIND: str
    STATE: tuple[str, ...] = ("state",)
    STATE_DIM: int = 0
    TIME_LIMIT: int

    def __init__(self, population: int, sizes, seed: int = 0,
                 max_episode_steps: int | None = None):  # fmt: skip
        from gymnasium.utils.seeding import np_random

        self.population, self.sizes = int(population), sizes
        self.max_episode_steps = max_episode_steps
        self.rngs = [np_random(int(seed) + p)[0] for p in range(self.population)]
        for rng in self.rngs:  # GymEnv.set_seed resets once with the seed: that draw is spent
            self._start_state(rng)
        self._count = np.zeros(self.population, dtype=np.int64)
        self.index = torch.arange(self.population)
        shape = (self.population, self.STATE_DIM) if self.STATE_DIM else (self.population,)
        for name in self.STATE:
            setattr(self, name, np.zeros(shape, dtype=np.float64))

    def _start_state(self, rng) -> np.ndarray:
        """One env's start state, drawn from its generator as Gymnasium's ``reset``."""
        raise NotImplementedError

    def _obs(self, rows: np.ndarray) -> Tensor:
        raise NotImplementedError

    @property
    def num_active(self) -> int:
        return int(self.index.numel())

    @property
    def limit(self) -> int:
        """Steps after which an episode is truncated."""
        if self.max_episode_steps is None:
            return self.TIME_LIMIT
        return min(self.TIME_LIMIT, self.max_episode_steps)

    def _reset_rows(self, rows: np.ndarray) -> None:
        for p in rows.tolist():  # each env from its own generator
            self._set_row(p, self._start_state(self.rngs[p]))
            self._count[p] = 0

    def _set_row(self, p: int, start: np.ndarray) -> None:
        self.state[p] = start

    def start(self) -> Tensor:
        """Reset every env; all active; observations ``[P, D]`` mapped by the specs."""
        self.index = torch.arange(self.population)
        rows = np.arange(self.population)
        self._reset_rows(rows)
        return self._obs(rows)

    def reset(self, rows: Tensor) -> Tensor:
        """Restart the envs of compact ``rows``; their observations ``[len(rows), D]``."""
        envs = self.index[rows].numpy()
        self._reset_rows(envs)
        return self._obs(envs)

    def compact(self, keep: Tensor) -> None:
        """Keep only the rows where ``keep`` (bool ``[n]``); the others stop stepping."""
        self.index = self.index[keep.nonzero().flatten()]

    def sync(self) -> None:
        """Nothing to write back: the envs' state is this object's."""

    def _ends(self, rows: np.ndarray, terminated: np.ndarray, reward: Tensor):
        """The step's return: count the step, truncate at the limit (not where terminated),
        observe the new states."""
        self._count[rows] += 1
        truncated = (self._count[rows] >= self.limit) & ~terminated
        obs = self._obs(rows)
        if not (terminated.any() or truncated.any()):
            return obs, reward, None
        return obs, reward, (torch.from_numpy(terminated), torch.from_numpy(truncated))

    def state_dict(self) -> dict:
        return {"kind": self.KIND, "index": self.index.clone(),
                **{name: torch.from_numpy(getattr(self, name).copy()) for name in self.STATE},
                "step_count": torch.from_numpy(self._count.copy()),
                "rngs": [rng.bit_generator.state for rng in self.rngs]}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        if state.get("kind") != self.KIND or len(state["rngs"]) != self.population:
            raise ValueError(f"the saved env state is not of {self.population} batched "
                             f"{self.KIND} envs (kind {state.get('kind')!r})")  # fmt: skip
        self.index = state["index"].clone()
        for name in self.STATE:
            setattr(self, name, state[name].numpy().copy())
        self._count = state["step_count"].numpy().copy()
        for rng, saved in zip(self.rngs, state["rngs"]):
            rng.bit_generator.state = saved


class MountainCarStepper(BatchedClassicEnv):
    """P MountainCar-v0 envs stepped as one batch (the ``EnvStepper`` protocol); the arguments
    are :class:`BatchedClassicEnv`'s (Gymnasium's limit: 200 steps)."""

    # gymnasium.envs.classic_control.MountainCarEnv's constants
    MIN_POSITION, MAX_POSITION, MAX_SPEED = -1.2, 0.6, 0.07
    GOAL_POSITION, GOAL_VELOCITY, FORCE, GRAVITY = 0.5, 0.0, 0.001, 0.0025
    TIME_LIMIT = 200  # MountainCar-v0's TimeLimit
    KIND, STATE = "mountain-car", ("position", "velocity")  # [P] each

    def _start_state(self, rng) -> np.ndarray:
        return np.array([rng.uniform(low=-0.6, high=-0.4), 0.0])

    def _set_row(self, p: int, start: np.ndarray) -> None:
        self.position[p], self.velocity[p] = start

    def _obs(self, rows: np.ndarray) -> Tensor:
        state = np.stack([self.position[rows], self.velocity[rows]], axis=1).astype(np.float32)
        return self.sizes.scale(torch.from_numpy(state))

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
        terminated = (x >= self.GOAL_POSITION) & (v >= self.GOAL_VELOCITY)
        reward = torch.full((rows.size,), -1.0, dtype=torch.float64)
        return self._ends(rows, terminated, reward)


class AcrobotStepper(BatchedClassicEnv):
    """P Acrobot-v1 envs stepped as one batch (the ``EnvStepper`` protocol), with Gymnasium's
    ``AcrobotEnv.step`` arithmetic ("book" dynamics, one RK4 step of 0.2 s) vectorised over the
    agents: the same observations, rewards and ends bit for bit, checked against one ``GymEnv``
    per agent in ``tests/envs/test_classic.py``.

    The arguments are :class:`BatchedClassicEnv`'s (Gymnasium's limit: 500 steps).

    Example:
        >>> from skillchain_torch.envs.external import make_env, read_specs
        >>> arms = AcrobotStepper(2, read_specs(make_env("gymnasium:Acrobot-v1")), seed=0)
        >>> arms.start().shape
        torch.Size([2, 6])
        >>> obs, reward, ends = arms.step(torch.tensor([0, 2]))
        >>> reward.tolist(), ends
        ([-1.0, -1.0], None)
    """

    # gymnasium.envs.classic_control.AcrobotEnv's constants
    DT = 0.2
    LINK_LENGTH_1, LINK_MASS_1, LINK_MASS_2 = 1.0, 1.0, 1.0
    LINK_COM_POS_1, LINK_COM_POS_2, LINK_MOI = 0.5, 0.5, 1.0
    MAX_VEL_1, MAX_VEL_2 = 4 * np.pi, 9 * np.pi
    AVAIL_TORQUE = np.array([-1.0, 0.0, 1.0])
    TIME_LIMIT = 500  # Acrobot-v1's TimeLimit

    KIND, STATE_DIM = "acrobot", 4

    def _start_state(self, rng) -> np.ndarray:
        # AcrobotEnv.reset: uniform in [-0.1, 0.1]^4, as float32
        return rng.uniform(low=-0.1, high=0.1, size=(4,)).astype(np.float32)

    def _obs(self, rows: np.ndarray) -> Tensor:
        s = self.state[rows]
        # Gymnasium keeps a reset's state in float32, so its first observation's cos and sin
        # are float32 maths (they round differently from float64's on ~0.1% of draws).
        fresh = (self._count[rows] == 0)[:, None]
        s = np.where(fresh, s.astype(np.float32), s)  # (float32 values: exact in float64)
        angles = s[:, :2]
        cos = np.where(fresh, np.cos(angles.astype(np.float32)), np.cos(angles))
        sin = np.where(fresh, np.sin(angles.astype(np.float32)), np.sin(angles))
        obs = np.stack([cos[:, 0], sin[:, 0], cos[:, 1], sin[:, 1], s[:, 2], s[:, 3]],
                       axis=1).astype(np.float32)  # fmt: skip
        return self.sizes.scale(torch.from_numpy(obs))

    def _dsdt(self, y: np.ndarray) -> np.ndarray:
        """``AcrobotEnv._dsdt`` ("book") for rows ``y [n, 5]`` (the state and the torque),
        each product and sum in Gymnasium's order. Its squares of NumPy scalars are ``pow``
        (``x**2`` of an array is ``x * x``, which rounds differently on ~0.1% of arguments),
        hence ``float_power``; the squares of Python constants stay Python's."""
        def sq(x):
            return np.float_power(x, 2.0)

        m1, m2, l1 = self.LINK_MASS_1, self.LINK_MASS_2, self.LINK_LENGTH_1
        lc1, lc2, I1, I2, g, pi = self.LINK_COM_POS_1, self.LINK_COM_POS_2, self.LINK_MOI, \
            self.LINK_MOI, 9.8, np.pi  # fmt: skip
        a = y[:, 4]
        theta1, theta2, dtheta1, dtheta2 = y[:, 0], y[:, 1], y[:, 2], y[:, 3]
        d1 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * np.cos(theta2)) + I1 + I2
        d2 = m2 * (lc2**2 + l1 * lc2 * np.cos(theta2)) + I2
        phi2 = m2 * lc2 * g * np.cos(theta1 + theta2 - pi / 2.0)
        phi1 = (-m2 * l1 * lc2 * sq(dtheta2) * np.sin(theta2)
                - 2 * m2 * l1 * lc2 * dtheta2 * dtheta1 * np.sin(theta2)
                + (m1 * lc1 + m2 * l1) * g * np.cos(theta1 - pi / 2) + phi2)  # fmt: skip
        ddtheta2 = (a + d2 / d1 * phi1 - m2 * l1 * lc2 * sq(dtheta1) * np.sin(theta2) - phi2) \
            / (m2 * lc2**2 + I2 - sq(d2) / d1)  # fmt: skip
        ddtheta1 = -(d2 * ddtheta2 + phi1) / d1
        return np.stack([dtheta1, dtheta2, ddtheta1, ddtheta2, np.zeros_like(a)], axis=1)

    def step(self, action: Tensor):
        """Step the active rows: ``(observation [n, 6], reward [n], ends)``; ``ends`` is
        ``None`` when no episode ended, else ``(terminated, truncated)`` bool ``[n]``."""
        rows = self.index.numpy()
        a = action.detach().to("cpu", torch.int64).numpy()
        y0 = np.concatenate([self.state[rows], self.AVAIL_TORQUE[a][:, None]], axis=1)
        # rk4(self._dsdt, s_augmented, [0, dt]): one step
        dt = self.DT - 0
        dt2 = dt / 2.0
        k1 = self._dsdt(y0)
        k2 = self._dsdt(y0 + dt2 * k1)
        k3 = self._dsdt(y0 + dt2 * k2)
        k4 = self._dsdt(y0 + dt * k3)
        ns = (y0 + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4))[:, :4]
        for i in (0, 1):  # wrap(ns[i], -pi, pi): one period at a time, as Gymnasium's loops
            while (ns[:, i] > np.pi).any():
                ns[:, i] = np.where(ns[:, i] > np.pi, ns[:, i] - 2 * np.pi, ns[:, i])
            while (ns[:, i] < -np.pi).any():
                ns[:, i] = np.where(ns[:, i] < -np.pi, ns[:, i] + 2 * np.pi, ns[:, i])
        ns[:, 2] = np.minimum(np.maximum(ns[:, 2], -self.MAX_VEL_1), self.MAX_VEL_1)
        ns[:, 3] = np.minimum(np.maximum(ns[:, 3], -self.MAX_VEL_2), self.MAX_VEL_2)
        self.state[rows] = ns
        terminated = -np.cos(ns[:, 0]) - np.cos(ns[:, 1] + ns[:, 0]) > 1.0
        reward = torch.from_numpy(np.where(terminated, 0.0, -1.0))
        return self._ends(rows, terminated, reward)


class CartPoleStepper(BatchedClassicEnv):
    """P CartPole-v1 envs stepped as one batch (the ``EnvStepper`` protocol), with Gymnasium's
    ``CartPoleEnv.step`` arithmetic (Euler) vectorised over the agents; the arguments are
    :class:`BatchedClassicEnv`'s (Gymnasium's limit: 500 steps). The reward is 1 every step,
    the step the pole falls included, as Gymnasium's.

    Example:
        >>> from skillchain_torch.envs.external import make_env, read_specs
        >>> bounds = "-2.4:2.4,-3:3,-0.21:0.21,-3:3"  # (its velocities are unbounded)
        >>> sizes = read_specs(make_env("gymnasium:CartPole-v1"), obs_bounds=bounds)
        >>> carts = CartPoleStepper(2, sizes, seed=0)
        >>> carts.start().shape
        torch.Size([2, 4])
        >>> obs, reward, ends = carts.step(torch.tensor([0, 1]))
        >>> reward.tolist(), ends
        ([1.0, 1.0], None)
    """

    # gymnasium.envs.classic_control.CartPoleEnv's constants
    GRAVITY, MASSCART, MASSPOLE, LENGTH, FORCE_MAG, TAU = 9.8, 1.0, 0.1, 0.5, 10.0, 0.02
    TOTAL_MASS = MASSPOLE + MASSCART
    POLEMASS_LENGTH = MASSPOLE * LENGTH
    THETA_THRESHOLD = 12 * 2 * math.pi / 360
    X_THRESHOLD = 2.4
    TIME_LIMIT = 500  # CartPole-v1's TimeLimit
    KIND, STATE_DIM = "cart-pole", 4

    def _start_state(self, rng) -> np.ndarray:
        return rng.uniform(low=-0.05, high=0.05, size=(4,))  # CartPoleEnv.reset

    def _obs(self, rows: np.ndarray) -> Tensor:
        return self.sizes.scale(torch.from_numpy(self.state[rows].astype(np.float32)))

    def step(self, action: Tensor):
        """Step the active rows: ``(observation [n, 4], reward [n], ends)``; ``ends`` is
        ``None`` when no episode ended, else ``(terminated, truncated)`` bool ``[n]``."""
        rows = self.index.numpy()
        a = action.detach().to("cpu", torch.int64).numpy()
        x, x_dot, theta, theta_dot = self.state[rows].T
        force = np.where(a == 1, self.FORCE_MAG, -self.FORCE_MAG)
        costheta, sintheta = np.cos(theta), np.sin(theta)
        temp = (force + self.POLEMASS_LENGTH * np.square(theta_dot) * sintheta) / self.TOTAL_MASS
        thetaacc = (self.GRAVITY * sintheta - costheta * temp) / (
            self.LENGTH * (4.0 / 3.0 - self.MASSPOLE * np.square(costheta) / self.TOTAL_MASS))
        xacc = temp - self.POLEMASS_LENGTH * thetaacc * costheta / self.TOTAL_MASS
        x, x_dot = x + self.TAU * x_dot, x_dot + self.TAU * xacc  # Euler, Gymnasium's order
        theta, theta_dot = theta + self.TAU * theta_dot, theta_dot + self.TAU * thetaacc
        self.state[rows] = np.stack([x, x_dot, theta, theta_dot], axis=1)
        terminated = ((x < -self.X_THRESHOLD) | (x > self.X_THRESHOLD)
                      | (theta < -self.THETA_THRESHOLD) | (theta > self.THETA_THRESHOLD))
        reward = torch.ones(rows.size, dtype=torch.float64)
        return self._ends(rows, terminated, reward)


BATCHED = {"MountainCar-v0": MountainCarStepper, "Acrobot-v1": AcrobotStepper,
           "CartPole-v1": CartPoleStepper}
BATCHED_IDS = tuple(BATCHED)


def batched_stepper(env: str, population: int, sizes, seed: int = 0,
                    max_episode_steps: int | None = None):  # fmt: skip
    """The batched stepper of ``env`` (``"gymnasium:MountainCar-v0"``,
    ``"gymnasium:Acrobot-v1"``, ``"gymnasium:CartPole-v1"``), or ``None`` where there is none
    (the trainer then steps one ``GymEnv`` per agent)."""
    kind = BATCHED.get(env.rpartition(":")[2])
    if kind is None or env.count(":") != 1:
        return None  # (a MODULE:ID env is the user's own, whatever its name)
    return kind(population, sizes, seed=seed, max_episode_steps=max_episode_steps)
