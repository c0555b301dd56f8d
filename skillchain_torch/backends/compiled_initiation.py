"""The built-in initiation classifier's memberships, fits and stores in C: chosen once.

:class:`CompiledInitiation` is what :func:`~.select.initiation_kernel` hands an
:class:`~skillchain_torch.options.InitiationClassifier` that is exactly the built-in class,
on the CPU in float64 with 4-d observations, where :mod:`.initiation`'s kernels are built (the
hierarchical agent asks for it once, when it is built, with its own compiled step). The
classifier keeps it as ``_kernel`` and calls it in place of its torch path in ``contains``,
``fit`` and ``add_examples``, so its own file reads as the torch path alone. The sums run in an
order of their own (equal to the torch path to rounding); the stores' places are the torch
path's, bit for bit.

Example:
    >>> from skillchain_torch.options import InitiationClassifier
    >>> clf = InitiationClassifier(population=1, slots=2, capacity=8)
    >>> clf.set_native(None) == AVAILABLE, isinstance(clf._kernel, CompiledInitiation) == AVAILABLE
    (True, True)
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends import initiation as kernels
from skillchain_torch.backends.native import for_c

__all__ = ["AVAILABLE", "CompiledInitiation"]

AVAILABLE = kernels.AVAILABLE
OBS_DIM = kernels.OBS_DIM


class CompiledInitiation:
    """The compiled calls of one :class:`~skillchain_torch.options.InitiationClassifier`
    (see the module docstring). It holds only the distance's dims as the kernels read them;
    every call reads the classifier it is given and writes its buffers in place, as the torch
    path does."""

    def __init__(self, distance_dims) -> None:
        dims = torch.zeros(OBS_DIM, dtype=torch.bool)
        dims[list(distance_dims)] = True
        self.dims = dims

    def contains(self, clf, obs: Tensor) -> Tensor:
        """``[P, K]``: the membership rule of ``clf.contains`` for ``obs [P, 4]`` (checked)."""
        return kernels.contains(
            clf.features.factor_index, clf.centered, clf.weight, clf.bias, clf.trained,
            clf.constrained, obs, clf.examples, clf.labels, clf.count, self.dims, clf.distance,
            clf.constrain_nearest)  # fmt: skip

    @staticmethod
    def fit(clf, mask: Tensor) -> Tensor:
        """``clf.fit(mask)`` in one pass: the ``[P, K]`` slots fitted."""
        return kernels.fit(
            clf.features.factor_index, clf.centered, for_c(mask, torch.bool), clf.examples,
            clf.labels, clf.count, clf.weight, clf.bias, clf.lr, clf.sweeps, clf.balanced,
            clf.sweeps_done, clf.trained, clf.dirty)  # fmt: skip

    @staticmethod
    def add_examples(clf, agents: Tensor, slots: Tensor, obs: Tensor,
                     labels: Tensor) -> Tensor | None:  # fmt: skip
        """The stores of ``clf.add_examples`` (``[N]`` agents, slots and labels, ``obs
        [N, 4]``) one example after the other: the ``[P, K]`` slots that received data, or
        ``None`` when an agent or slot index is out of range (nothing stored)."""
        touched = torch.zeros(clf.population, clf.slots, dtype=torch.bool)
        ok = kernels.store(kernels.stores_of(clf), agents.contiguous(), slots.contiguous(),
                           for_c(obs, torch.float64), for_c(labels, torch.bool), touched)
        return touched if ok else None
