"""Fourier basis for linear value function approximation (Konidaris, Osentoski & Thomas 2011).

Skill chaining's Pinball agents (paper, section 5.1) use a 4th-order basis (625 features) or a
5th-order basis (1296) for the top-level Q and a 3rd-order basis (256) for option policies.

Example:
    >>> import torch
    >>> basis = FourierBasis(dim=2, order=1)
    >>> basis.coefficients.tolist()
    [[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]]
    >>> basis(torch.tensor([[0.0, 1.0]], dtype=torch.float64)).round(decimals=6).tolist()
    [[1.0, -1.0, 1.0, -1.0]]
"""

from __future__ import annotations

import itertools
import math

import torch
from torch import Tensor, nn


class FourierBasis(nn.Module):
    """``phi_i(x) = cos(pi * c_i . x)`` for every ``c_i`` in ``{0..order}^dim``.

    Args:
        dim: state dimension; inputs are expected scaled to ``[0, 1]``.
        order: the largest coefficient per dimension.
        dtype: dtype of the ``coefficients`` buffer (float64 default).

    The coefficient vectors are in lexicographic order with the last dimension varying fastest,
    so ``num_features = (order + 1) ** dim`` and feature 0 is the constant 1.
    """

    def __init__(self, dim: int, order: int, dtype: torch.dtype = torch.float64):
        super().__init__()
        if dim < 1 or order < 0:
            raise ValueError(f"need dim >= 1 and order >= 0, got dim={dim}, order={order}")
        self.dim = dim
        self.order = order
        coefficients = list(itertools.product(range(order + 1), repeat=dim))
        self.register_buffer("coefficients", torch.tensor(coefficients, dtype=dtype))
        self.num_features = len(coefficients)

    def forward(self, x: Tensor) -> Tensor:
        """Map states ``[..., dim]`` to features ``[..., num_features]``."""
        c = self.coefficients
        x = x.to(c.dtype)
        # c . x accumulated left to right with elementwise ops, as a sequential implementation
        # does; no matmul, so each agent's features are independent of the population size.
        dot = x[..., None, 0] * c[:, 0]
        for j in range(1, self.dim):
            dot = dot + x[..., None, j] * c[:, j]
        return torch.cos(math.pi * dot)

    def step_size_scale(self) -> Tensor:
        """Per-feature step-size factors ``alpha_i / alpha = 1 / ||c_i||_2`` (1 for ``c = 0``)."""
        norm = self.coefficients.square().sum(-1).sqrt()
        return torch.where(norm == 0, torch.ones_like(norm), 1.0 / norm)

    def extra_repr(self) -> str:
        return f"dim={self.dim}, order={self.order}, num_features={self.num_features}"
