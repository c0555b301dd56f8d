"""What the compiled kernels' Python sides share: a state resumes only on its own kind, and
arrays reach C contiguous and of the kernel's dtype (:func:`for_c`).

The flat agent (:mod:`skillchain_torch.backends.sarsa`) and the hierarchical agents
(:mod:`skillchain_torch.backends.hierarchical`) each have a torch path and a compiled
one. Their sums run in different orders, so a run saved by one kind and continued by the other
would match neither an uninterrupted torch run nor an uninterrupted compiled one. Agents store
their kind in their state (``"native"``) and refuse a state of the other kind.

Example:
    >>> check_same_kernels({"native": True}, native=True)
    >>> check_same_kernels({}, native=True)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: this state was saved by a torch-kernel agent, and this agent uses the native ...
    >>> import torch
    >>> flags = torch.ones(3, dtype=torch.bool)
    >>> for_c(flags, torch.bool) is flags, for_c(torch.ones(3), torch.bool).dtype
    (True, torch.bool)
"""

from __future__ import annotations

import torch

__all__ = ["check_same_kernels", "for_c"]


def for_c(x: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """``x`` as a contiguous tensor of ``dtype`` whose address C may read; ``x`` itself, with no
    call into torch, when it already is one (this runs a dozen times a step, and a no-op
    ``Tensor.to`` still costs a few microseconds)."""
    if x.dtype != dtype:
        x = x.to(dtype)
    return x if x.is_contiguous() else x.contiguous()


def check_same_kernels(state: dict, native: bool) -> None:
    """``ValueError`` unless ``state`` (an agent's ``state_dict``; no ``"native"`` key: saved
    before the compiled kernels, i.e. torch) was saved by an agent of kind ``native``."""
    saved = bool(state.get("native", False))
    if saved != native:
        raise ValueError(
            f"this state was saved by a {'native' if saved else 'torch'}-kernel agent, and "
            f"this agent uses the {'native' if native else 'torch'} kernels, whose "
            "rounding differs: resume with the same kind (native=... in Python; "
            "skillchain train --torch-only for torch kernels)")
