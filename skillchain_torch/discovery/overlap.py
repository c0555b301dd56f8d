"""No overlap with siblings or parents (paper section 4.3).

"We require that the initiation set of an option does not overlap that of its siblings or
parents." Applied where membership is decided, from the classifier outputs already computed for
action selection (the paper's remark: at most one run of each classifier per visited state):
option k's effective initiation set is its classifier's set minus the sets of

* its parent, the option whose initiation set k targets, and
* its *older* siblings, the options created earlier to target the same event.

Older siblings keep what they hold and a younger one gets the rest, so two siblings never
exclude each other's shared region from both. Only trained classifiers exclude: an untrained
one is "true everywhere" and would empty its relatives. In discovery slots fill in order and
are never freed, so the lower slot of two siblings is the older.

Example:
    >>> import torch
    >>> from skillchain_torch.options import OptionBank
    >>> bank = OptionBank.build(population=1, slots=3, order=1, capacity=8)
    >>> for _ in range(2):
    ...     _ = bank.allocate(torch.tensor([True]), target_event=0)   # two goal options
    >>> bank.classifier.trained[:] = True
    >>> raw = torch.tensor([[True, True, True]])
    >>> exclude_overlap(raw, overlap_exclusion(bank), bank.classifier.trained).tolist()
    [[True, False, True]]
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.backends import discovery as backend
from skillchain_torch.options import OptionBank

__all__ = ["overlap_exclusion", "exclude_overlap"]


def overlap_exclusion(bank: OptionBank) -> Tensor:
    """``BoolTensor [P, K, K]``: ``[p, k, j]`` when option k must stay out of j's set
    (j is k's parent, or an older sibling: same target, lower slot)."""
    live = bank.live()
    K = bank.slots
    slots = torch.arange(K, device=live.device)
    parent = bank.parent[..., None] == slots  # [P, K, K]: j is k's parent
    chained = bank.parent >= 0
    same_parent = chained[..., None] & (bank.parent[..., None] == bank.parent[:, None, :])
    same_event = (~chained & (bank.target_event >= 0))[..., None] & (~chained)[:, None, :] & (
        bank.target_event[..., None] == bank.target_event[:, None, :]
    )
    older = slots[None, :] < slots[:, None]  # [k, j]: j < k
    sibling = (same_parent | same_event) & older
    both_live = live[..., None] & live[:, None, :]
    return (parent | sibling) & both_live


def exclude_overlap(contains: Tensor, exclusion: Tensor, trained: Tensor) -> Tensor:
    """The effective memberships ``[P, K]``: ``contains`` minus the trained sets each option
    must avoid (``exclusion`` from :func:`overlap_exclusion`)."""
    if backend.NATIVE and backend.applies(contains, exclusion):
        return backend.exclude_overlap(contains, exclusion, trained)
    blocking = contains & trained  # [P, J]
    excluded = (exclusion & blocking[:, None, :]).any(-1)
    return contains & ~excluded
