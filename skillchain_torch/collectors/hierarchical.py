"""``HierarchicalCollector``: run a Pinball env with a hierarchical agent, yield transitions.

In the spirit of TorchRL's ``Collector`` (iterate, get ``TensorDict`` batches of
``frames_per_batch`` frames until ``total_frames``), but written for this agent because
TorchRL's collector does not fit it:

* a top-level decision spans several environment steps (an option runs until its termination
  predicate fires), so the policy is not a stateless ``TensorDictModule`` mapping one
  observation to one action: it needs per-agent option state (the executing slot, its running
  time, the reward accumulated since the decision) that lives between steps;
* the agent learns *inside* the step (SMDP Sarsa when a decision ends, intra-option
  Q-learning on every transition) and must see episode ends and restarts in order, with
  per-agent random streams that make a population reproduce single runs;
* TorchRL's collector resets environments itself and calls the policy on the reset output,
  while the agent's protocol decides the first action of a restarted episode after its last
  update.

Each batch has batch size ``[T, P]`` (``T = frames_per_batch // P`` steps of the P
environments) and the keys ``observation``, ``state``, ``action``, ``decision`` (``< 5`` a
primitive, ``5 + k`` option slot k: the decision in force at this step), ``option`` (slot
executing now, -1 none), and ``("next", key)`` for ``reward``, ``done``, ``terminated``,
``truncated`` (``[T, P, 1]``), ``observation`` and ``state``. An ended episode's ``next`` entries
are its last state; the environment restarts before the following step.

Example:
    >>> from skillchain_torch.agents import HierarchicalAgent
    >>> from skillchain_torch.envs.pinball import PinballEnv
    >>> from skillchain_torch.options import OptionBank
    >>> env = PinballEnv("pinball_simple_single", batch_size=[2], seed=0)
    >>> agent = HierarchicalAgent(OptionBank.build(2, slots=1, order=1), order=1)
    >>> batch = next(iter(HierarchicalCollector(env, agent, frames_per_batch=8)))
    >>> batch.batch_size, batch["next", "reward"].shape
    (torch.Size([4, 2]), torch.Size([4, 2, 1]))
"""

from __future__ import annotations

from collections.abc import Iterator

import torch
from tensordict import TensorDict

from skillchain_torch.envs.pinball import observation

__all__ = ["HierarchicalCollector"]


class HierarchicalCollector:
    """Iterate over ``TensorDict`` batches of an env driven by a hierarchical agent.

    Args:
        env: a :class:`~skillchain_torch.envs.pinball.PinballEnv` with ``batch_size [P]``.
        agent: an agent following the episode protocol (``begin`` / ``observe`` /
            ``observe_ends``, ``actions``, ``decisions``, ``options``) for the same P, e.g.
            :class:`~skillchain_torch.agents.HierarchicalAgent`.
        frames_per_batch: env frames per batch (rounded down to a multiple of P, at least P).
        total_frames: stop after this many frames (``-1``: never).
    """

    def __init__(self, env, agent, frames_per_batch: int, total_frames: int = -1):
        if len(env.batch_size) != 1:
            raise ValueError(f"env must have batch_size [P], got {tuple(env.batch_size)}")
        self.env, self.agent = env, agent
        self.population = env.batch_size[0]
        self.steps_per_batch = max(1, int(frames_per_batch) // self.population)
        self.frames_per_batch = self.steps_per_batch * self.population
        self.total_frames = int(total_frames)
        self.frames = 0
        self._started = False

    def _start(self) -> None:
        self.agent.begin(self.env.reset_raw())
        self._started = True

    def rollout(self) -> TensorDict:
        """Collect one batch of ``steps_per_batch`` steps (starting the episodes if needed)."""
        if not self._started:
            self._start()
        env, agent = self.env, self.agent
        P = self.population
        keys = ("observation", "state", "action", "decision", "option")
        next_keys = ("observation", "state", "reward", "done", "terminated", "truncated")
        rows = {k: [] for k in keys}
        nxt = {k: [] for k in next_keys}
        all_rows = torch.arange(P, device=env.state.device)
        for _ in range(self.steps_per_batch):
            state = env.state
            rows["state"].append(state)
            rows["observation"].append(observation(state))
            action = agent.actions.clone()
            rows["action"].append(action)
            rows["decision"].append(agent.decisions.clone())
            rows["option"].append(agent.options.clone())
            obs, reward, terminated, truncated = env.step_raw(action)
            done = terminated | truncated
            for key, value in (("observation", obs), ("state", env.state), ("reward", reward),
                               ("done", done), ("terminated", terminated),
                               ("truncated", truncated)):
                nxt[key].append(value)
            if bool(done.any()):
                restart = all_rows[done]
                start_obs = env.reset_raw(done)[restart]
                agent.observe_ends(obs, reward, terminated, truncated, restart, start_obs)
            else:
                agent.observe(obs, reward)
        self.frames += self.frames_per_batch
        out = {k: torch.stack(v) for k, v in rows.items()}
        out["next"] = {k: torch.stack(v) for k, v in nxt.items()}
        for key in ("reward", "done", "terminated", "truncated"):
            out["next"][key] = out["next"][key][..., None]
        return TensorDict(out, batch_size=[self.steps_per_batch, P])

    def __iter__(self) -> Iterator[TensorDict]:
        while self.total_frames < 0 or self.frames < self.total_frames:
            yield self.rollout()

    def __repr__(self) -> str:
        return (f"HierarchicalCollector(population={self.population}, "
                f"frames_per_batch={self.frames_per_batch}, total_frames={self.total_frames})")
