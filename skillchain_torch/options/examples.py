"""Where new initiation-set examples go in a slot's bounded store (paper section 5.1).

Executions turn into examples (states of a successful trajectory: positive; the start of a
failed one: negative); a slot keeps at most ``capacity`` of them. :func:`store_places` decides,
for a batch of new examples, which place of which slot's store each one takes: in order while
the store has room, then ``"reservoir"`` (the ``n``-th example replaces a uniformly drawn
stored one with probability ``capacity / (n + 1)``, so the store stays a uniform sample of all
seen) or ``"ring"`` (the newest ``capacity``). Pure functions; the store itself is
:class:`~skillchain_torch.options.InitiationClassifier`'s.

Example:
    >>> import torch
    >>> flat = torch.tensor([0, 0, 1])          # two examples for store 0, one for store 1
    >>> zeros = torch.zeros(3, dtype=torch.int64)
    >>> cell, keep = store_places(flat, seen=torch.tensor([0, 3]), seed=zeros, slot=flat,
    ...                           generation=zeros, capacity=4, replacement="ring")
    >>> cell.tolist(), keep.tolist()                    # places 0, 1 of slot 0; place 3 of slot 1
    ([0, 1, 7], [0, 1, 2])
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.rng import GOLDEN_GAMMA, logical_rshift, splitmix64, stream_key

__all__ = ["REPLACEMENTS", "RESERVOIR_STREAM", "reservoir_uniform", "store_places", "failure_place"]

REPLACEMENTS = ("reservoir", "ring")
RESERVOIR_STREAM = stream_key(0x1417)  # the reservoir's salt (also read by the C stores)


def reservoir_uniform(seed: Tensor, slot: Tensor, generation: Tensor, index: Tensor) -> Tensor:
    """A uniform in [0, 1) that is a pure function of ``(seed, slot, generation, index)``.

    Stateless hashing (SplitMix64 chained over the four integers) rather than a counter: the
    draw for an agent's ``index``-th example of a slot never depends on other agents or slots.
    """
    key = splitmix64(seed ^ RESERVOIR_STREAM)
    key = splitmix64(key + slot * GOLDEN_GAMMA)
    key = splitmix64(key + generation * GOLDEN_GAMMA)
    return logical_rshift(splitmix64(key + index * GOLDEN_GAMMA), 11).to(torch.float64) * 2.0**-53


def store_places(flat: Tensor, seen: Tensor, seed: Tensor, slot: Tensor, generation: Tensor,
                 capacity: int, replacement: str) -> tuple[Tensor, Tensor]:  # fmt: skip
    """Places of new examples ``[N]`` in the stores: ``(cell, keep)``.

    Args:
        flat: each example's store (``agent * K + slot``), ``[N]``, in the order they arrive.
        seen: examples each store has seen so far, ``[P * K]``.
        seed, slot, generation: per example, its agent's seed, its slot and the slot's
            generation (the reservoir's draws are a hash of these and the example's number).
        capacity: places per store; replacement: ``"reservoir"`` or ``"ring"``.

    Returns:
        ``cell``: flat places (``store * capacity + place``), each at most once; ``keep``: the
        example written there. Of several new examples landing on one place the last wins, as
        a sequential loop would have it; examples the reservoir rejects are not written.
    """
    n, device = flat.shape[0], flat.device
    # Rank of each example among the earlier ones of its store (stable: insertion order).
    sorted_flat, order = torch.sort(flat, stable=True)
    arange = torch.arange(n, device=device)
    start = torch.ones(n, dtype=torch.bool, device=device)
    start[1:] = sorted_flat[1:] != sorted_flat[:-1]
    first = torch.cummax(torch.where(start, arange, torch.zeros_like(arange)), 0).values
    rank = torch.empty_like(arange)
    rank[order] = arange - first
    index = seen[flat] + rank  # the example's number in its store's history
    if replacement == "ring":
        position = index % capacity
    else:
        u = reservoir_uniform(seed, slot, generation, index)
        draw = torch.minimum(torch.floor(u * (index + 1).to(u.dtype)).to(torch.int64), index)
        position = torch.where(index < capacity, index, torch.where(draw < capacity, draw, -1))
    # Of the examples written to one place keep the last (a stable sort over the few new
    # examples, not a buffer the size of the stores).
    placed = (position >= 0).nonzero()[:, 0]
    cell, order = torch.sort(flat[placed] * capacity + position[placed], stable=True)
    last = torch.ones_like(cell, dtype=torch.bool)
    last[:-1] = cell[1:] != cell[:-1]
    return cell[last], placed[order[last]]


def failure_place(seed: Tensor, slot: Tensor, generation: Tensor, index: Tensor, capacity: int,
                  stored_labels: Tensor) -> int:  # fmt: skip
    """The place a failure (negative example) number ``index >= capacity`` takes in a full
    store under ``store_failures``: never rejected, it replaces the first stored *positive*
    from the reservoir's draw ``mod capacity`` on (cyclically), or the drawn place if every
    stored example is a negative. Late in a run a slot has seen tens of thousands of examples,
    and a plain reservoir keeps a new failure with probability ``capacity / (index + 1)``
    (about 2%), so the set stops learning where its option fails.

    Args: one example's ``seed``, ``slot``, ``generation``, ``index`` (0-d tensors), the
    store's ``capacity`` and its ``stored_labels [capacity]`` (bool).

    Example:
        >>> z = torch.tensor(0)
        >>> labels = torch.tensor([False, True, False, True])
        >>> failure_place(z, z, z, torch.tensor(9), 4, labels) in (1, 3)
        True
    """
    u = reservoir_uniform(seed, slot, generation, index)
    draw = min(int(torch.floor(u * float(int(index) + 1))), int(index))
    first = draw % capacity
    positive = stored_labels.roll(-first).nonzero()
    return (first + int(positive[0, 0])) % capacity if positive.numel() else first
