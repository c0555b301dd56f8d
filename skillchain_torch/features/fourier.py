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

from skillchain_torch.backends.select import same_bits_kernel


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
        self.register_buffer("_k", torch.arange(order + 1, dtype=dtype), persistent=False)
        self.num_features = len(coefficients)
        # The compiled features (the same bits) where built, chosen once: None, the torch path.
        self._kernel = same_bits_kernel("fourier")

    def forward(self, x: Tensor) -> Tensor:
        """Map states ``[..., dim]`` to features ``[..., num_features]``."""
        lead = x.shape[:-1]
        if x.dtype != self._k.dtype:
            x = x.to(self._k.dtype)
        x = x.reshape(-1, self.dim)
        kernel = self._kernel
        phi = None if kernel is None else kernel(x, self.dim, self.order, self.num_features)
        if phi is not None:
            return phi.reshape(*lead, self.num_features)
        n = x.shape[0]
        # c . x accumulated left to right, as a sequential implementation does, but built by
        # broadcast additions of t_j[k] = x_j * k (k = 0..order): dot[c] = ((t_0[c_0] + t_1[c_1])
        # + ...), last dimension fastest. Same bits as sum_j x_j * c_j in that order, a handful
        # of operations instead of a gather or a matmul, and each row (agent) is computed
        # independently of the others, so features do not depend on the population size.
        table = (x[:, :, None] * self._k).unsqueeze(2).unbind(1)  # dim x [n, 1, order + 1]
        dot = table[0]
        for t in table[1:]:
            dot = dot.view(n, -1, 1) + t
        return torch.cos(math.pi * dot.view(n, -1)).reshape(*lead, self.num_features)

    def step_size_scale(self) -> Tensor:
        """Per-feature step-size factors ``alpha_i / alpha = 1 / ||c_i||_2`` (1 for ``c = 0``)."""
        norm = self.coefficients.square().sum(-1).sqrt()
        return torch.where(norm == 0, torch.ones_like(norm), 1.0 / norm)

    def extra_repr(self) -> str:
        return f"dim={self.dim}, order={self.order}, num_features={self.num_features}"
