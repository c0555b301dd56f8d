"""Neural top-level action values ``Q(s, d)``: one small MLP per agent, stacked over the population.

The paper's top level is linear in a Fourier basis (:class:`~skillchain_torch.modules.
LinearQHead`); section 7 names richer function approximators as the way on, and deep skill
chaining (Bagaria & Konidaris) uses neural networks. :class:`MLPQHead` is that head behind the
same :class:`~skillchain_torch.interfaces.ValueHead` interface, so the agent, discovery and the
checkpoints treat it as they treat the linear one; it learns by a loss module and a torch
optimizer (:class:`~skillchain_torch.objectives.SMDPSarsaLoss`, optionally through
:class:`~skillchain_torch.objectives.ReplayTD`).

Example:
    >>> import torch
    >>> head = MLPQHead(num_features=4, num_decisions=7, population=3, hidden=16)
    >>> phi = torch.rand(3, 4, dtype=torch.float64)
    >>> head(phi).shape, float(head(phi).abs().max())   # [P, D]; zero at the start
    (torch.Size([3, 7]), 0.0)
    >>> head.set_values(torch.tensor([[False] * 5 + [True, False]] * 3),
    ...                 torch.full((3, 7), 250.0, dtype=torch.float64))
    >>> head(phi)[:, 5].tolist()                         # a joining option's value, everywhere
    [250.0, 250.0, 250.0]
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from skillchain_torch.invariant import affine_rows, least_squares
from skillchain_torch.modules.stacked import stacked_affine

__all__ = ["MLPQHead"]


class MLPQHead(nn.Module):
    """P independent MLPs ``phi [P, F] -> Q [P, D]``, their weights stacked ``[P, ...]``.

    Args:
        num_features: F, the input size (the agent's ``features`` of the observation; with
            ``features=nn.Identity()`` the observation in the unit box itself).
        num_decisions: D (the primitives, then the option slots).
        population: P.
        hidden, layers: width and number of the tanh hidden layers.
        value_scale: the network's output is ``Q / value_scale``. Pinball's returns are of the
            order of 10^4 (goal +10,000, completion reward +10,000); with ``value_scale=1000``
            the network works on values of order 10 and, with the loss's matching
            ``value_scale``, on TD errors of order 10, where Adam's default step is sane.
        seed: int (agent p's initial weights come from a ``torch.Generator`` seeded
            ``seed + p``) or ``LongTensor [P]`` of per-agent seeds; an agent starts the same
            whatever the population.
        dtype, device: of the weights (float32 by default: a network gains nothing from
            float64 and its tanh costs several times more there). The values come back in the
            input's dtype, so the agent's arithmetic stays in float64.

    Why stacked weights and batched matmuls rather than ``torch.func.vmap`` over P copies of one
    module: the input may carry leading batch dims (``[B, P, F]``, a replay minibatch), and a
    batched matmul is one kernel per layer for all P agents. The output layer starts at
    zero, so every decision starts at ``Q = 0`` as in the linear head; :meth:`set_values` writes
    a constant value for a decision (the way discovery starts a joining option) by zeroing that
    decision's output weights and setting its bias. Agents are independent, bit for bit within
    one population size; across sizes the batched matmuls may round the last bits differently.
    """

    def __init__(self, num_features: int, num_decisions: int, population: int,
                 hidden: int = 64, layers: int = 2, value_scale: float = 1000.0,
                 seed: int | Tensor = 0, dtype: torch.dtype = torch.float32,
                 device: torch.device | str | None = None):  # fmt: skip
        super().__init__()
        if min(num_features, num_decisions, population, hidden, layers) < 1:
            raise ValueError("num_features, num_decisions, population, hidden and layers must be "
                             ">= 1")  # fmt: skip
        if not value_scale > 0:
            raise ValueError(f"value_scale must be > 0, got {value_scale}")
        self.num_features, self.num_decisions = int(num_features), int(num_decisions)
        self.population, self.value_scale = int(population), float(value_scale)
        seeds = (seed.reshape(-1).tolist() if isinstance(seed, Tensor)
                 else [int(seed) + p for p in range(population)])  # fmt: skip
        if len(seeds) != population:
            raise ValueError(f"seed must be an int or [P={population}] seeds, got {len(seeds)}")
        self.config = dict(hidden=int(hidden), layers=int(layers), value_scale=self.value_scale)
        sizes = [self.num_features] + [int(hidden)] * int(layers) + [self.num_decisions]
        # set_values writes so far, per agent (saved: a resumed learner compares with it, and
        # copies the target of the agents written, of no other)
        self.register_buffer("writes", torch.zeros(population, dtype=torch.int64,
                                                   device=device))  # fmt: skip
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
            self.weights.append(nn.Parameter(torch.zeros(population, fan_in, fan_out,
                                                         dtype=dtype, device=device)))
            self.biases.append(nn.Parameter(torch.zeros(population, fan_out, dtype=dtype,
                                                        device=device)))  # fmt: skip
        with torch.no_grad():
            for p in range(population):  # PyTorch's default range, +-1/sqrt(fan_in)
                g = torch.Generator().manual_seed(int(seeds[p]))
                for weight, bias in zip(self.weights[:-1], self.biases[:-1]):
                    bound = 1.0 / math.sqrt(weight.shape[1])
                    draws = torch.rand(weight.shape[1] * weight.shape[2] + bias.shape[1],
                                       generator=g, dtype=torch.float64) * 2 - 1  # fmt: skip
                    n = weight.shape[1] * weight.shape[2]
                    weight[p] = (bound * draws[:n]).reshape(weight.shape[1:]).to(weight)
                    bias[p] = (bound * draws[n:]).to(bias)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        key = prefix + "writes"  # saved before writes were counted per agent: one total
        if key in state_dict and state_dict[key].ndim == 0:
            state_dict[key] = state_dict[key].expand(self.population).clone()
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def forward(self, phi: Tensor) -> Tensor:
        """``phi [*B, P, F] -> Q [*B, P, D]`` (in ``phi``'s dtype)."""
        x = phi.to(self.weights[0].dtype)
        lead = x.shape[:-2]
        x = x.reshape(-1, self.population, self.num_features).transpose(0, 1)  # [P, N, F]
        last = len(self.weights) - 1
        for i, (weight, bias) in enumerate(zip(self.weights, self.biases)):
            x = stacked_affine(x, weight, bias)  # each agent's layer on its rows
            if i < last:
                x = torch.tanh(x)
        q = (x * self.value_scale).transpose(0, 1).reshape(*lead, self.population, -1)
        return q.to(phi.dtype)

    def forward_mask(self, phi: Tensor, mask: Tensor, dense: int = 0) -> Tensor:
        """``Q [P, D]`` where ``mask`` (and in the first ``dense`` columns), 0 elsewhere (the
        whole network runs: an MLP's columns share their hidden layers)."""
        q = self(phi)
        keep = mask.clone()
        keep[..., :dense] = True
        return torch.where(keep, q, torch.zeros_like(q))

    def q_value(self, phi: Tensor, decision: Tensor, index: Tensor | None = None) -> Tensor:
        """``Q(s_p, decision_p)``: ``[*B, P]``, or the rows ``index`` of ``[P]``."""
        q = self(phi).gather(-1, decision.to(torch.int64)[..., None])[..., 0]
        return q if index is None else q[index]

    @torch.no_grad()
    def set_values(self, mask: Tensor, value: Tensor) -> None:
        """``Q(s, d) = value[p, d]`` everywhere for ``(p, d)`` in ``mask [P, D]``: the decision's
        output weights go to 0 and its bias to ``value / value_scale``."""
        weight, bias = self.weights[-1], self.biases[-1]
        m = mask.to(device=weight.device, dtype=torch.bool)
        self.writes += m.any(-1).to(self.writes)  # (a learner copies these agents' targets)
        weight.copy_(torch.where(m[:, None, :], torch.zeros_like(weight), weight))
        target = (value.to(bias) / self.value_scale)
        bias.copy_(torch.where(m, target, bias))

    @torch.no_grad()
    def fit_values(self, mask: Tensor, phi: Tensor, values: Tensor) -> None:
        """``Q(s, d) ~ values[p, n, d]`` on the states ``phi [N, F]``, for ``(p, d)`` in ``mask
        [P, D]``: the decision's output weights and bias become the least-squares fit in agent
        p's own last hidden layer (the hidden layers stay as they are).

        This is the neural counterpart of fitting a linear head's weights in its basis: how a
        joining option's value starts from the agent's own values (``value_start="agent"``).

        Example:
            >>> head = MLPQHead(num_features=2, num_decisions=3, population=1, hidden=8)
            >>> phi = torch.rand(50, 2, dtype=torch.float64)
            >>> head.fit_values(torch.tensor([[False, False, True]]), phi,
            ...                 torch.full((1, 50, 3), 40.0, dtype=torch.float64))
            >>> round(float(head(phi[:3, None])[..., 2].mean()), 3)
            40.0
        """
        weight, bias = self.weights[-1], self.biases[-1]
        m = mask.to(device=weight.device, dtype=torch.bool)
        for p in m.any(-1).nonzero()[:, 0].tolist():  # each agent alone: no population effect
            x = phi.to(weight)
            for w, b in zip(self.weights[:-1], self.biases[:-1]):
                x = torch.tanh(affine_rows(x, w[p].T, b[p]))
            h = torch.cat([x, torch.ones_like(x[:, :1])], dim=-1).to(torch.float64)
            fit = least_squares(h, values[p].to(h) / self.value_scale)  # [H + 1, D]
            weight[p] = torch.where(m[p], fit[:-1].to(weight), weight[p])
            bias[p] = torch.where(m[p], fit[-1].to(bias), bias[p])
        self.writes += m.any(-1).to(self.writes)  # (a learner copies these agents' targets)

    def select_agents(self, index) -> MLPQHead:
        """A new head holding agents ``index`` (repeats allowed), weights copied."""
        index = torch.as_tensor(index, dtype=torch.int64).reshape(-1)
        weight = self.weights[0]
        new = MLPQHead(self.num_features, self.num_decisions, len(index),
                       hidden=self.config["hidden"], layers=self.config["layers"],
                       value_scale=self.value_scale, dtype=weight.dtype,
                       device=weight.device)  # fmt: skip
        with torch.no_grad():
            for mine, theirs in zip([*self.weights, *self.biases], [*new.weights, *new.biases]):
                theirs.copy_(mine[index.to(mine.device)])
        return new

    def extra_repr(self) -> str:
        return (f"num_features={self.num_features}, num_decisions={self.num_decisions}, "
                f"population={self.population}, hidden={self.config['hidden']}, "
                f"layers={self.config['layers']}, value_scale={self.value_scale}")
