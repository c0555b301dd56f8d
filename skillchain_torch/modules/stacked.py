"""One affine layer of G stacked networks, with each network's arithmetic its own.

A population holds one small network per agent (or per agent and option slot), their weights
stacked ``[G, ...]`` and evaluated together. For the runs of a population to be independent
samples *bit for bit* (an agent re-run alone returns exactly what it returned among others:
what ``skillchain verify`` checks), each network's arithmetic must not depend on how many
others share the call. A batched matmul over G gives that: every batch element is the same
small matmul whatever G is. A broadcast bias does not: its gradient is a sum over the batch
rows that torch's reduction kernels may order differently for different tensor sizes (seen on
the option head's output bias: 1e-20 apart between P = 1 and P = 3 after one step, and then
whole episodes apart). So the bias rides in the matmul: the input gains a column of ones and
the weight the bias as its last row, and both gradients come out of the matmul's backward.

Example:
    >>> import torch
    >>> x = torch.rand(3, 5, 4, dtype=torch.float64)             # G = 3 networks, 5 rows each
    >>> w, b = torch.rand(3, 4, 2, dtype=torch.float64), torch.rand(3, 2, dtype=torch.float64)
    >>> y = stacked_affine(x, w, b)
    >>> y.shape, torch.allclose(y, x @ w + b[:, None])
    (torch.Size([3, 5, 2]), True)
    >>> bool((stacked_affine(x[:1], w[:1], b[:1]) == y[:1]).all())  # network 0 alone: same bits
    True
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["stacked_affine"]


def stacked_affine(x: Tensor, weight: Tensor, bias: Tensor) -> Tensor:
    """``x [G, N, I] @ weight [G, I, O] + bias [G, O]`` as one batched matmul (``[G, N, O]``)."""
    ones = torch.ones(*x.shape[:-1], 1, dtype=x.dtype, device=x.device)
    return torch.bmm(torch.cat([x, ones], -1), torch.cat([weight, bias[:, None, :]], -2))
