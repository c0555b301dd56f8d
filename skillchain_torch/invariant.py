"""Reductions whose per-agent result does not depend on the population size.

The reproducibility contract (DESIGN.md) asks that agent ``p`` computes bit-identical numbers
whether it runs alone (P = 1) or inside a population of P agents. Elementwise arithmetic is
layout-invariant, but ``bmm`` / ``einsum`` / ``matmul`` over a population are not (the BLAS
kernel blocks differently for different batch shapes). A CPU sum over a contiguous last dim is
row-independent *except* when the whole result is a single number and the input has at least
``GRAIN_SIZE`` (32768) elements: then ATen splits the reduced dim across threads and adds the
partial sums in a different order. :func:`rowwise_sum` avoids that case by giving the reduction a
second (zero) row, so every row is always summed by one thread, in one fixed order.

Example:
    >>> import torch
    >>> a = torch.rand(5, 3, 40_000, dtype=torch.float64)
    >>> b = torch.rand(5, 1, 40_000, dtype=torch.float64)
    >>> together = rowwise_dot(a, b)            # [5, 3]
    >>> alone = rowwise_dot(a[2:3, 1:2], b[2:3])  # [1, 1], a single output
    >>> bool(together[2, 1] == alone[0, 0])
    True
"""

from __future__ import annotations

import torch
from torch import Tensor


def rowwise_sum(x: Tensor) -> Tensor:
    """Sum over the last dim, each row reduced by one thread in a fixed order.

    Args:
        x: tensor ``[..., N]``.

    Returns:
        ``[...]``, bit-identical for a given row whatever the leading shape is.
    """
    # A strided last dim would be reduced lane-by-lane across rows (a different order).
    x = x.contiguous()
    if x.numel() // max(x.shape[-1], 1) == 1:
        # A single output row would let ATen's two-pass reduction split it across threads.
        pad = torch.stack([x.reshape(-1), torch.zeros_like(x.reshape(-1))])
        return pad.sum(-1)[0].reshape(x.shape[:-1])
    return x.sum(-1)


def rowwise_dot(a: Tensor, b: Tensor) -> Tensor:
    """Batch-invariant ``(a * b).sum(-1)`` with broadcasting; never a BLAS call."""
    return rowwise_sum(a * b)


def least_squares(h: Tensor, y: Tensor) -> Tensor:
    """``[F, C]`` minimising ``||h w - y||`` for ``h [N, F]``, ``y [N, C]``, through ``pinv`` (an
    SVD) and :func:`rowwise_dot`: the same bits on every call (``lstsq`` and ``matmul`` round
    differently with the operands' addresses).

    Example:
        >>> h = torch.tensor([[1.0, 0.0], [1.0, 1.0], [1.0, 2.0]], dtype=torch.float64)
        >>> least_squares(h, h @ torch.tensor([[2.0], [3.0]], dtype=torch.float64)).round(
        ...     decimals=9).tolist()
        [[2.0], [3.0]]
    """
    pinv = torch.linalg.pinv(h)  # [F, N]
    return rowwise_dot(pinv[None, :, :], y.T.contiguous()[:, None, :]).T  # [F, C]


def affine_rows(x: Tensor, weight: Tensor, bias: Tensor) -> Tensor:
    """``x [N, I] @ weight.T + bias`` for ``weight [O, I]``, ``bias [O]``, by
    :func:`rowwise_dot` (no BLAS call: the same bits whatever the operands' addresses)."""
    return rowwise_dot(x[:, None, :], weight[None]) + bias

