"""The flat Sarsa agent's step in C: chosen once, when the agent is built.

:class:`CompiledSarsaStep` is what :func:`~.select.flat_step` hands a
:class:`~skillchain_torch.agents.FlatSarsaAgent` on the CPU with Pinball's sizes where
:mod:`.sarsa`'s kernels are built. The agent binds its four calls once (the values of every
working row, of some rows, one Sarsa update, and a whole step without an episode end), so its
file reads as the torch path alone. The kernels sum in their own order: equal to the torch
path to rounding, each agent's numbers its own.

Example:
    >>> from skillchain_torch.agents import FlatSarsaAgent
    >>> from skillchain_torch.trainers import TrainConfig
    >>> agent = FlatSarsaAgent(TrainConfig(runs=2))
    >>> isinstance(agent.kernel, CompiledSarsaStep) == AVAILABLE
    True
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends import sarsa as kernels
from skillchain_torch.backends.native import for_c

__all__ = ["AVAILABLE", "CompiledSarsaStep"]

AVAILABLE = kernels.AVAILABLE


class CompiledSarsaStep:
    """The compiled calls of a flat Sarsa agent (stateless: each reads the agent's working
    rows, ``agent._work``)."""

    @staticmethod
    def values(agent, phi: Tensor) -> Tensor:
        """``Q(s, .)`` of every working row: ``[n, D]``."""
        return kernels.linear_q(agent._work.head.weight, phi)

    @staticmethod
    def row_values(agent, phi: Tensor, rows: Tensor) -> Tensor:
        """``Q(s, .)`` of the working ``rows`` only: ``[len(rows), D]``."""
        return kernels.linear_q(agent._work.head.weight, phi[rows], rows)

    @staticmethod
    def learn(agent, reward: Tensor, phi1: Tensor, a1: Tensor, q_next: Tensor,
              terminated: Tensor | None) -> None:  # fmt: skip
        """One Sarsa step of every working row toward ``r + gamma q_next``."""
        w = agent._work
        kernels.sarsa_learn(w.head.weight, w.phi, w.action, for_c(reward, torch.float64), q_next,
                            None if terminated is None else for_c(terminated, torch.bool),
                            agent.update.step_size, w.gamma)  # fmt: skip

    @staticmethod
    def observe(agent, phi1: Tensor, reward: Tensor, slot: int) -> Tensor:
        """The whole step of every working row (no episode ended): its next actions."""
        w = agent._work
        return kernels.sarsa_observe(w.head.weight, w.phi, phi1, w.action,
                                     for_c(reward, torch.float64), w.uniforms, slot,
                                     agent.policy.epsilon, agent.update.step_size,
                                     w.gamma)  # fmt: skip
