"""``HierarchicalCollector``: P agents and their envs stepped together; ``TensorDict`` batches out.

The loop every trainer of this library runs, in the form of TorchRL's ``Collector``: iterate
and get ``TensorDict`` batches ``[T, n]`` (``n`` active agents), until every agent has run its
episodes or ``total_frames`` frames. :class:`~skillchain_torch.trainers.PopulationTrainer`
iterates one; a script can too.

Why not ``torchrl.collectors.Collector``: it fits a stateless policy over one batch of envs
that it resets itself, and this one does not fit that:

* a top-level decision spans several environment steps (an option runs until its termination
  predicate fires), so the policy is not a ``TensorDictModule`` from one observation to one
  action: it holds per-agent option state (the executing slot, its running time, the reward
  accumulated since the decision) between steps;
* the agent learns *inside* the step (SMDP Sarsa when a decision ends, intra-option
  Q-learning on every transition) and must see episode ends and restarts in order, with
  per-agent random streams that make a population reproduce single runs;
* agents finish their episodes at different times: a finished agent stops acting and
  learning, and the batch shrinks to the agents still running (compact rows).

The collector keeps TorchRL's conventions instead: iteration, ``frames_per_batch`` and
``total_frames``, ``TensorDict`` batches with the ``("next", ...)`` keys, ``state_dict`` and
``load_state_dict``.

One step, in order (:meth:`_steps`): the env steps the active agents' actions; each agent's
return so far takes the reward; the top level's exploration follows its schedule; then either
``agent.observe`` (no episode ended) or, when some did, the restarts (``stepper.reset``), the
agent's terminal updates and first decisions (``agent.observe_ends``), and the retirement of
agents whose last episode just ended (``compact``, env and agent alike).

Keys of a batch (``T`` steps of the ``n`` agents active during it):

====================================  ===============  ========================================
key                                   shape            meaning
====================================  ===============  ========================================
``agent``                             ``[T, n]``       agent id (row ``p`` of a population)
``observation``                       ``[T, n, D]``    ``s``
``action``                            ``[T, n]``       the primitive taken at ``s``
``decision``, ``option``              ``[T, n]``       the top-level decision in force (``< A``:
                                                       a primitive, ``A + k``: option slot k)
                                                       and the executing slot (-1 none), for
                                                       agents that have options
``("next", "observation")``           ``[T, n, D]``    ``s'`` (an ended episode's last state)
``("next", "reward")``                ``[T, n, 1]``
``("next", "done" / "terminated" /    ``[T, n, 1]``    as TorchRL
"truncated")``
``("next", "episode_reward")``        ``[T, n, 1]``    the episode's return so far, this step
                                                       included (TorchRL's ``RewardSum``)
``("next", "step_count")``            ``[T, n, 1]``    the episode's steps so far
``state``, ``("next", "state")``      ``[T, n, 4]``    Pinball's raw state (``state=True``)
====================================  ===============  ========================================

Batches end after ``frames_per_batch // n`` steps, or, with ``frames_per_batch=None``, at every
step in which an episode ended (what a trainer wants: it records those episodes, runs its hooks
and writes its checkpoints between batches); the rows of a batch never change inside it.

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

import math
from collections.abc import Callable, Iterator

import torch
from tensordict import TensorDict
from torch import Tensor

from skillchain_torch.interfaces import EnvStepper

__all__ = ["HierarchicalCollector"]


class HierarchicalCollector:
    """Iterate over ``TensorDict`` batches of P agents driving their envs.

    Args:
        env: a :class:`~skillchain_torch.envs.pinball.PinballEnv` with ``batch_size [P]``, or
            an env stepper (:class:`~skillchain_torch.interfaces.EnvStepper`: Pinball's
            :class:`~skillchain_torch.envs.pinball.stepper.ActiveEnvStepper`, or
            :class:`~skillchain_torch.trainers.loop.env_stepper.EnvStepper` over TorchRL envs).
        agent: P agents following the episode protocol
            (:class:`~skillchain_torch.interfaces.EpisodeAgent`).
        frames_per_batch: env frames per batch (``T = frames_per_batch // n``), or ``None``:
            a batch ends at every step in which an episode ended.
        total_frames: stop after this many frames (``-1``: never).
        episodes: each agent retires after this many episodes (``None``: never).
        epsilon: the top level's exploration as a function of the population step
            (``policies.LinearEpsilon``), set on the agent before each step learns; ``None``
            leaves the agent's own.
        state: record Pinball's raw ``state`` (default: when ``env`` is a ``PinballEnv``).
    """

    def __init__(self, env, agent, frames_per_batch: int | None = None,
                 total_frames: int = -1, *, episodes: int | None = None,
                 epsilon: Callable[[int], float] | None = None,
                 state: bool | None = None):  # fmt: skip
        if isinstance(env, EnvStepper):  # the declared seam (interfaces), not a guess
            self.stepper = env
        else:
            from skillchain_torch.envs.pinball.stepper import ActiveEnvStepper

            if len(env.batch_size) != 1:
                raise ValueError(f"env must have batch_size [P], got {tuple(env.batch_size)}")
            self.stepper = ActiveEnvStepper(env)
        self.population = int(agent.population)
        self.frames_per_batch = (None if frames_per_batch is None else  # a multiple of P
                                 max(1, int(frames_per_batch) // self.population) * self.population)
        self.total_frames = int(total_frames)
        self.episodes, self.epsilon = episodes, epsilon
        self.state = hasattr(self.stepper, "raw_state") if state is None else bool(state)
        # The collection's state, declared once (what a checkpoint holds; state_dict).
        self.started = False
        self.frames = 0  # agent steps, summed over agents (TorchRL's frames)
        self.global_step = 0  # population steps (every active agent steps once per step)
        self.episodes_done = torch.zeros(self.population, dtype=torch.int64)
        self.max_frames: int | None = None  # a limit for this iteration only (trainer.train)
        self._ret = torch.zeros(self.population, dtype=torch.float64)  # per active row
        self._start = torch.zeros(self.population, dtype=torch.int64)  # its episode's start
        self._obs: Tensor | None = None  # s of each active row
        self._retired = False  # agents retired at the last episode end (the rows changed)
        self.finished = False  # started, and every agent has run its episodes
        # The active agents' ids and their next actions, as the agent last returned them (it
        # returns them from begin, observe and observe_ends): the loop asks for nothing else.
        self.index: Tensor | None = None
        self._action: Tensor | None = None
        self.agent = agent

    @property
    def agent(self):
        """The agents the collector drives (assigning others reads their rows afresh)."""
        return self._agent

    @agent.setter
    def agent(self, agent) -> None:
        self._agent = agent
        # A fresh agent: its rows and actions are read again (its rows once it has begun).
        self.index = agent.index if self.started else None
        self._action = None
        self.finished = self.started and self.index.numel() == 0

    # ------------------------------------------------------------------ iteration
    @property
    def num_active(self) -> int:
        return self.population if self.index is None else int(self.index.numel())

    def start(self) -> None:
        """Reset every env and let the agents take their first decisions."""
        obs = self.stepper.start()
        self._action = self.agent.begin(obs)
        self.index = self.agent.index
        self._obs = obs
        device = obs.device
        self._ret = torch.zeros(self.population, dtype=torch.float64, device=device)
        self._start = torch.zeros(self.population, dtype=torch.int64, device=device)
        self.started = True

    @property
    def agent(self):
        """The agents this collector drives (assigning one replaces them)."""
        return self._agent

    @agent.setter
    def agent(self, agent) -> None:
        # The schedule reaches the agent through its declared method, checked here once.
        if self.epsilon is not None and not callable(getattr(agent, "set_epsilon", None)):
            raise ValueError(f"an exploration schedule (epsilon_init) anneals the agent, but "
                             f"{type(agent).__name__} has no set_epsilon(epsilon) method")
        self._agent = agent

    def __iter__(self) -> Iterator[TensorDict]:
        if not self.started:
            self.start()
        while self.total_frames < 0 or self.frames < self.total_frames:
            if self.max_frames is not None and self.frames >= self.max_frames:
                return
            index = self.index  # the active agents (a batch's rows never change)
            if index.numel() == 0:
                return
            yield self._steps(index.clone())  # (the batch's own: the agent's stay its own)

    def rollout(self) -> TensorDict:
        """Collect one batch (starting the episodes if needed)."""
        return next(iter(self))

    def _steps(self, index: Tensor) -> TensorDict:
        """Step the active agents ``index`` until the batch ends; the batch ``[T, n]``.

        This loop runs every population step of a run, so its lists are locals, and it calls
        the env and the agent once each per step. The agent's actions, decisions and options
        are kept without a copy: an agent replaces them, it does not write them in place (the
        built-in agents replace every state tensor)."""
        stepper, agent, schedule = self.stepper, self.agent, self.epsilon
        n = int(index.numel())
        cap = math.inf if self.frames_per_batch is None else max(1, self.frames_per_batch // n)
        limit = math.inf if self.max_frames is None else self.max_frames
        if self.total_frames >= 0:
            limit = min(limit, self.total_frames)
        # Agents with options declare their per-step state (``step_state``, all P rows): the
        # decision in force and the executing slot are read from it, not asked for.
        decisions = hasattr(agent, "step_state")
        every = n == self.population  # rows are agents: no gather
        record_state = self.state
        first_step = self.global_step + 1
        observations, actions, next_observations, rewards, returns, starts, ends_at = \
            [], [], [], [], [], [], []  # fmt: skip
        decision, option, state, next_state = [], [], [], []
        action = agent.actions if self._action is None else self._action
        while True:
            observations.append(self._obs)
            actions.append(action)
            if decisions:
                held = agent.step_state
                decision.append(held.decision if every else held.decision[index])
                option.append(held.option if every else held.option[index])
            if record_state:
                state.append(stepper.raw_state())
            obs, reward, ends = stepper.step(action)
            self._ret = ret = self._ret + reward  # the episode's return so far (a new tensor)
            self.global_step += 1
            self.frames += n
            if schedule is not None:
                agent.set_epsilon(schedule(self.global_step))
            next_observations.append(obs)
            rewards.append(reward)
            returns.append(ret)
            starts.append(self._start)
            if record_state:
                next_state.append(stepper.raw_state())
            if ends is None:
                action = agent.observe(obs, reward)
                self._obs = obs
                if len(rewards) < cap and self.frames < limit:
                    continue
                self._action = action
                break
            ends_at.append((len(rewards) - 1, ends))
            self._episode_ends(obs, reward, *ends)
            if (self.frames_per_batch is None or self._retired or len(rewards) >= cap
                    or self.frames >= limit):  # fmt: skip (the rows change: the batch ends)
                break
            action = self._action
        return self._batch(index, first_step, observations, actions, next_observations,
                           rewards, returns, starts, ends_at, decision, option, state,
                           next_state)  # fmt: skip

    def _episode_ends(self, obs: Tensor, reward: Tensor, terminated: Tensor,
                      truncated: Tensor) -> None:  # fmt: skip
        """Restart the rows whose episodes ended (or retire them after their last episode)."""
        rows = (terminated | truncated).nonzero().flatten()
        agents = self.index[rows]
        self.episodes_done[agents.cpu()] += 1
        if self.episodes is None:
            finishing = torch.zeros(rows.shape[0], dtype=torch.bool, device=rows.device)
        else:
            finishing = (self.episodes_done[agents.cpu()] >= self.episodes).to(rows.device)
        restart = rows[~finishing]
        start_obs = self.stepper.reset(restart) if restart.numel() else None
        self._action = self.agent.observe_ends(obs, reward, terminated, truncated, restart,
                                               start_obs)  # fmt: skip
        self._ret = self._ret.index_fill(0, rows, 0.0)
        self._start = self._start.index_fill(0, rows, self.global_step)
        next_obs = obs.clone()
        if start_obs is not None:
            next_obs[restart] = start_obs.to(next_obs.dtype)
        self._obs = next_obs
        self._retired = bool(finishing.any())
        if self._retired:
            keep = torch.ones(terminated.shape[0], dtype=torch.bool, device=rows.device)
            keep[rows[finishing]] = False
            self.stepper.compact(keep)
            self.agent.compact(keep)
            self._ret, self._start, self._obs = self._ret[keep], self._start[keep], self._obs[keep]
            self.index, self._action = self.index[keep], self._action[keep]
            self.finished = self.index.numel() == 0

    def _batch(self, index, first_step, observations, actions, next_observations, rewards,
               returns, starts, ends_at, decision, option, state, next_state) -> TensorDict:
        """The ``TensorDict [T, n]`` of the steps just taken (lists of ``[n, ...]`` tensors)."""
        T, n = len(rewards), int(index.numel())
        device = rewards[0].device
        next_obs = torch.stack(next_observations)
        if observations[0] is None:  # resumed without the current observations
            observations[0] = torch.full_like(next_obs[0], float("nan"))
        terminated = torch.zeros(T, n, 1, dtype=torch.bool, device=device)
        truncated = torch.zeros(T, n, 1, dtype=torch.bool, device=device)
        for t, (term, trunc) in ends_at:
            terminated[t, :, 0], truncated[t, :, 0] = term, trunc
        step = torch.arange(first_step, first_step + T, device=device)[:, None]
        nxt = {"observation": next_obs, "reward": torch.stack(rewards)[..., None],
               "episode_reward": torch.stack(returns)[..., None],
               "step_count": (step - torch.stack(starts))[..., None],
               "terminated": terminated, "truncated": truncated, "done": terminated | truncated}
        out = {"agent": index.expand(T, n), "observation": torch.stack(observations),
               "action": torch.stack(actions), "next": nxt}
        if decision:
            out["decision"], out["option"] = torch.stack(decision), torch.stack(option)
        if state:
            out["state"], nxt["state"] = torch.stack(state), torch.stack(next_state)
        return TensorDict(out, batch_size=[T, n], device=device)

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict:
        """Progress and every agent's episode so far (``partial_return``/``partial_length``
        ``[P]``), as a checkpoint holds them."""
        P, index = self.population, self.index
        partial_return = torch.zeros(P, dtype=torch.float64)
        partial_length = torch.zeros(P, dtype=torch.int64)
        if self.started:
            partial_return[index.cpu()] = self._ret.cpu()
            partial_length[index.cpu()] = (self.global_step - self._start).cpu()
        return {"started": self.started, "global_step": self.global_step,
                "agent_steps": self.frames, "episodes_done": self.episodes_done.clone(),
                "partial_return": partial_return, "partial_length": partial_length}

    def load_state_dict(self, state: dict, obs: Tensor | None = None) -> None:
        """Continue from ``state`` (the agent and the stepper loaded first); ``obs``: the
        active rows' current observations (default: the agent's own ``obs`` rows)."""
        self.started = bool(state["started"])
        self.global_step = int(state["global_step"])
        self.frames = int(state["agent_steps"])
        self.episodes_done = torch.as_tensor(state["episodes_done"], dtype=torch.int64).clone()
        self.index = index = self.agent.index
        self._action = None  # read from the agent at the next batch
        self.finished = self.started and index.numel() == 0
        device = index.device
        self._ret = state["partial_return"].to(device)[index].clone()
        self._start = self.global_step - state["partial_length"].to(device)[index]
        if obs is None and hasattr(self.agent, "obs"):
            obs = self.agent.obs[index]
        self._obs = obs

    def __repr__(self) -> str:
        return (f"HierarchicalCollector(population={self.population}, "
                f"frames_per_batch={self.frames_per_batch}, total_frames={self.total_frames}, "
                f"episodes={self.episodes})")
