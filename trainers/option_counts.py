"""Option counting for :class:`~.option_monitor.OptionMonitor`: per agent and slot, the steps
under each option in the current episode, and the executions that ended, their durations, and
how they ended (success, timeout).

Two ways to count (``counting``): read the counts a skill-chaining agent's discovery keeps
anyway at the ends of executions (:class:`~skillchain_torch.discovery.executions.
ExecutionCounts`; nothing per step), or wrap the agent's ``transition`` and count every step
(any :class:`~skillchain_torch.agents.HierarchicalAgent`). A test checks they agree.

Example:
    >>> from skillchain_torch.trainers.option_monitor import OptionMonitor
    >>> OptionMonitor(counting="every step")
    Traceback (most recent call last):
    ...
    ValueError: counting must be 'agent', 'step' or None, got 'every step'
"""

from __future__ import annotations

import time

import numpy as np
import torch
from torch import Tensor

from skillchain_torch.options import OptionBank

__all__ = ["OptionCounts"]


class OptionCounts:
    """Mixin of :class:`~.option_monitor.OptionMonitor`: its counters (module docstring).

    Reads ``counting`` and ``seconds`` and sets ``agent``, ``_kept``, ``_totals``.
    """

    # ------------------------------------------------------------------ counting
    def attach(self, agent) -> OptionCounts:
        """Start counting ``agent``'s transitions (it needs ``bank``, ``events``, ``contains``,
        ``max_option_steps`` and ``transition``, as :class:`HierarchicalAgent`)."""
        if self.agent is not None:
            raise RuntimeError("this monitor is already attached to an agent")
        if not isinstance(getattr(agent, "bank", None), OptionBank):
            raise TypeError("the agent has no option bank to monitor")
        self.agent = agent
        P, K = agent.bank.population, agent.bank.slots
        device = agent.bank.status.device
        zeros = dict(dtype=torch.int64, device=device)
        # Steps of the current episode under primitive decisions (column 0) and option k
        # (k + 1): one indexed add a step, the per-step cost being most of the monitor's.
        self._tally = torch.zeros(P, K + 1, **zeros)
        self._column = torch.arange(P, device=device) * (K + 1) + 1  # + option = flat index
        # On the CPU through NumPy views: an operation on ten numbers costs far less there.
        self._numpy = device.type == "cpu"
        if self._numpy:
            self._tally_np = self._tally.view(-1).numpy()
            self._column_np = self._column.numpy()
        self.executions = torch.zeros(P, K, **zeros)  # ended executions
        self.execution_steps = torch.zeros(P, K, **zeros)
        self.successes = torch.zeros(P, K, **zeros)
        self.timeouts = torch.zeros(P, K, **zeros)
        self._slots = torch.arange(K, device=device)
        counts = getattr(getattr(agent, "discovery", None), "counts", None)
        if self.counting == "agent" and counts is None:
            raise ValueError("counting='agent' needs an agent whose discovery keeps counts "
                             "(SkillChainingAgent)")  # fmt: skip
        self._kept = counts if self.counting != "step" else None
        if self._kept is not None:  # the agent counts: nothing to do per step
            return self
        original = agent.transition

        def transition(next_obs, reward, terminated, truncated, stepped):
            info = original(next_obs, reward, terminated, truncated, stepped)
            start = time.perf_counter()
            self._count(info, next_obs, terminated, stepped)
            self.seconds += time.perf_counter() - start
            return info

        self._original = original
        agent.transition = transition
        return self

    def detach(self) -> None:
        """Stop counting (the agent's own ``transition`` is restored)."""
        if self.agent is not None:
            if self._kept is None:
                del self.agent.transition  # the instance attribute; the method shows through
            self.agent = None

    @property
    def steps(self) -> Tensor:
        """``[P]`` steps of the current episode."""
        return self._tally.sum(-1)

    @property
    def option_steps(self) -> Tensor:
        """``[P, K]`` steps of the current episode under each option."""
        return self._tally[:, 1:]

    def _count(self, info: dict, next_obs: Tensor, terminated: Tensor, stepped: Tensor) -> None:
        if self._numpy:  # (no torch.no_grad() there: entering it cost more than the count)
            return self._count_numpy(info, next_obs, terminated, stepped)
        with torch.no_grad():
            self._count_torch(info, next_obs, terminated, stepped.to(torch.bool))

    def _count_torch(self, info, next_obs, terminated, stepped) -> None:
        option = info["option"]
        self._tally.view(-1).index_add_(0, self._column + option, stepped.to(torch.int64))
        executed = info["decision_ended"] & (option >= 0) & stepped  # an execution ended
        if not bool(executed.any()):
            return
        ended = (option[:, None] == self._slots) & executed[:, None]  # [P, K]
        duration = info["duration"][:, None]
        self.executions += ended
        self.execution_steps += ended * duration
        reached = self._reached(info, next_obs, terminated, stepped)
        self.successes += ended & reached
        self.timeouts += ended & ~reached & (duration >= self.agent.max_option_steps)

    def _count_numpy(self, info, next_obs, terminated, stepped) -> None:
        """The same counts on NumPy views (a (row, slot) index is distinct: ``+=`` adds once)."""
        if stepped.dtype != torch.bool:
            stepped = stepped.to(torch.bool)
        option_np, stepped_np = info["option"].numpy(), stepped.numpy()
        self._tally_np[self._column_np + option_np] += stepped_np
        executed = info["decision_ended"].numpy() & (option_np >= 0) & stepped_np
        if not executed.any():
            return
        rows = np.flatnonzero(executed)
        slots = option_np[rows]
        duration = info["duration"].numpy()[rows]
        reached = self._reached(info, next_obs, terminated, stepped).numpy()[rows, slots]
        self.executions.numpy()[rows, slots] += 1
        self.execution_steps.numpy()[rows, slots] += duration
        self.successes.numpy()[rows, slots] += reached
        self.timeouts.numpy()[rows, slots] += ~reached & (duration >= self.agent.max_option_steps)

    def _reached(self, info, next_obs, terminated, stepped) -> Tensor:
        """``[P, K]``: each option's target event at ``s'``."""
        reached = info.get("reached")
        if reached is None:  # an agent that does not report its options' targets
            agent = self.agent
            terminated = terminated.to(torch.bool) & stepped
            with torch.no_grad():
                reached = agent.bank.target_reached(next_obs, terminated, agent.events,
                                                    contains=agent.contains)
        return reached

    _COUNTERS = ("steps", "option_steps", "executions", "execution_steps", "successes",
                 "timeouts")

    def counts(self, agents=None) -> dict[str, np.ndarray]:
        """The current (unfinished episode) counters of ``agents`` (default all) as numpy."""
        index = slice(None) if agents is None else torch.as_tensor(agents, dtype=torch.int64)
        return {name: getattr(self, name)[index].cpu().numpy() for name in self._COUNTERS}

    def end_episodes(self, agents, episodes, lengths=None) -> dict[str, np.ndarray]:
        """Fold the counters of ``agents`` (their episodes ``episodes``, 0-based; ``lengths``:
        their steps, needed when the agent keeps the counts) into the episode totals, reset
        them, and return their per-agent counts."""
        index = torch.as_tensor(list(agents), dtype=torch.int64,
                                device=self.steps.device)
        counts = self.counts(index) if self._kept is None else self._agent_counts(index, lengths)
        self._tally[index] = 0
        for name in self._COUNTERS[2:]:
            getattr(self, name)[index] = 0
        K = self.option_steps.shape[1]
        for row, episode in enumerate(episodes):
            total = self._totals.setdefault(int(episode), {
                "agents": np.zeros(1, dtype=np.int64), "steps": np.zeros(1, dtype=np.int64),
                **{name: np.zeros(K, dtype=np.int64) for name in self._COUNTERS[1:]}})
            total["agents"] += 1
            for name in self._COUNTERS:
                total[name] += counts[name][row]
        return counts

    def _agent_counts(self, index: Tensor, lengths) -> dict[str, np.ndarray]:
        """The counters of the agents ``index`` from their last episode's kept counts."""
        if lengths is None:
            raise ValueError("end_episodes needs the episodes' lengths when the agent keeps "
                             "the counts (counting='agent')")  # fmt: skip
        kept = self._kept
        outcomes = kept.last_outcomes[index].cpu().numpy()  # [n, K, 3]
        steps = kept.last_steps[index].cpu().numpy()
        return {"steps": np.asarray(lengths, dtype=np.int64), "option_steps": steps,
                "executions": outcomes.sum(-1), "execution_steps": steps,
                "successes": outcomes[..., 0], "timeouts": outcomes[..., 1]}
