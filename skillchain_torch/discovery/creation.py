"""Option creation (paper sections 4.1 and 4.3): a triggered target event spawns an option.

When a transition ``s -> s'`` triggers (enters) a target event on the agent's list, the agent
creates an option whose termination condition is that event, *unless* ``s`` already lies in
the initiation set of an option targeting that event (the covered-start exception). An
executing option that reaches its own target does not count as uncovered either: it was
started inside its initiation set, and reaching the target is its success, not a new event.

At most one option is created per agent and step; when several listed events fire at once
the first base event wins (the goal before user events), then the lowest slot.

Example:
    >>> import torch
    >>> base_trig = torch.tensor([[True], [True], [False]])        # the goal fired for 0 and 1
    >>> slot_trig = torch.zeros(3, 2, dtype=torch.bool)
    >>> covered = (torch.tensor([[False], [True], [False]]), torch.zeros(3, 2, dtype=torch.bool))
    >>> create, event, parent = choose_creation(base_trig, slot_trig, *covered)
    >>> create.tolist(), event.tolist(), parent.tolist()
    ([True, False, False], [0, -1, -1], [-1, -1, -1])
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.options import OptionBank

from .events import targeting

__all__ = ["covered_start", "choose_creation"]


def covered_start(bank: OptionBank, num_base: int, contains: Tensor,
                  executing: Tensor) -> tuple[Tensor, Tensor]:  # fmt: skip
    """Events whose trigger at this transition is *covered*: ``(base [P, E], slot [P, K])``.

    Args:
        bank: the options (their targets).
        num_base: E, the number of base events.
        contains: ``[P, K]`` initiation-set membership of ``s``, the state the trigger came
            from (computed for action selection at ``s``: no classifier runs again).
        executing: ``LongTensor [P]`` the option executing during the transition, -1 none.
    """
    base, slot = targeting(bank, num_base)  # [P, K, E], [P, K, K]
    base_cov = (base & contains[..., None]).any(1)
    slot_cov = (slot & contains[..., None]).any(1)
    # The executing option's own target: its start state was in its initiation set.
    agents = torch.arange(bank.population, device=contains.device)
    running = (executing >= 0)[:, None]
    k = executing.clamp(min=0)
    base_cov = base_cov | (running & base[agents, k])
    slot_cov = slot_cov | (running & slot[agents, k])
    return base_cov, slot_cov


def choose_creation(base_trig: Tensor, slot_trig: Tensor, base_cov: Tensor,
                    slot_cov: Tensor) -> tuple[Tensor, Tensor, Tensor]:  # fmt: skip
    """Which agents create an option now, and what it targets.

    Args:
        base_trig, slot_trig: ``[P, E]`` / ``[P, K]`` listed events triggered by this
            transition (on the list *and* entered).
        base_cov, slot_cov: the covered events of :func:`covered_start`.

    Returns:
        ``(create [P], target_event [P], parent [P])``: the new option targets base event
        ``target_event`` (``parent = -1``) or slot ``parent``'s initiation set
        (``target_event = -1``).
    """
    candidates = torch.cat([base_trig & ~base_cov, slot_trig & ~slot_cov], dim=-1)
    create = candidates.any(-1)
    first = candidates.to(torch.int64).argmax(-1)
    num_base = base_trig.shape[1]
    none = torch.full_like(first, -1)
    target_event = torch.where(create & (first < num_base), first, none)
    parent = torch.where(create & (first >= num_base), first - num_base, none)
    return create, target_event, parent
