"""Option slot statuses and slot addressing.

Every agent of a population holds a fixed number K of option *slots*; a slot's status follows the
life of an option in the paper (section 5.1):

- ``EMPTY``: no option.
- ``GESTATING``: just created; its policy learns off-policy only and it cannot be executed
  (the paper's 10-episode "gestation period").
- ``LEARNING``: in the agent's repertoire; its initiation set is being learned.
- ``LEARNED``: the initiation set converged (weights changed on average < 0.15 per episode twice
  in a row); it is constrained to points near positive examples and becomes a target event.

Example:
    >>> OptionStatus.LEARNING > OptionStatus.GESTATING, int(OptionStatus.LEARNED)
    (True, 3)
    >>> slot_mask(torch.tensor([True, False, True]), torch.tensor([1, 0, 2]), 3).tolist()
    [[False, True, False], [False, False, False], [False, False, True]]
"""

from __future__ import annotations

from enum import IntEnum

import torch
from torch import Tensor


class OptionStatus(IntEnum):
    """The status of one option slot (stored as ``int64`` tensors ``[P, K]``)."""

    EMPTY = 0
    GESTATING = 1
    LEARNING = 2
    LEARNED = 3


def slot_mask(
    agents: int | Tensor,
    slot: int | Tensor,
    slots: int,
    population: int | None = None,
    device: torch.device | str | None = None,
) -> Tensor:
    """A ``BoolTensor [P, K]`` selecting slot ``slot`` of the chosen agents.

    Args:
        agents: an agent index (int), a ``BoolTensor [P]`` mask, or a ``LongTensor`` of indices
            (then ``population`` is required).
        slot: one slot for all chosen agents (int) or a ``LongTensor [P]`` with a slot per
            agent; entries ``< 0`` select nothing (e.g. the ``-1`` of a full agent).
        slots: K.
        population: P; inferred from a boolean ``agents`` mask.
    """
    if isinstance(agents, Tensor) and agents.dtype == torch.bool:
        if agents.ndim != 1:
            raise ValueError(f"agent mask must be [P], got {tuple(agents.shape)}")
        population = agents.shape[0] if population is None else population
        chosen = agents
        device = agents.device
    else:
        if population is None:
            raise ValueError("population is required when agents are given as indices")
        chosen = torch.zeros(population, dtype=torch.bool, device=device)
        chosen[torch.as_tensor(agents, dtype=torch.int64, device=device)] = True
    if chosen.shape != (population,):
        raise ValueError(f"agent mask must be [P={population}], got {tuple(chosen.shape)}")
    slot = torch.as_tensor(slot, dtype=torch.int64, device=chosen.device).expand(population)
    if bool((slot >= slots).any()):
        raise ValueError(f"slot index out of range for K={slots}: {slot.tolist()}")
    ks = torch.arange(slots, device=chosen.device)
    return chosen[:, None] & (slot[:, None] == ks) & (slot[:, None] >= 0)


def check_slot_mask(mask: Tensor, population: int, slots: int, name: str = "mask") -> Tensor:
    """Validate a ``[P, K]`` mask and return it as bool."""
    if tuple(mask.shape) != (population, slots):
        raise ValueError(f"{name} must be [P={population}, K={slots}], got {tuple(mask.shape)}")
    return mask.to(torch.bool)


def agent_index(index, population: int) -> Tensor:
    """``index`` (int, list or ``LongTensor``) as a 1-d ``LongTensor`` of valid agent indices."""
    index = torch.as_tensor(index, dtype=torch.int64).reshape(-1)
    if index.numel() == 0:
        raise ValueError("select at least one agent")
    if bool(((index < 0) | (index >= population)).any()):
        raise ValueError(f"agent indices {index.tolist()} out of range for P={population}")
    return index


def agent_seeds(seed: int | Tensor, population: int) -> Tensor:
    """Per-agent seeds ``[P]``: ``seed + p`` for an int (as ``CounterRNG.from_seed``), or the
    given ``LongTensor [P]``."""
    if isinstance(seed, Tensor):
        seeds = seed.to(torch.int64).reshape(-1)
    else:
        seeds = torch.arange(population, dtype=torch.int64) + int(seed)
    if seeds.shape != (population,):
        raise ValueError(f"seed tensor must be [P={population}], got {tuple(seeds.shape)}")
    return seeds
