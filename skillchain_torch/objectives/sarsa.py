"""Linear SMDP Sarsa for the top-level decision (paper section 5.1: gamma = 1, epsilon = 0.01).

A decision ``d`` taken in ``s`` lasts ``k`` primitive steps (k = 1 for a primitive action, the
option's execution time otherwise) and earns the summed reward ``R``; then

    delta = R + gamma^k * Q(s', d') * (1 - terminal) - Q(s, d)
    w[d] += alpha * scale * delta * phi(s)

Example:
    >>> import torch
    >>> from skillchain_torch.modules import LinearQHead
    >>> head = LinearQHead(num_features=2, num_decisions=3, population=1)
    >>> update = SarsaUpdate(alpha=0.5, gamma=0.9)
    >>> phi = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
    >>> delta = update(head, phi, decision=torch.tensor([2]), reward=torch.tensor([-3.0]),
    ...                duration=torch.tensor([2]), next_phi=phi, next_decision=torch.tensor([2]),
    ...                terminal=torch.tensor([False]))
    >>> delta.tolist(), head.weight[0, 2].tolist()
    ([-3.0], [-1.5, 0.0])
"""

from __future__ import annotations

import functools

import torch
from torch import Tensor, nn

from skillchain_torch.invariant import rowwise_dot
from skillchain_torch.modules.linear_q import LinearQHead


@functools.lru_cache(maxsize=64)
def _power_table(gamma: float, size: int) -> tuple[float, ...]:
    return tuple(gamma**k for k in range(size))


def discount(gamma: float, duration: Tensor, dtype: torch.dtype = torch.float64) -> Tensor:
    """``gamma ** duration`` elementwise, equal to Python's ``gamma ** k`` for each entry.

    ``torch.pow`` is neither equal to libm's ``pow`` nor layout-invariant (its vectorised and
    scalar paths differ in the last bit), so the powers come from a table computed in Python and
    indexed by the integer durations.
    """
    duration = duration.to(torch.int64)
    if duration.numel() == 0:
        return torch.zeros(duration.shape, dtype=dtype, device=duration.device)
    if bool((duration < 0).any()):
        raise ValueError("durations must be >= 0")
    size = 1 << int(duration.max()).bit_length()  # power-of-two sizes keep the cache small
    table = torch.tensor(_power_table(float(gamma), size), dtype=dtype, device=duration.device)
    return table[duration]


def smdp_td_error(
    reward: Tensor,
    duration: Tensor,
    q_sa: Tensor,
    q_next: Tensor,
    terminal: Tensor,
    gamma: float = 1.0,
) -> Tensor:
    """``delta = R + gamma^k * Q(s', d') * (1 - terminal) - Q(s, d)``, all ``[P]``.

    A terminal transition does not bootstrap: ``Q(s', d')`` is ignored there (it may be any
    value, even inf). A truncated episode is not terminal and should bootstrap.
    """
    # gamma^k = 1 exactly when gamma = 1 (the paper's), and 1 * q = q: skip the power table.
    bootstrap = q_next if gamma == 1.0 else discount(gamma, duration, q_sa.dtype) * q_next
    bootstrap = torch.where(terminal.to(torch.bool), torch.zeros_like(bootstrap), bootstrap)
    return (reward.to(q_sa.dtype) + bootstrap) - q_sa


def _flat(x: Tensor, population: int) -> Tensor:
    # Accept TorchRL's [P, 1] reward/done layout as well as [P].
    return x.reshape(population)


class SarsaUpdate(nn.Module):
    """Closed-form linear SMDP Sarsa step applied to a :class:`LinearQHead`.

    Args:
        alpha: the step size (paper: 0.001 with a 4th-order Fourier basis, 0.0005 with 5th).
        gamma: the discount (paper: 1).
        step_size_scale: optional ``[F]`` per-feature factors, e.g.
            ``FourierBasis.step_size_scale()`` (Konidaris et al. 2011).

    ``forward`` returns the TD error ``[P]`` (0 for inactive agents) and updates the head in
    place. Each agent reads and writes only its own weight row, so the update is bit-identical
    whether an agent runs alone or in a population.
    """

    def __init__(self, alpha: float, gamma: float = 1.0, step_size_scale: Tensor | None = None):
        super().__init__()
        self.alpha = float(alpha)
        self.gamma = float(gamma)
        step = torch.tensor(self.alpha, dtype=torch.float64)
        if step_size_scale is not None:
            step = step * step_size_scale.to(torch.float64)
        self.register_buffer("step_size", step)

    @torch.no_grad()
    def forward(
        self,
        q_head: LinearQHead,
        phi: Tensor,
        decision: Tensor,
        reward: Tensor,
        duration: Tensor,
        next_phi: Tensor,
        next_decision: Tensor,
        terminal: Tensor,
        active: Tensor | None = None,
        next_value: Tensor | None = None,
    ) -> Tensor:
        """Apply one SMDP Sarsa step per active agent.

        Args:
            q_head: the top-level Q head, weights ``[P, D, F]``.
            phi, next_phi: features of ``s`` and ``s'``, ``[P, F]``.
            decision, next_decision: ``LongTensor [P]``; ``next_decision`` is unused where
                ``terminal``, and both are unused for inactive agents.
            reward: summed reward over the decision's ``duration`` steps, ``[P]`` or ``[P, 1]``.
            duration: ``k``, the number of primitive steps the decision lasted (int, >= 1).
            terminal: ``BoolTensor [P]``: the episode ended in ``s'`` (no bootstrap).
            active: ``BoolTensor [P]``; agents outside it neither learn nor report an error.
            next_value: ``Q(s', d') [P]`` when the caller already has it (valued with the
                current weights, as when ``d'`` was chosen); ``next_phi`` is then unused.
        """
        population = q_head.population
        device = q_head.weight.device
        if active is None:
            active = torch.ones(population, dtype=torch.bool, device=device)
        active = _flat(active, population).to(torch.bool)
        terminal = _flat(terminal, population).to(torch.bool)
        zero = torch.zeros_like(decision)
        decision = torch.where(active, _flat(decision, population), zero)

        # One gather of the updated rows serves Q(s, d) and the write-back.
        agents = torch.arange(population, device=device)
        w_sa = q_head.weight[agents, decision]
        q_sa = rowwise_dot(w_sa, phi.to(w_sa.dtype))  # = q_head.q_value(phi, decision)
        if next_value is None:
            bootstraps = active & ~terminal
            next_decision = torch.where(bootstraps, _flat(next_decision, population), zero)
            q_next = q_head.q_value(next_phi, next_decision)
        else:
            q_next = _flat(next_value, population).to(q_sa.dtype)
        delta = smdp_td_error(
            _flat(reward, population),
            _flat(duration, population),
            q_sa,
            q_next,
            terminal,
            self.gamma,
        )
        delta = torch.where(active, delta, torch.zeros_like(delta))
        increment = self.step_size * (delta[:, None] * phi.to(delta.dtype))
        # = q_head.add_to_decision(decision, increment, mask=active)
        q_head.weight[agents, decision] = torch.where(active[:, None], w_sa + increment, w_sa)
        return delta

    def extra_repr(self) -> str:
        return f"alpha={self.alpha}, gamma={self.gamma}, scaled={self.step_size.ndim > 0}"
