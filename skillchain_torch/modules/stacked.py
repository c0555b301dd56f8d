"""One affine layer of G stacked networks, the bias inside the matmul.

A population holds one small network per agent (or per agent and option slot), their weights
stacked ``[G, ...]`` and evaluated together. A broadcast bias's gradient is a sum over the
batch rows, a reduction whose order torch's kernels may choose by tensor size; here the input
gains a column of ones and the weight the bias as its last row, so both gradients come out of
one batched matmul's backward. (Seen on the option head's output bias: 1e-20 apart between an
agent alone and the same agent among 3 after one step. Batched matmuls themselves may still
round differently for different G on some shapes, so this removes one P-dependence, not all.)

Example:
    >>> import torch
    >>> x = torch.rand(3, 5, 4, dtype=torch.float64)             # G = 3 networks, 5 rows each
    >>> w, b = torch.rand(3, 4, 2, dtype=torch.float64), torch.rand(3, 2, dtype=torch.float64)
    >>> y = stacked_affine(x, w, b)
    >>> y.shape, torch.allclose(y, x @ w + b[:, None])
    (torch.Size([3, 5, 2]), True)
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["stacked_affine"]


def stacked_affine(x: Tensor, weight: Tensor, bias: Tensor) -> Tensor:
    """``x [G, N, I] @ weight [G, I, O] + bias [G, O]`` as one batched matmul (``[G, N, O]``)."""
    ones = torch.ones(*x.shape[:-1], 1, dtype=x.dtype, device=x.device)
    return torch.bmm(torch.cat([x, ones], -1), torch.cat([weight, bias[:, None, :]], -2))
