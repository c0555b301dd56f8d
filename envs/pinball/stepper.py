"""``ActiveEnvStepper``: step only the environments whose agents are still training.

:meth:`PinballEnv.step_raw` steps every environment of the batch. Once most agents of a
population have finished their episodes that wastes most of a step, so the trainer steps the
*active* environments only, in compact rows (row ``i`` is environment ``index[i]``), through the
same pure physics the env uses: on the CPU in float64 the compiled step
(:mod:`~skillchain_torch.envs.pinball.native`, one call for all active balls, writing the
observations too); otherwise :func:`~skillchain_torch.envs.pinball.pinball_step`. Both are
bit-identical to ``step_raw`` ball by ball, so an environment's trajectory does not depend on
which others are active (``tests/trainers/test_stepper.py`` checks it against ``step_raw``).

Starts are drawn by ``env.reset_raw`` (the env's own per-environment stream). The compact state
is the truth while training; :meth:`sync` writes it back into the env (its state and step
counters) before checkpoints and at the end.

This is the env's documented fast path, and it lives in the env's own package: it is the only
code outside :class:`PinballEnv` that touches the env's simulator holder (``env._sim``:
``state``, ``step_count``, ``done``, ``rng``), because the env has no masked ``step_raw`` and no
``state_dict`` for its raw state yet. The trainer uses it for Pinball and
:class:`~skillchain_torch.trainers.loop.env_stepper.EnvStepper` (``EnvBase.step``) for any
other env.
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.envs.pinball import native as _native
from skillchain_torch.envs.pinball import observation, pinball_step

__all__ = ["ActiveEnvStepper"]


class ActiveEnvStepper:
    """Compact stepping of a subset of a :class:`PinballEnv`'s environments.

    Args:
        env: a ``PinballEnv`` with ``batch_size=[P]``.
        native: call the compiled step directly (default: whenever it is built and the env is
            on the CPU in float64). ``False`` steps through ``pinball_step``, which on the CPU
            itself takes the compiled step when built (``physics.NATIVE``). Every path gives
            the same bits.

    Example:
        >>> from skillchain_torch.envs.pinball.env import PinballEnv
        >>> stepper = ActiveEnvStepper(PinballEnv(batch_size=[3], seed=0))
        >>> stepper.start().shape
        torch.Size([3, 4])
        >>> obs, reward, ends = stepper.step(torch.tensor([0, 4, 1]))
        >>> reward.tolist(), ends
        ([-5.0, -1.0, -5.0], None)
    """

    def __init__(self, env, native: bool | None = None):
        self.env = env
        self.population = int(env.num_envs)
        self.max_episode_steps = env.max_episode_steps
        self.pinball_map = env.pinball_map
        self._sim = env._sim
        self._device = self._sim.state.device
        cpu64 = self._device.type == "cpu" and env.dtype == torch.float64
        if native is None:
            native = cpu64 and _native.AVAILABLE
        if native and not (cpu64 and _native.AVAILABLE):
            raise ValueError(
                "native=True needs the compiled step (built: "
                f"{_native.AVAILABLE}) and a CPU float64 env (got {self._device}, {env.dtype})"
            )
        self._native = _native.native_board(self.pinball_map) if native else None
        self.index = torch.arange(self.population, device=self._device)
        self._state = self._sim.state.clone()  # [n, 4]
        self._count = self._sim.step_count.clone()  # steps in the current episode, [n]

    # ------------------------------------------------------------------ modes
    @property
    def num_active(self) -> int:
        return int(self.index.numel())

    def raw_state(self) -> Tensor:
        """The active rows' raw states ``[n, 4]`` (a copy: the compiled step steps in place)."""
        return self._state.clone()

    # ------------------------------------------------------------------ episodes
    def start(self) -> Tensor:
        """Reset every environment and make all of them active; observations ``[P, 4]``."""
        obs = self.env.reset_raw()
        self.index = torch.arange(self.population, device=self._device)
        self._state = self._sim.state.clone()
        self._count = torch.zeros(self.population, dtype=torch.long, device=self._device)
        return obs.reshape(self.population, 4)

    def step(self, action: Tensor):
        """Step the active rows: ``(observation [n, 4], reward [n], ends)``.

        ``ends`` is ``None`` when no episode ended, else ``(terminated, truncated)``, bool
        tensors ``[n]`` (truncated only where ``max_episode_steps`` is reached without the goal).
        """
        if self._native is not None:
            return self._step_native(action)
        state, reward, terminated = pinball_step(self._state, action, self.pinball_map)
        self._state = state
        return observation(state), reward, self._ends(terminated, bool(terminated.any()))

    def _ends(self, terminated: Tensor, any_goal: bool):
        """Count the step; ``(terminated, truncated)``, or ``None`` if no episode ended."""
        self._count += 1
        if self.max_episode_steps is None:
            return (terminated, torch.zeros_like(terminated)) if any_goal else None
        truncated = (self._count >= self.max_episode_steps) & ~terminated
        if not any_goal and not bool(truncated.any()):
            return None
        return terminated, truncated

    def _step_native(self, action: Tensor):
        state = self._state
        if not state.is_contiguous():
            state = self._state = state.contiguous()
        n = state.shape[0]
        # Observations and rewards in one fresh block (callers may keep them); the state itself
        # is stepped in place, since only this object holds it.
        out = torch.empty(5 * n, dtype=torch.float64)
        obs, reward = out[: 4 * n].view(n, 4), out[4 * n :]
        terminated = torch.empty(n, dtype=torch.bool)
        action = action if action.dtype == torch.long else action.to(torch.long)
        action = action if action.is_contiguous() else action.contiguous()
        # check=False: every tensor here was made (or made contiguous int64) just above.
        n_goal = self._native.step_into(state, action, reward, terminated, obs, check=False)
        return obs, reward, self._ends(terminated, n_goal > 0)

    def reset(self, rows: Tensor) -> Tensor:
        """Restart the environments in compact ``rows``; their observations ``[len(rows), 4]``."""
        envs = self.index[rows]
        mask = torch.zeros(self.population, dtype=torch.bool, device=self._device)
        mask[envs] = True
        obs = self.env.reset_raw(mask).reshape(self.population, 4)[envs]
        self._state[rows] = self._sim.state[envs]
        self._count[rows] = 0
        return obs

    def compact(self, keep: Tensor) -> None:
        """Keep only the rows where ``keep`` (bool ``[n]``) is True; the others are written back.

        Dropped rows belong to agents whose last episode just ended: their env is left done.
        """
        self.sync()
        sim = self._sim
        done = sim.done.clone()
        done[self.index[~keep]] = True
        sim.done = done
        keep_rows = keep.nonzero().flatten()
        self.index = self.index[keep_rows]
        self._state = self._state[keep_rows]
        self._count = self._count[keep_rows]

    # ------------------------------------------------------------------ state
    def sync(self) -> None:
        """Write the active rows' states and step counters back into the env."""
        sim = self._sim
        state = sim.state.clone()
        state[self.index] = self._state
        sim.state = state
        count = sim.step_count.clone()
        count[self.index] = self._count
        sim.step_count = count
        done = sim.done.clone()
        done[self.index] = False  # episode ends are handled (restarted) within the same step
        sim.done = done

    def state_dict(self) -> dict:
        """The env's raw state (all P), step counters, done flags, start stream; active rows."""
        self.sync()
        sim = self._sim
        return {
            "state": sim.state.clone(),
            "step_count": sim.step_count.clone(),
            "done": sim.done.clone(),
            "rng": sim.rng.state_dict(),
            "seed": self.env.seed,
            "index": self.index.clone(),
        }

    def load_state_dict(self, state: dict) -> None:
        sim, dev = self._sim, self._device
        sim.state = state["state"].to(device=dev, dtype=self.env.dtype).clone()
        sim.step_count = state["step_count"].to(dev).clone()
        sim.done = state["done"].to(dev).clone()
        sim.rng.load_state_dict(state["rng"])
        sim.rng.to(dev)
        self.env.seed = int(state["seed"])
        self.index = state["index"].to(dev).clone()
        self._state = sim.state[self.index].clone()
        self._count = sim.step_count[self.index].clone()
