"""Which points lie within a distance of some example: the initiation sets' 0.1 constraint
for many points at once, without the all-pairs distance matrix.

:func:`within_any` answers exactly what
``(torch.cdist(points, examples, compute_mode="donot_use_mm_for_euclid_dist") <= distance)
.any(-1)`` answers, bit for bit, but computes the distance only for pairs in neighbouring
cells of a grid of side ``distance``: two points within ``distance`` of each other differ by
at most that much in every coordinate, so their cells differ by at most one in each. Drawing
an initiation set (62,500 probe points against up to 500 stored positives) then costs
milliseconds instead of the tenths of a second of the full matrix.

Example:
    >>> import torch
    >>> points = torch.tensor([[0.0, 0.0], [0.5, 0.5], [0.95, 0.95]], dtype=torch.float64)
    >>> examples = torch.tensor([[0.05, 0.05], [1.0, 1.0]], dtype=torch.float64)
    >>> within_any(points, examples, 0.1).tolist()
    [True, False, True]
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["within_any"]

# Cells a hair wider than the distance, so that a pair the rounded distance accepts can never
# straddle two cells' gap (floor differences stay <= 1 despite the division's rounding).
_WIDEN = 1.0 + 1e-6
# Above this share of all pairs the candidates cost more than the dense matrix they avoid.
_DENSE_SHARE = 0.25
# Grids up to this many cells index their points through a table (about 15^4 cells on the
# unit board at distance 0.1); larger ones search the sorted keys.
_TABLE_CELLS = 1 << 22


def _dense(points: Tensor, examples: Tensor, distance: float) -> Tensor:
    distance_matrix = torch.cdist(points, examples, compute_mode="donot_use_mm_for_euclid_dist")
    return (distance_matrix <= distance).any(-1)


@torch.no_grad()
def within_any(points: Tensor, examples: Tensor, distance: float) -> Tensor:
    """``BoolTensor [N]``: point ``i`` of ``points [N, d]`` is within Euclidean ``distance``
    of at least one of ``examples [M, d]`` (``cdist <= distance``, as the dense test).

    Only pairs in neighbouring grid cells are measured; each pair's distance is the same
    ``cdist`` kernel on the same two rows, so the answer is the dense one bit for bit. Falls
    back to the dense matrix where the grid would not save work (most pairs are neighbours,
    non-finite coordinates, a grid too large to index).
    """
    n, d = points.shape
    m = examples.shape[0]
    out = torch.zeros(n, dtype=torch.bool, device=points.device)
    if n == 0 or m == 0:
        return out
    if not distance > 0:
        return _dense(points, examples, distance)
    cell = float(distance) * _WIDEN
    # (amax propagates NaN: a non-finite coordinate fails the test too.)
    reach = max(float(points.abs().amax()), float(examples.abs().amax())) / cell
    if not reach <= 2.0**40:  # cell indices must stay exact integers
        return _dense(points, examples, distance)
    point_cell = torch.floor(points / cell).to(torch.int64)
    example_cell = torch.floor(examples / cell).to(torch.int64)
    low = torch.minimum(point_cell.amin(0), example_cell.amin(0)) - 1
    span = (torch.maximum(point_cell.amax(0), example_cell.amax(0)) + 2 - low).tolist()
    if math.prod(span) >= 2**62:  # keys would overflow int64
        return _dense(points, examples, distance)
    cells = math.prod(span)
    strides = torch.tensor([math.prod(span[:j]) for j in range(d)], device=points.device)
    point_key = ((point_cell - low) * strides).sum(-1)
    example_key = ((example_cell - low) * strides).sum(-1)
    order = torch.argsort(point_key)
    # Every example looks up the points of its 3^d neighbouring cells: a range of the sorted
    # points, from a table of cell starts where the grid is small (a gather), else by search.
    steps = torch.tensor([-1, 0, 1], device=points.device)
    offsets = (torch.cartesian_prod(*[steps] * d).reshape(-1, d) * strides).sum(-1)
    query = (example_key[:, None] + offsets).reshape(-1)
    if cells <= _TABLE_CELLS:
        per_cell = torch.bincount(point_key, minlength=cells)
        first = (per_cell.cumsum(0) - per_cell)[query]
        count = per_cell[query]
    else:
        sorted_key = point_key[order]
        first = torch.searchsorted(sorted_key, query)
        count = torch.searchsorted(sorted_key, query, right=True) - first
    pairs = int(count.sum())
    if pairs == 0:
        return out
    if pairs > _DENSE_SHARE * n * m:
        return _dense(points, examples, distance)
    example = torch.arange(m, device=points.device).repeat_interleave(
        count.reshape(m, -1).sum(-1))
    # Pair j of a range starting at first (the range's own j counted from its start).
    skip = (first - (count.cumsum(0) - count)).repeat_interleave(count)
    point = order[skip + torch.arange(pairs, device=points.device)]
    # [pairs, 1, d] against [pairs, 1, d]: each pair on its own, the dense kernel's bits.
    pair_distance = torch.cdist(points[point][:, None], examples[example][:, None],
                                compute_mode="donot_use_mm_for_euclid_dist").reshape(-1)
    out[point[pair_distance <= distance]] = True
    return out
