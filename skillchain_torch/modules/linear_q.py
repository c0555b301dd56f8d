"""Linear action values ``Q(s, d) = w_d . phi(s)`` for a population of agents.

Example:
    >>> import torch
    >>> head = LinearQHead(num_features=3, num_decisions=2, population=4)
    >>> head.weight.shape
    torch.Size([4, 2, 3])
    >>> phi = torch.ones(4, 3, dtype=torch.float64)
    >>> step = torch.full((4, 3), 0.5, dtype=torch.float64)
    >>> head.add_to_decision(torch.tensor([1, 0, 1, 0]), step)
    >>> head(phi)[0].tolist(), head.q_value(phi, torch.tensor([1, 1, 0, 0])).tolist()
    ([0.0, 1.5], [1.5, 0.0, 0.0, 1.5])
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from skillchain_torch.invariant import rowwise_dot, rowwise_sum


class LinearQHead(nn.Module):
    """Population-batched linear Q-function over a fixed set of decisions.

    Args:
        num_features: F, the length of the feature vector ``phi(s)``.
        num_decisions: D, fixed at construction. For skill chaining this is the 5 primitive
            actions plus K option slots (``decision = 5 + k`` is slot k); slots that do not hold
            a usable option yet are masked out by the caller's ``available`` mask, so the weight
            shape never changes while options are created.
        population: P, the number of independent agents.
        dtype, device: of the weights (float64 default, as in the reference implementation).

    The weights ``weight [P, D, F]`` (zeros) are a *buffer*, not a Parameter: linear TD methods
    apply closed-form updates (see ``SarsaUpdate``), no autograd graph is ever built, and a buffer
    still travels with ``.to()`` and ``state_dict()``.

    All products are elementwise followed by a sum over the contiguous feature dim, never a
    ``bmm``/``matmul`` across the population, so agent p's values are bit-identical whether it
    runs alone or in a population.
    """

    def __init__(
        self,
        num_features: int,
        num_decisions: int,
        population: int,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
    ):
        super().__init__()
        self.num_features = num_features
        self.num_decisions = num_decisions
        self.population = population
        weight = torch.zeros(population, num_decisions, num_features, dtype=dtype, device=device)
        self.register_buffer("weight", weight)
        # Scratch space of forward_rows (not state): allocated on first use, reused after.
        self.register_buffer("_scratch", None, persistent=False)

    def _check_phi(self, phi: Tensor) -> None:
        if phi.shape != (self.population, self.num_features):
            raise ValueError(
                f"phi must be [P={self.population}, F={self.num_features}], got {tuple(phi.shape)}"
            )

    def forward(self, phi: Tensor) -> Tensor:
        """Q values of every decision: ``phi [P, F] -> q [P, D]``."""
        self._check_phi(phi)
        return rowwise_dot(self.weight, phi[:, None, :].to(self.weight.dtype))

    def forward_rows(self, phi: Tensor, rows: Tensor, decisions: int | None = None) -> Tensor:
        """``forward`` for the agents in ``rows [P]`` only (bit-equal there); other rows 0.

        ``decisions``: value only the first this many decisions (the rest read 0), e.g. the
        primitives and the option slots in use; each value is the same row sum either way.
        """
        self._check_phi(phi)
        d = self.num_decisions if decisions is None else min(int(decisions), self.num_decisions)
        index = rows.nonzero()[:, 0]
        q = torch.zeros(self.population, self.num_decisions, dtype=self.weight.dtype,
                        device=self.weight.device)  # fmt: skip
        phi = phi.to(self.weight.dtype)
        if 2 * index.numel() < self.population:  # few rows: gather them
            q[index, :d] = rowwise_dot(self.weight[index, :d], phi[index][:, None, :])
            return q
        # Most rows: multiply every row into a reused buffer rather than gather ~all weights
        # (a copy as large as the product). Each value is the same row sum; others are dropped.
        product = self._product(d)
        torch.mul(self.weight[:, :d], phi[:, None, :], out=product)
        q[:, :d] = torch.where(rows[:, None], rowwise_sum(product), 0.0)
        return q

    def forward_mask(self, phi: Tensor, need: Tensor, dense: int = 0) -> Tensor:
        """Values where ``need [P, D]`` (bit-equal to ``forward`` there); 0 elsewhere.

        The first ``dense`` decisions (e.g. the primitives, always available) are valued as in
        :meth:`forward_rows` for every row needing any of them; the others (e.g. option slots,
        available in a few states) by gathering just the needed ``(agent, decision)`` rows.

        Example:
            >>> head = LinearQHead(num_features=2, num_decisions=3, population=2)
            >>> head.weight.fill_(1.0)[1, 2] = 3.0
            >>> phi = torch.ones(2, 2, dtype=torch.float64)
            >>> need = torch.tensor([[True, False, False], [True, False, True]])
            >>> head.forward_mask(phi, need, dense=1).tolist()
            [[2.0, 0.0, 0.0], [2.0, 0.0, 6.0]]
        """
        if tuple(need.shape) != (self.population, self.num_decisions):
            raise ValueError(f"need must be [P={self.population}, D={self.num_decisions}], "
                             f"got {tuple(need.shape)}")  # fmt: skip
        q = self.forward_rows(phi, need[:, :dense].any(-1), dense)
        pi, di = need[:, dense:].nonzero().unbind(-1)
        if pi.numel() > 0:
            di = di + dense
            q[pi, di] = rowwise_dot(self.weight[pi, di], phi[pi].to(self.weight.dtype))
        return q

    def _product(self, decisions: int) -> Tensor:
        """A contiguous ``[P, decisions, F]`` scratch view of one buffer kept across calls
        (allocating megabytes every step costs page faults)."""
        size = self.population * self.num_decisions * self.num_features
        buffer, w = self._scratch, self.weight
        if buffer is None or buffer.numel() != size or buffer.dtype != w.dtype \
                or buffer.device != w.device:  # fmt: skip
            buffer = self._scratch = torch.empty(size, dtype=w.dtype, device=w.device)
        return buffer[: self.population * decisions * self.num_features].view(
            self.population, decisions, self.num_features)

    def q_value(self, phi: Tensor, decision: Tensor, index: Tensor | None = None) -> Tensor:
        """``Q(s_p, decision_p)`` for each agent: ``[P]``; bit-equal to ``forward`` gathered.

        ``index [n]``: only these agents (``[n]`` values, the same bits as their entries of the
        full result): the weight rows of the others are not read."""
        self._check_phi(phi)
        if index is None:
            index = torch.arange(self.population, device=decision.device)
        else:
            phi, decision = phi[index], decision[index]
        return rowwise_dot(self.weight[index, decision], phi.to(self.weight.dtype))

    @torch.no_grad()
    def add_to_decision(self, decision: Tensor, increment: Tensor, mask: Tensor | None = None):
        """``weight[p, decision[p]] += increment[p]`` for agents with ``mask[p]`` (default all).

        Each agent touches only its own row, so the update is per-agent elementwise. Agents
        outside the mask may carry any decision index (e.g. -1); their weights stay untouched.
        """
        agents = torch.arange(self.population, device=self.weight.device)
        if mask is None:
            mask = torch.ones(self.population, dtype=torch.bool, device=self.weight.device)
        decision = torch.where(mask, decision, torch.zeros_like(decision))
        rows = self.weight[agents, decision]
        self.weight[agents, decision] = torch.where(
            mask[:, None], rows + increment.to(rows.dtype), rows
        )

    @torch.no_grad()
    def set_values(self, mask: Tensor, value: Tensor) -> None:
        """``Q(s, d) = value[p, d]`` for every state, for the ``(p, d)`` in ``mask [P, D]``
        (skill chaining's initial ``Q(s, o)`` of a joining option). Feature 0 must be the
        constant, as :class:`~skillchain_torch.features.FourierBasis`'s ``cos(0) = 1`` is.

        Example:
            >>> head = LinearQHead(num_features=2, num_decisions=3, population=1)
            >>> head.set_values(torch.tensor([[False, False, True]]),
            ...                 torch.tensor([[0.0, 0.0, -7.0]]))
            >>> head(torch.tensor([[1.0, 0.3]], dtype=torch.float64)).tolist()
            [[0.0, 0.0, -7.0]]
        """
        init = torch.zeros_like(self.weight)
        init[..., 0] = value.to(self.weight.dtype)
        self.weight.copy_(torch.where(mask[..., None], init, self.weight))

    def extra_repr(self) -> str:
        return (
            f"num_features={self.num_features}, num_decisions={self.num_decisions}, "
            f"population={self.population}"
        )
