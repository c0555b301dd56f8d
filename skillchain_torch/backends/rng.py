"""CounterRNG's draws in C (``_rng.c``): the same SplitMix64 words, so the same bits.

:class:`~skillchain_torch.rng.CounterRNG` asks :func:`draw` first and computes the draw with
int64 tensor operations where it answers ``None``. A draw is ~15 small tensor operations
(shifts, xors, products, the counter update), ~0.1 ms a step for one agent, where the
arithmetic is a few nanoseconds.

Example:
    >>> import torch
    >>> seeds, counter = torch.tensor([0]), torch.tensor([0])
    >>> drawn = draw(seeds, counter, 1, None, salt=0, uniform=False)
    >>> words, counter = drawn if AVAILABLE else (torch.tensor([[-2152535657050944081]]),
    ...                                           torch.tensor([1]))
    >>> words.tolist(), counter.tolist()        # SplitMix64's first word of seed 0
    ([[-2152535657050944081]], [1])
"""

from __future__ import annotations

import torch
from torch import Tensor

try:
    from skillchain_torch.backends import _rng as _c
except ImportError:  # built without a C compiler: CounterRNG's tensor path
    _c = None

__all__ = ["AVAILABLE", "draw"]

AVAILABLE = _c is not None
# Used wherever built (the same bits: no choice to make), by a CounterRNG that took it when
# built (skillchain_torch.backends.select.same_bits_kernel; same_bits_kernels builds without).


def draw(seeds: Tensor, counter: Tensor, n: int, mask: Tensor | None, salt: int,
         uniform: bool) -> tuple[Tensor, Tensor] | None:  # fmt: skip
    """``(out [P, n], new counter [P])``: words ``counter[p] .. counter[p] + n - 1`` of agent
    ``p``'s stream (``seeds[p] ^ salt``), as int64 bits or as float64 uniforms in [0, 1) from
    their 53 high bits; the counter advances by ``n`` where ``mask [P]`` (default every agent).
    ``None`` where the kernel does not apply (switched off, not on the CPU, a non-contiguous
    stream, or a mask of another shape, which the tensor path broadcasts or refuses)."""
    if not (seeds.device.type == "cpu" and seeds.is_contiguous()
            and counter.is_contiguous()):  # fmt: skip
        return None
    if mask is not None:
        if mask.dtype != torch.bool or not mask.is_cpu:
            mask = mask.to(device="cpu", dtype=torch.bool)
        mask = mask if mask.is_contiguous() else mask.contiguous()
        if mask.shape != seeds.shape:
            return None
    P = seeds.shape[0]
    out = torch.empty(P, n, dtype=torch.float64 if uniform else torch.int64)
    new_counter = torch.empty_like(counter)
    _c.draw(P, n, seeds.data_ptr(), counter.data_ptr(), 0 if mask is None else mask.data_ptr(),
            salt, uniform, out.data_ptr(), new_counter.data_ptr())  # fmt: skip
    return out, new_counter
