"""The initiation classifier's memberships and fits in C (``_initiation.c``).

:class:`~.compiled_initiation.CompiledInitiation` calls these for an
:class:`~skillchain_torch.options.InitiationClassifier` given one by
:func:`~.select.initiation_kernel` (the skill-chaining agent asks for it with its own compiled
step, on CPU float64):

* :func:`contains`: every slot's membership of one state per agent, each slot one pass (the
  logit, then for constrained slots the stored positives until one is within reach);
* :func:`logistic_sweeps`: :func:`~skillchain_torch.options.logistic.logistic_sweeps` with the
  sweeps in one call instead of five tensor operations each;
* :func:`fit`: the classifier's whole fit of the slots in a mask (features, the terms of
  :func:`~skillchain_torch.options.logistic.sweep_terms`, the sweeps), one pass per slot on its
  stored examples, in place: the numbers of :func:`logistic_sweeps`, bit for bit;
* :func:`store`: :meth:`~skillchain_torch.options.InitiationClassifier.add_examples`'s stores,
  one example after the other, placed as :func:`~skillchain_torch.options.examples.store_places`
  places them (the same reservoir draws), bit for bit; :func:`store_executions` stores the
  examples of ended executions straight from their trace.

Their sums run in a fixed order of their own and the sweeps use an exponential of their own
(:func:`exp`, within 1 ulp of libm's), so they agree with the torch path to rounding, not bit
for bit (a membership differs only for a state within rounding of a boundary). Each
slot's numbers depend on that slot alone, so agent p in a population equals agent p alone.

Example:
    >>> import torch
    >>> x = torch.tensor([[[1.0, 0.0], [1.0, 1.0]]], dtype=torch.float64)
    >>> labels, stored = torch.tensor([[True, False]]), torch.ones(1, 2, dtype=torch.bool)
    >>> params = torch.zeros(1, 3, dtype=torch.float64)
    >>> from skillchain_torch.options import logistic
    >>> fit = logistic_sweeps if AVAILABLE else logistic.logistic_sweeps
    >>> bool(fit(x, labels, stored, params, lr=1.0, sweeps=50)[0, 1] < 0)
    True
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from skillchain_torch.backends.native import for_c
from skillchain_torch.options.examples import RESERVOIR_STREAM
from skillchain_torch.options.logistic import sweep_terms

try:
    from skillchain_torch.backends import _initiation as _c
    from skillchain_torch.backends import _stores as _stores_c
except ImportError:  # built without a C compiler: the classifier keeps its torch path
    _c = _stores_c = None

__all__ = ["AVAILABLE", "Stores", "contains", "exp", "fit", "logistic_sweeps", "store",
           "store_executions", "stores_of"]

AVAILABLE = _c is not None
OBS_DIM = 4


class Stores(NamedTuple):
    """A classifier's example stores as the kernels read and write them (in place): the
    buffers of :class:`~skillchain_torch.options.InitiationClassifier` (``stores``)."""

    examples: Tensor  #: ``[P, K, C, 4]`` float64
    labels: Tensor  #: ``[P, K, C]`` bool
    count: Tensor  #: ``[P, K]`` int64: examples stored
    seen: Tensor  #: ``[P, K]`` int64: examples ever added
    generation: Tensor  #: ``[P, K]`` int64: resets of the slot (the reservoir's draws use it)
    seeds: Tensor  #: ``[P]`` int64: the agents' seeds (the reservoir's draws use them)
    ring: bool  #: ``replacement == "ring"`` (the newest C), else the reservoir
    keep_negatives: bool  #: a positive never replaces a stored negative
    store_failures: bool = False  #: a negative always enters a full store (failure_place)


def stores_of(classifier) -> Stores:
    """An :class:`~skillchain_torch.options.InitiationClassifier`'s stores as the kernels take
    them (they write its buffers in place)."""
    return Stores(classifier.examples, classifier.labels, classifier.count, classifier.seen,
                  classifier.generation, classifier.seeds, classifier.replacement == "ring",
                  classifier.keep_negatives, classifier.store_failures)  # fmt: skip


def contains(factors: Tensor, centered: bool, weight: Tensor, bias: Tensor,
             trained: Tensor, constrained: Tensor, obs: Tensor, examples: Tensor,
             labels: Tensor, count: Tensor, dims: Tensor, distance: float,
             nearest: bool = False) -> Tensor:  # fmt: skip
    """``BoolTensor [P, K]``: the classifier's membership rule for ``obs [P, 4]`` (with
    ``nearest``: ``constrain_nearest``'s).

    ``factors``: the ``factor_index`` of the classifier's :class:`~skillchain_torch.features.
    PolynomialFeatures` (computed here, with the same bits, of ``2 obs - 1`` if ``centered``);
    the others are its parameters and stores as they are (contiguous CPU float64; ``dims``:
    bool ``[4]``, the distance's dims).
    """
    P, K, F = weight.shape
    out = torch.empty(P, K, dtype=torch.bool)
    obs = obs.contiguous()
    _c.contains(P, K, F, examples.shape[2], factors.data_ptr(), factors.shape[1], centered,
                weight.data_ptr(), bias.data_ptr(), trained.data_ptr(), constrained.data_ptr(),
                obs.data_ptr(), examples.data_ptr(), labels.data_ptr(), count.data_ptr(),
                dims.data_ptr(), float(distance), out.data_ptr(), int(nearest))  # fmt: skip
    return out


def logistic_sweeps(x: Tensor, labels: Tensor, stored: Tensor, params: Tensor, lr: float,
                    sweeps: int, balanced: bool = False) -> Tensor:  # fmt: skip
    """:func:`~skillchain_torch.options.logistic.logistic_sweeps` (same arguments, same
    result up to rounding), the sweeps compiled; CPU float64."""
    x, step, minus_step_y = sweep_terms(x, labels, stored, lr, balanced)
    x, step, minus_step_y = x.contiguous(), step.contiguous(), minus_step_y.contiguous()
    v = (-params.to(x.dtype)).contiguous()
    M, L, F1 = x.shape
    _c.sweeps(M, L, F1, x.data_ptr(), step.data_ptr(), minus_step_y.data_ptr(), v.data_ptr(),
              int(sweeps))  # fmt: skip
    return -v


def fit(factors: Tensor, centered: bool, mask: Tensor, examples: Tensor,
        labels: Tensor, count: Tensor, weight: Tensor, bias: Tensor, lr: float, sweeps: int,
        balanced: bool, sweeps_done: Tensor, trained: Tensor, dirty: Tensor) -> Tensor:
    """``sweeps`` gradient steps for every slot in ``mask [P, K]`` (bool) holding data, on its
    stored examples, writing ``weight [P, K, F]`` and ``bias [P, K]`` in place and updating the
    slots' ``sweeps_done``, ``trained`` and ``dirty``; the other arguments are the classifier's
    stores as they are (contiguous CPU). Returns the ``[P, K]`` mask of slots fitted."""
    P, K, F = weight.shape
    mask = mask.contiguous()
    fitted = torch.empty(P, K, dtype=torch.bool)
    _c.fit(P, K, examples.shape[2], F, factors.data_ptr(), factors.shape[1], centered,
           mask.data_ptr(), examples.data_ptr(), labels.data_ptr(), count.data_ptr(),
           weight.data_ptr(), bias.data_ptr(), float(lr), int(sweeps), balanced,
           sweeps_done.data_ptr(), trained.data_ptr(), dirty.data_ptr(),
           fitted.data_ptr())  # fmt: skip
    return fitted


def _stores(stores: Stores, touched: Tensor) -> tuple:
    """The store arguments of the C ``store`` functions, in their order."""
    return (stores.seeds.data_ptr(), stores.generation.data_ptr(), RESERVOIR_STREAM,
            int(stores.ring) | int(stores.keep_negatives) << 1 | int(stores.store_failures) << 2,
            stores.seen.data_ptr(), stores.examples.data_ptr(), stores.labels.data_ptr(),
            stores.count.data_ptr(), touched.data_ptr())  # fmt: skip


def store(stores: Stores, agents: Tensor, slots: Tensor, obs: Tensor, labels: Tensor,
          touched: Tensor) -> bool:  # fmt: skip
    """Store examples ``obs [N, 4]`` (float64) with ``labels [N]`` (bool) for
    ``(agents, slots)`` (int64 ``[N]``) in ``stores``, in order, marking ``touched [P, K]``
    (bool). False (nothing written) if an index is out of range."""
    P, K, C = stores.labels.shape
    status = _stores_c.store(P, K, C, agents.shape[0], agents.data_ptr(), slots.data_ptr(),
                      obs.data_ptr(), labels.data_ptr(), *_stores(stores, touched))
    return status == 0


def store_executions(stores: Stores, states: Tensor, slot: Tensor, duration: Tensor,
                     success: Tensor, failure: Tensor, touched: Tensor) -> int:  # fmt: skip
    """The examples of ended executions (see ``ExecutionTrace.examples``: the first
    ``duration`` states ``[P, T, 4]`` of a success, the first of a failure) stored in slot
    ``slot [P]`` of each agent, marking ``touched [P, K]``; the number of examples."""
    P, K, C = stores.labels.shape
    slot, duration = for_c(slot, torch.int64), for_c(duration, torch.int64)
    success, failure = for_c(success, torch.bool), for_c(failure, torch.bool)
    return _stores_c.store_executions(P, K, C, states.shape[1], states.data_ptr(), slot.data_ptr(),
                               duration.data_ptr(), success.data_ptr(), failure.data_ptr(),
                               *_stores(stores, touched))  # fmt: skip


def exp(x: Tensor) -> Tensor:
    """The sweeps' exponential of a float64 tensor: within 1 ulp of ``torch.exp``, the same
    bits on every CPU (it runs four lanes wide where AVX2 is there, one value at a time
    elsewhere, with the same operations)."""
    x = x.to(torch.float64).contiguous()
    out = torch.empty_like(x)
    _c.exp(x.numel(), x.data_ptr(), out.data_ptr())
    return out
