"""Polynomial features: every monomial of total degree <= ``degree``, the constant included.

The paper's initiation-set classifiers (section 5.1) use logistic regression on 2nd-order
polynomial features of the 4-d Pinball state: 15 features.

Order: by total degree, then within a degree in ``itertools.combinations_with_replacement``
order of the variable indices. For dim 2, degree 2: ``1, x1, x2, x1^2, x1 x2, x2^2``.

Example:
    >>> import torch
    >>> poly = PolynomialFeatures(dim=2, degree=2)
    >>> poly(torch.tensor([[2.0, 3.0]], dtype=torch.float64)).tolist()
    [[1.0, 2.0, 3.0, 4.0, 6.0, 9.0]]
    >>> PolynomialFeatures(dim=4, degree=2).num_features
    15
"""

from __future__ import annotations

import itertools

import torch
from torch import Tensor, nn


class PolynomialFeatures(nn.Module):
    """All monomials of ``x [..., dim]`` of total degree at most ``degree``.

    Buffers:
        exponents: ``[F, dim]`` the exponent of each variable in each monomial (float).
        factor_index: ``[F, max(degree, 1)]`` indices into ``[1, x_1, ..., x_dim]`` whose
            product is the monomial (index 0 is the constant 1, used as padding).
    """

    def __init__(self, dim: int, degree: int, dtype: torch.dtype = torch.float64):
        super().__init__()
        if dim < 1 or degree < 0:
            raise ValueError(f"need dim >= 1 and degree >= 0, got dim={dim}, degree={degree}")
        self.dim = dim
        self.degree = degree
        width = max(degree, 1)
        factors, exponents = [], []
        for total in range(degree + 1):
            for combo in itertools.combinations_with_replacement(range(dim), total):
                factors.append([i + 1 for i in combo] + [0] * (width - total))
                exponents.append([combo.count(i) for i in range(dim)])
        self.register_buffer("exponents", torch.tensor(exponents, dtype=dtype))
        self.register_buffer("factor_index", torch.tensor(factors, dtype=torch.int64))
        self.num_features = len(factors)

    def forward(self, x: Tensor) -> Tensor:
        """Map ``[..., dim]`` to ``[..., num_features]``."""
        x = x.to(self.exponents.dtype)
        padded = torch.cat([torch.ones_like(x[..., :1]), x], dim=-1)
        # Repeated elementwise products (never pow): exact x*x and population-invariant.
        out = padded[..., self.factor_index[:, 0]]
        for j in range(1, self.factor_index.shape[1]):
            out = out * padded[..., self.factor_index[:, j]]
        return out

    def extra_repr(self) -> str:
        return f"dim={self.dim}, degree={self.degree}, num_features={self.num_features}"
