"""One scale for a copied option policy and the option's own targets (issue 30).

A policy copied from the top level (``policy_start="top-level"``) values a state by the agent's
return *to the goal* through it. The option's own Q-learning target is different: section 4.1
sets its reward to "R plus an option completion reward for triggering T", so at its target it
learns toward ``r + C`` and stops there. The two disagree by the top level's value of the
target: for the goal option (target: the goal, where the episode ends and the top level's own
target is ``r + 0``) by ``C``; for a chained option (target: its parent's initiation set,
where the top level bootstraps on ``V(s')``) by ``C - V(s')``, which on the hard instance is
tens of thousands. Learning from the copy then starts with TD errors of that size at every
target entry, and one of them flips the greedy policy over most of the set.

``policy_start="top-level-shifted"`` adds that difference to the copy, as a constant (the
option basis's first feature is the constant 1): ``C - V`` where ``V`` is 0 for a base target
event (the episode ends there) and, for a chained option, the top level's mean state value
``max_a Q(s, a)`` over its parent's stored positive examples (the states of the target region
the agent has actually reached). The copied policy is unchanged (a constant per option); only
its values move onto the option's own scale.

Example:
    >>> import torch
    >>> from skillchain_torch.features import FourierBasis
    >>> from skillchain_torch.modules import LinearQHead
    >>> from skillchain_torch.options import OptionBank
    >>> bank = OptionBank.build(population=1, slots=2, order=1, capacity=4)
    >>> _ = bank.allocate(torch.tensor([True]), target_event=0)       # slot 0: the goal
    >>> _ = bank.allocate(torch.tensor([True]), parent=torch.tensor([0]))  # slot 1: chained
    >>> x = torch.full((1, 4), 0.5, dtype=torch.float64)
    >>> bank.classifier.add_examples(0, 0, x, torch.tensor([True])).tolist()
    [[True, False]]
    >>> basis = FourierBasis(4, 1)
    >>> head = LinearQHead(num_features=basis.num_features, num_decisions=7, population=1)
    >>> head.weight.data[0, 2, 0] = 3000.0                  # max_a Q(s, a) = 3000 everywhere
    >>> target_levels(bank, head, basis, torch.tensor([[True, True]])).tolist()
    [[0.0, 3000.0]]
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import OptionBank

__all__ = ["target_levels", "shift_option_values"]


@torch.no_grad()
def target_levels(bank: OptionBank, q_head: LinearQHead, basis: FourierBasis,
                  mask: Tensor, num_primitives: int | None = None) -> Tensor:  # fmt: skip
    """``[P, K]``: the top level's value of each masked option's target (module docstring);
    0 for a base target event and where the parent has no stored positive example."""
    num_primitives = bank.num_actions if num_primitives is None else num_primitives
    clf = bank.classifier
    levels = torch.zeros(mask.shape, dtype=torch.float64, device=mask.device)
    for p, k in mask.nonzero().tolist():
        parent = int(bank.parent[p, k])
        if parent < 0:
            continue  # a base event: the episode ends there (the goal), the top level's 0
        n = int(clf.count[p, parent])
        positive = clf.labels[p, parent, :n].to(torch.bool)
        if not bool(positive.any()):
            continue
        states = clf.examples[p, parent, :n][positive].to(torch.float64)
        q = basis(states) @ q_head.weight[p, :num_primitives].T  # [N, A]
        levels[p, k] = q.max(-1).values.mean()
    return levels


@torch.no_grad()
def shift_option_values(option_head, mask: Tensor, shift: Tensor) -> None:
    """Add ``shift [P, K]`` to every action value of the masked options of a Fourier option
    head (the weight of its constant first feature)."""
    weight = option_head.weight  # [P, K, A, F]
    for p, k in mask.nonzero().tolist():
        weight[p, k, :, 0] += shift[p, k].to(weight.dtype)
