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

__all__ = ["AugmentedCache", "augment", "augmented_affine", "stacked_affine"]


def augment(weight: Tensor, bias: Tensor) -> Tensor:
    """``weight [G, I, O]`` with ``bias [G, O]`` as its last row: ``[G, I + 1, O]``."""
    return torch.cat([weight, bias[:, None, :]], -2)


def augmented_affine(x: Tensor, augmented: Tensor) -> Tensor:
    """``x [G, N, I]`` with a column of ones, times ``augmented [G, I + 1, O]``."""
    ones = torch.ones(*x.shape[:-1], 1, dtype=x.dtype, device=x.device)
    return torch.bmm(torch.cat([x, ones], -1), augmented)


def stacked_affine(x: Tensor, weight: Tensor, bias: Tensor) -> Tensor:
    """``x [G, N, I] @ weight [G, I, O] + bias [G, O]`` as one batched matmul (``[G, N, O]``)."""
    return augmented_affine(x, augment(weight, bias))


class AugmentedCache:
    """Augmented weights kept until one of the tensors they were built from changes.

    A module's acting forwards (no gradient) rebuild the same augmented weights every step
    between two updates; :meth:`get` returns the last ones while every tensor is the same
    object at the same version and address (``Tensor._version`` counts in-place writes,
    including through views; a ``.data`` swap keeps the version but moves the address). It
    holds the tensors, so an address cannot be reused by another tensor while its
    entry lives. Where a gradient is wanted it always builds afresh.

    Example:
        >>> w, b = torch.zeros(1, 2, 1), torch.zeros(1, 1)
        >>> cache = AugmentedCache()
        >>> first = cache.get([w, b], lambda: [augment(w, b)])
        >>> cache.get([w, b], lambda: [augment(w, b)]) is first
        True
        >>> _ = b.add_(1.0)                                   # a write: built again
        >>> cache.get([w, b], lambda: [augment(w, b)])[0][0, -1].tolist()
        [1.0]
    """

    def __init__(self, size: int = 4):
        self.size = int(size)
        self._entries: dict[int, tuple] = {}

    def get(self, tensors, build):
        if torch.is_grad_enabled() and any(t.requires_grad for t in tensors):
            return build()
        versions = tuple((t._version, t.data_ptr()) for t in tensors)  # (.data swaps: new ptr)
        entry = self._entries.get(id(tensors[0]))
        if (entry is not None and len(entry[0]) == len(tensors) and entry[1] == versions
                and all(a is b for a, b in zip(entry[0], tensors))):  # fmt: skip
            return entry[2]
        value = build()
        if len(self._entries) >= self.size:
            self._entries.clear()
        self._entries[id(tensors[0])] = (tuple(tensors), versions, value)
        return value
