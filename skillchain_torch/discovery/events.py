"""The target-event list of skill chaining (paper sections 4.2-4.4), per agent.

An agent's target events are the *base* events, shared by all agents and indexed ``0..E-1``
(the end-of-episode goal first, then any indicator the user adds, e.g. a novelty event), and
the initiation sets of its LEARNED options (slot ``j``: the chaining step). An event leaves the
list once ``max_branching`` options target it (section 4.3); a learned set joins it.

Which option targets what is read from the :class:`~skillchain_torch.options.OptionBank`:
slot ``k`` with ``parent[k] = j >= 0`` targets slot j's initiation set; with ``parent[k] < 0``
it targets base event ``target_event[k]``. Everything here is a pure function of the bank's
``[P, K]`` metadata and elementwise, so agent p's answers never depend on the other agents.

Example:
    >>> import torch
    >>> from skillchain_torch.options import OptionBank, OptionStatus
    >>> bank = OptionBank.build(population=1, slots=4, order=1, capacity=8)
    >>> _ = bank.allocate(torch.tensor([True]), target_event=0)      # slot 0 -> goal
    >>> _ = bank.allocate(torch.tensor([True]), parent=0)            # slot 1 -> I(slot 0)
    >>> base, slot = targeting(bank, num_base=1)
    >>> base.sum(1).tolist(), slot.sum(1).tolist()                   # options per event
    ([[1]], [[1, 0, 0, 0]])
    >>> bank.set_status(torch.tensor([[True, False, False, False]]), OptionStatus.LEARNED)
    >>> [t.tolist() for t in event_list(bank, num_base=1)]           # goal, I(slot 0) listed
    [[[True]], [[True, False, False, False]]]
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from skillchain_torch.backends import discovery as backend
from skillchain_torch.options import OptionBank, OptionStatus, TerminationPredicate

__all__ = ["MAX_BRANCHING", "targeting", "event_list", "evaluate_base_events",
           "target_indicator", "entered"]  # fmt: skip

MAX_BRANCHING = 3  # paper 5.1: "a maximum branching factor of 3"


def targeting(bank: OptionBank, num_base: int) -> tuple[Tensor, Tensor]:
    """Which live option targets which event.

    Returns:
        ``base [P, K, E]``: slot k targets base event e; ``slot [P, K, K]``: slot k targets
        slot j's initiation set (``[p, k, j]``, i.e. j is k's parent in the skill tree).
    """
    live = bank.live()
    chained = bank.parent >= 0
    events = torch.arange(num_base, device=live.device)
    base = (live & ~chained)[..., None] & (bank.target_event[..., None] == events)
    slots = torch.arange(bank.slots, device=live.device)
    slot = (live & chained)[..., None] & (bank.parent[..., None] == slots)
    return base, slot


def event_list(bank: OptionBank, num_base: int,
               max_branching: int = MAX_BRANCHING) -> tuple[Tensor, Tensor]:  # fmt: skip
    """The target events on each agent's list: ``(base [P, E], slot [P, K])``.

    A base event is listed until ``max_branching`` options target it; slot j's initiation set
    is listed once the option is LEARNED, until ``max_branching`` options target it.
    """
    if backend.NATIVE and backend.applies(bank.status):
        return backend.event_list(bank.parent, bank.target_event, bank.status,
                                           num_base, max_branching)  # fmt: skip
    base, slot = targeting(bank, num_base)
    base_on = base.sum(1) < max_branching
    slot_on = (bank.status == OptionStatus.LEARNED) & (slot.sum(1) < max_branching)
    return base_on, slot_on


def evaluate_base_events(events: Sequence[TerminationPredicate], obs: Tensor,
                         terminated: Tensor) -> Tensor:  # fmt: skip
    """``BoolTensor [P, E]``: every base event's indicator at ``obs [P, 4]``."""
    if not events:
        return torch.zeros(obs.shape[0], 0, dtype=torch.bool, device=obs.device)
    if len(events) == 1:  # the paper's goal alone, every step: a view, not a stack
        fired = events[0](obs, terminated)
        return (fired if fired.device == obs.device else fired.to(obs.device)).unsqueeze(-1)
    return torch.stack([e(obs, terminated).to(obs.device) for e in events], dim=-1)


def target_indicator(bank: OptionBank, base_fired: Tensor, contains: Tensor) -> Tensor:
    """``[P, K]``: each live slot's target event at a state, from the base events' values
    ``base_fired [P, E]`` and the initiation-set memberships ``contains [P, K]`` there.

    The same answer as :meth:`OptionBank.target_reached`, without evaluating any event again.
    """
    if backend.NATIVE and backend.applies(contains, bank.status):
        return backend.target_indicator(bank.parent, bank.target_event, bank.status,
                                                 base_fired, contains)  # fmt: skip
    chained = bank.parent >= 0
    from_parent = contains.gather(1, bank.parent.clamp(min=0))
    if base_fired.shape[1] == 0:
        from_base = torch.zeros_like(from_parent)
    else:
        index = bank.target_event.clamp(min=0, max=base_fired.shape[1] - 1)
        from_base = base_fired.gather(1, index) & (bank.target_event >= 0)
    return torch.where(chained, from_parent, from_base) & bank.live()


def entered(before: Tensor, after: Tensor) -> Tensor:
    """An event is *triggered* by a transition that enters it: false at ``s``, true at ``s'``.

    For the goal (only ever true at the last state) this is the event itself; for an
    initiation set it is the first step inside it, not every step spent there.
    """
    return after & ~before
