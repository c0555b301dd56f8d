"""Hot-path kernels of the flat agent: the library's arithmetic in fewer tensor operations.

A single agent pays torch's per-operation overhead (a few microseconds) on every operation of
every step, so these functions compute exactly what the library pieces compute -- bit for bit,
``tests/trainers/test_flat.py`` checks it -- with as few operations as possible:

* :func:`decide`: :func:`~skillchain_torch.policies.epsilon_greedy` with every action
  available, without its validation syncs;
* :func:`decision_table` / :func:`candidate_codes`: epsilon-greedy split in two. The uniforms
  are known in advance (counter-based streams), so for each upcoming decision the action is
  tabulated for all 2^D possible sets of greedy actions; a step then only computes which set
  it has (a bit code) and looks the action up.

Every operation is elementwise or a reduction within one agent's row, so an agent's numbers do
not depend on which other agents are in the batch.
"""

from __future__ import annotations

import functools

import torch
from torch import Tensor

__all__ = ["decide", "decision_table", "candidate_codes"]


def decide(q: Tensor, explore: Tensor, u1: Tensor) -> Tensor:
    """``epsilon_greedy(q, all available, epsilon, (u0, u1))`` bit for bit, without syncs.

    Args:
        q: ``[n, D]`` action values; explore: ``u0 < epsilon``, bool ``[n]``; u1: ``[n]``.

    ``k = floor(u1 * count)`` needs no clamp: for ``u1 <= 1 - 2^-53`` and an integer
    ``count < 2^52`` the product rounds below ``count``.
    """
    candidates = (q == q.amax(-1, keepdim=True)) | explore[:, None]
    k = (u1 * candidates.sum(-1)).long()
    # index of the (k+1)-th candidate = number of positions whose running count is <= k
    return (candidates.cumsum(-1) <= k[:, None]).sum(-1)


@functools.lru_cache(maxsize=16)
def _code_tables(num_actions: int, device: torch.device) -> tuple[Tensor, Tensor]:
    """Per bit code of a candidate set: its size ``[2^D]`` and its members ``[2^D, D]``
    (built once per device; callers do not modify them)."""
    codes = 1 << num_actions
    members = torch.zeros(codes, num_actions, dtype=torch.int64)
    size = torch.zeros(codes, dtype=torch.int64)
    for code in range(codes):
        chosen = [d for d in range(num_actions) if code >> d & 1]
        size[code] = len(chosen)
        members[code, : len(chosen)] = torch.tensor(chosen, dtype=torch.int64)
    return size.to(device), members.to(device)


def decision_table(explore: Tensor, u1: Tensor, num_actions: int) -> Tensor:
    """The action for every upcoming decision and every greedy set: ``[n, B, 2^D]`` int64.

    Args:
        explore: ``u0 < epsilon`` of the next B decisions, bool ``[n, B]``.
        u1: their index uniforms ``[n, B]``.

    Entry ``[p, b, code]`` is what :func:`decide` returns for decision b of row p when the
    greedy actions are the bits of ``code`` (exploring replaces them by all actions). Code 0
    (no greedy action: NaN values) maps to action 0; callers check values for NaN separately.
    """
    size, members = _code_tables(num_actions, u1.device)
    codes = torch.arange(1 << num_actions, device=u1.device)
    code = torch.where(explore[..., None], codes[-1], codes)  # [n, B, 2^D]
    count = size[code]
    k = (u1[..., None] * count).long()
    k = torch.where(count > 0, k, torch.zeros_like(k))
    return members.view(-1)[code * num_actions + k]


def candidate_codes(q: Tensor, powers: Tensor) -> Tensor:
    """Bit code of the greedy actions of action-major values ``q [D, n]``: ``[n]`` int64."""
    return ((q == q.amax(0)) * powers).sum(0)
