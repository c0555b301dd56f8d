"""Planar geometry for validating Pinball maps at load time (pure functions).

Maps are checked once, when they are parsed, so these functions favour exact answers over
speed: a decision that float rounding could flip (a vertex exactly on another edge, three
collinear vertices) is settled in exact rational arithmetic, since :class:`fractions.Fraction`
holds every double exactly. Floats decide everything else, which is nearly everything, and the
polygon checks are vectorised so that a map of tens of thousands of edges is checked in a
fraction of a second.

Edge ``k`` of a polygon with vertices ``P_0 .. P_{n-1}`` runs from ``P_k`` to ``P_{k+1 mod n}``;
indices here are 0-based (the map parser adds 1 for its messages, as it does for lines).

Example:
    >>> square = [(0.4, 0.4), (0.6, 0.4), (0.6, 0.6), (0.4, 0.6)]
    >>> round(polygon_area(square), 12), find_self_intersection(square)
    (0.04, None)
    >>> find_self_intersection([(0.4, 0.4), (0.6, 0.6), (0.6, 0.4), (0.4, 0.6)])  # a bow tie
    (0, 2)
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

__all__ = [
    "orientation",
    "segments_intersect",
    "polygon_area",
    "find_self_intersection",
    "point_segment_distance2",
    "point_in_polygon",
]

# A float cross product whose magnitude exceeds this multiple of its two products' magnitudes
# has the exact sign (Shewchuk's bound for orient2d is 3.3e-16; the margin is generous).
_REL_ERR = 1e-14
# Below this, products may be subnormal and lose relative precision: decide exactly.
_TINY = 1e-280
# Polygons with more vertices than this are checked with numpy instead of Python loops.
_VECTOR_MIN = 24
# Candidate edge pairs of one polygon examined at once (bounds the check's memory).
_PAIR_BUDGET = 1 << 20


def _exact_orientation(a, b, c) -> int:
    ax, ay = Fraction(a[0]), Fraction(a[1])
    d = (Fraction(b[0]) - ax) * (Fraction(c[1]) - ay) - (Fraction(b[1]) - ay) * (
        Fraction(c[0]) - ax
    )
    return (d > 0) - (d < 0)


def orientation(a, b, c) -> int:
    """Exact sign of the cross product ``(b - a) x (c - a)``: 1 left turn, -1 right, 0 collinear.

    Example:
        >>> orientation((0.0, 0.0), (1.0, 0.0), (0.5, 1e-300)), orientation((0, 0), (1, 1), (3, 3))
        (1, 0)
    """
    left = (b[0] - a[0]) * (c[1] - a[1])
    right = (b[1] - a[1]) * (c[0] - a[0])
    d = left - right
    if abs(d) > _REL_ERR * (abs(left) + abs(right)) and abs(d) > _TINY:
        return 1 if d > 0 else -1
    return _exact_orientation(a, b, c)


def _within_box(a, b, p) -> bool:
    """Whether ``p`` lies in the bounding box of segment ``a b`` (exact: comparisons only)."""
    return min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])


def segments_intersect(a, b, c, d) -> bool:
    """Whether the closed segments ``a b`` and ``c d`` share a point (exact; touching counts).

    Example:
        >>> segments_intersect((0, 0), (1, 1), (0, 1), (1, 0)), segments_intersect(
        ...     (0, 0), (1, 0), (0.5, 0.0), (0.5, 1.0))
        (True, True)
        >>> segments_intersect((0, 0), (1, 0), (0, 0.1), (1, 0.1))
        False
    """
    o1, o2 = orientation(a, b, c), orientation(a, b, d)
    o3, o4 = orientation(c, d, a), orientation(c, d, b)
    if o1 * o2 < 0 and o3 * o4 < 0:
        return True
    return (
        (o1 == 0 and _within_box(a, b, c))
        or (o2 == 0 and _within_box(a, b, d))
        or (o3 == 0 and _within_box(c, d, a))
        or (o4 == 0 and _within_box(c, d, b))
    )


def polygon_area(points) -> float:
    """Signed area (shoelace; positive counter-clockwise in x-right, y-up axes).

    Coordinates are taken relative to the first vertex, which keeps the rounding error
    proportional to the polygon's size rather than to its distance from the origin.

    Example:
        >>> polygon_area([(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)])
        0.5
    """
    x0, y0 = points[0]
    total = 0.0
    for (x1, y1), (x2, y2) in zip(points[1:], points[2:], strict=False):
        total += (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    return 0.5 * total


def _doubles_back(a, b, c) -> bool:
    """Whether the path ``a -> b -> c`` turns back on itself (collinear, reversing at ``b``)."""
    if orientation(a, b, c) != 0:
        return False
    dot = (Fraction(b[0]) - Fraction(a[0])) * (Fraction(c[0]) - Fraction(b[0])) + (
        Fraction(b[1]) - Fraction(a[1])
    ) * (Fraction(c[1]) - Fraction(b[1]))
    return dot < 0


def find_self_intersection(points) -> tuple[int, int] | None:
    """The first pair of edges ``(i, j)``, ``i < j``, that share a point they should not.

    Adjacent edges may share only their common vertex: they intersect if the outline doubles
    back there (collinear, reversing). Other edges may share nothing, not even a touching
    vertex. Returns ``None`` for a simple polygon. Consecutive duplicate vertices (zero-length
    edges) are the caller's to reject first.

    Example:
        >>> find_self_intersection([(0.1, 0.1), (0.5, 0.1), (0.3, 0.1)])  # back at (0.5, 0.1)
        (0, 1)
        >>> find_self_intersection([(0.1, 0.1), (0.5, 0.1), (0.5, 0.5), (0.3, 0.1), (0.2, 0.5)])
        (0, 2)
    """
    n = len(points)
    for k in range(n):  # adjacent edges k and k + 1 meet at vertex k + 1
        if _doubles_back(points[k], points[(k + 1) % n], points[(k + 2) % n]):
            return (k, k + 1) if k + 1 < n else (0, n - 1)
    if n < 4:
        return None
    if n < _VECTOR_MIN:
        return _first_crossing_loops(points)
    return _first_crossing_numpy(points)


def _first_crossing_loops(points):
    n = len(points)
    for i in range(n - 2):
        a, b = points[i], points[i + 1]
        ax0, ax1 = min(a[0], b[0]), max(a[0], b[0])
        ay0, ay1 = min(a[1], b[1]), max(a[1], b[1])
        for j in range(i + 2, n - (i == 0)):  # skip edge i + 1 and, for i = 0, edge n - 1
            c, d = points[j], points[(j + 1) % n]
            if (
                max(c[0], d[0]) < ax0
                or min(c[0], d[0]) > ax1
                or max(c[1], d[1]) < ay0
                or min(c[1], d[1]) > ay1
            ):
                continue
            if segments_intersect(a, b, c, d):
                return (i, j)
    return None


def _orient_arrays(ax, ay, bx, by, cx, cy):
    """Float orientations and whether each sign is certain (see :func:`orientation`)."""
    left = (bx - ax) * (cy - ay)
    right = (by - ay) * (cx - ax)
    d = left - right
    sure = (np.abs(d) > _REL_ERR * (np.abs(left) + np.abs(right))) & (np.abs(d) > _TINY)
    return np.sign(d), sure


def _first_crossing_numpy(points):
    """Non-adjacent crossings of a large polygon: a sweep over x finds the edge pairs whose
    boxes overlap (about linear in n for ordinary outlines), floats decide them, and the few
    pairs whose float signs are uncertain are settled exactly."""
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[0]
    q = np.roll(p, -1, axis=0)
    x0, x1 = np.minimum(p[:, 0], q[:, 0]), np.maximum(p[:, 0], q[:, 0])
    y0, y1 = np.minimum(p[:, 1], q[:, 1]), np.maximum(p[:, 1], q[:, 1])
    order = np.argsort(x0, kind="stable")
    sx0 = x0[order]
    # Edge order[s] can only meet the edges order[s + 1 : stop[s]] further along the sweep.
    stop = np.searchsorted(sx0, x1[order], side="right")
    count = np.maximum(stop - np.arange(n) - 1, 0)
    cum = np.cumsum(count)
    s = 0
    while s < n:
        # A block of sweep positions with at most _PAIR_BUDGET candidate pairs (one at least).
        done = int(cum[s - 1]) if s else 0
        e = max(int(np.searchsorted(cum, done + _PAIR_BUDGET, side="right")), s + 1)
        reps = count[s:e]
        first = np.repeat(np.arange(s, e), reps)
        offset = np.arange(int(reps.sum())) - np.repeat(np.cumsum(reps) - reps, reps)
        i, j = order[first], order[first + 1 + offset]
        gap = np.abs(i - j)
        keep = (gap != 1) & (gap != n - 1) & (y0[i] <= y1[j]) & (y0[j] <= y1[i])
        i, j = np.minimum(i[keep], j[keep]), np.maximum(i[keep], j[keep])
        found = _decide_pairs(p, q, i, j)
        if found:
            return min(found)
        s = e
    return None


def _decide_pairs(p, q, i, j) -> list[tuple[int, int]]:
    a, b, c, d = p[i], q[i], p[j], q[j]
    o1, s1 = _orient_arrays(a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1])
    o2, s2 = _orient_arrays(a[:, 0], a[:, 1], b[:, 0], b[:, 1], d[:, 0], d[:, 1])
    o3, s3 = _orient_arrays(c[:, 0], c[:, 1], d[:, 0], d[:, 1], a[:, 0], a[:, 1])
    o4, s4 = _orient_arrays(c[:, 0], c[:, 1], d[:, 0], d[:, 1], b[:, 0], b[:, 1])
    sure = s1 & s2 & s3 & s4
    apart = sure & ((o1 * o2 > 0) | (o3 * o4 > 0))
    crossing = sure & (o1 * o2 < 0) & (o3 * o4 < 0)
    out = [(int(u), int(v)) for u, v in zip(i[crossing], j[crossing], strict=True)]
    unsure = ~sure & ~apart
    # Opposite certain signs on one side already separate the segments.
    unsure &= ~((s1 & s2 & (o1 * o2 > 0)) | (s3 & s4 & (o3 * o4 > 0)))
    for u, v in zip(i[unsure].tolist(), j[unsure].tolist(), strict=True):
        pts = [tuple(x) for x in (p[u], q[u], p[v], q[v])]
        if segments_intersect(*pts):
            out.append((u, v))
    return out


def point_segment_distance2(px: float, py: float, ax, ay, bx, by):
    """Squared distance from the point ``(px, py)`` to segments ``a b`` (floats or arrays).

    The same closest-point formula as the physics' contact test (``t`` clamped to [0, 1]).

    Example:
        >>> round(float(point_segment_distance2(0.5, 0.3, 0.0, 0.0, 1.0, 0.0)), 12)
        0.09
    """
    ex, ey = bx - ax, by - ay
    t = np.clip(((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
    dx, dy = px - (ax + ex * t), py - (ay + ey * t)
    return dx * dx + dy * dy


def point_in_polygon(px: float, py: float, points) -> bool:
    """Even-odd test: whether ``(px, py)`` lies inside a simple polygon.

    Floats decide; a point within rounding distance of an edge may land on either side, so
    callers test the distance to the edges first.

    Example:
        >>> square = [(0.4, 0.4), (0.6, 0.4), (0.6, 0.6), (0.4, 0.6)]
        >>> point_in_polygon(0.5, 0.5, square), point_in_polygon(0.7, 0.5, square)
        (True, False)
    """
    p = np.asarray(points, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    return bool(np.count_nonzero(_crossings(px, py, p[:, 0], p[:, 1], q[:, 0], q[:, 1])) % 2)


def _crossings(px, py, ax, ay, bx, by):
    """Edges that a ray from ``(px, py)`` towards +x crosses (half-open in y, so each vertex
    is counted once)."""
    straddle = (ay > py) != (by > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = ax + (py - ay) * (bx - ax) / (by - ay)
    return straddle & (px < x_at)
