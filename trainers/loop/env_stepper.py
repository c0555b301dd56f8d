"""``EnvStepper``: the trainer's stepper for any TorchRL env (Gymnasium ids through ``GymEnv``).

:class:`~.stepper.ActiveEnvStepper` is Pinball's fast path. This is the general one, with the
same interface (``start``, ``step``, ``reset``, ``compact``, ``sync``, ``state_dict``): one
unbatched TorchRL env per agent, agent ``p``'s env seeded with ``seed + p`` (so agent p's run
does not depend on the others), each stepped through ``EnvBase.step`` and reset through
``EnvBase.reset`` only while its agent is training. Observations are mapped onto the unit box
by the spec's bounds (:class:`~skillchain_torch.envs.external.EnvSizes`), rewards come from
``("next", "reward")``, the goal event from ``("next", "terminated")``; an env's own
truncation (a ``TimeLimit``) and ``max_episode_steps`` both truncate.

Why one env per agent and not a TorchRL ``SerialEnv``: finished agents stop stepping (a
batched env steps every member), and agent p's environment keeps its own seed whatever P is.

An env's simulator state is Gymnasium's own and is not saved: a checkpoint records the step
counters only, and resuming such a run is refused with a one-line error.

Example:
    >>> from skillchain_torch.envs.external import make_env, read_specs
    >>> envs = [make_env("gymnasium:MountainCar-v0") for _ in range(2)]
    >>> stepper = EnvStepper(envs, read_specs(envs[0]), seed=0)
    >>> obs = stepper.start()
    >>> obs.shape, bool(((obs >= 0) & (obs <= 1)).all())
    (torch.Size([2, 2]), True)
    >>> obs, reward, ends = stepper.step(torch.tensor([0, 2]))
    >>> reward.tolist(), ends
    ([-1.0, -1.0], None)
"""

from __future__ import annotations

import torch
from tensordict import TensorDict
from torch import Tensor

__all__ = ["EnvStepper"]


class EnvStepper:
    """Compact stepping of P unbatched TorchRL envs, one per agent.

    Args:
        envs: P envs (``batch_size=[]``) with integer (categorical) actions.
        sizes: their :class:`~skillchain_torch.envs.external.EnvSizes`.
        seed: env ``p`` is seeded with ``seed + p``.
        max_episode_steps: truncate an episode after this many steps (``None``: only the
            env's own limit).
    """

    def __init__(self, envs, sizes, seed: int = 0, max_episode_steps: int | None = None):
        self.envs, self.sizes = list(envs), sizes
        self.population = len(self.envs)
        self.max_episode_steps = max_episode_steps
        for p, env in enumerate(self.envs):
            env.set_seed(int(seed) + p)
        self.index = torch.arange(self.population)
        self._td: list[TensorDict | None] = [None] * self.population
        self._count = torch.zeros(self.population, dtype=torch.long)

    @property
    def num_active(self) -> int:
        return int(self.index.numel())

    def _obs(self, td: TensorDict) -> Tensor:
        return td.get("observation")

    def start(self) -> Tensor:
        """Reset every env; all active; observations ``[P, D]`` in the unit box."""
        self.index = torch.arange(self.population)
        self._td = [env.reset() for env in self.envs]
        self._count.zero_()
        return self.sizes.scale(torch.stack([self._obs(td) for td in self._td]))

    def step(self, action: Tensor):
        """Step the active rows: ``(observation [n, D], reward [n], ends)``; ``ends`` is
        ``None`` when no episode ended, else ``(terminated, truncated)`` bool ``[n]``."""
        obs, reward, terminated, truncated = [], [], [], []
        for row, a in enumerate(action.tolist()):
            p = int(self.index[row])
            td = self._td[p].set("action", torch.tensor(a, dtype=torch.int64))
            nxt = self.envs[p].step(td).get("next")
            self._td[p] = nxt
            obs.append(self._obs(nxt))
            reward.append(float(nxt.get("reward").reshape(-1)[0]))
            terminated.append(bool(nxt.get("terminated").reshape(-1)[0]))
            truncated.append(bool(nxt.get("truncated").reshape(-1)[0]))
        self._count[self.index] += 1
        terminated_t = torch.tensor(terminated, dtype=torch.bool)
        truncated_t = torch.tensor(truncated, dtype=torch.bool) & ~terminated_t
        if self.max_episode_steps is not None:
            truncated_t |= (self._count[self.index] >= self.max_episode_steps) & ~terminated_t
        obs_t = self.sizes.scale(torch.stack(obs))
        reward_t = torch.tensor(reward, dtype=torch.float64)
        if not bool((terminated_t | truncated_t).any()):
            return obs_t, reward_t, None
        return obs_t, reward_t, (terminated_t, truncated_t)

    def reset(self, rows: Tensor) -> Tensor:
        """Restart the envs of compact ``rows``; their observations ``[len(rows), D]``."""
        out = []
        for row in rows.tolist():
            p = int(self.index[row])
            self._td[p] = self.envs[p].reset()
            self._count[p] = 0
            out.append(self._obs(self._td[p]))
        return self.sizes.scale(torch.stack(out))

    def compact(self, keep: Tensor) -> None:
        """Keep only the rows where ``keep`` (bool ``[n]``); the others stop stepping."""
        self.index = self.index[keep.nonzero().flatten()]

    def sync(self) -> None:
        """Nothing to write back: each env holds its own state."""

    def state_dict(self) -> dict:
        return {"kind": "torchrl-envs", "index": self.index.clone(),
                "step_count": self._count.clone()}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        raise ValueError("a run on a Gymnasium/TorchRL env cannot resume from a checkpoint: "
                         "the env's simulator state is its own and is not saved; run it again")
