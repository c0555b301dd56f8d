"""The map-validation geometry against exact brute force (rational arithmetic)."""

import doctest
import random
from fractions import Fraction

import pytest

from skillchain_torch.envs.pinball import geometry
from skillchain_torch.envs.pinball.geometry import (
    find_self_intersection,
    orientation,
    point_in_polygon,
    polygon_area,
    segments_intersect,
)


def test_doctests():
    assert doctest.testmod(geometry).failed == 0


def exact_orientation(a, b, c):
    f = [Fraction(v) for v in (*a, *b, *c)]
    d = (f[2] - f[0]) * (f[5] - f[1]) - (f[3] - f[1]) * (f[4] - f[0])
    return (d > 0) - (d < 0)


def random_point(rnd, kind):
    if kind == "grid":  # exact collinearities and shared points
        return (rnd.randint(0, 6) / 6, rnd.randint(0, 6) / 6)
    return (rnd.random(), rnd.random())


def test_orientation_is_exact_near_collinear_points():
    rnd = random.Random(0)
    for _ in range(3000):
        a, b = (rnd.random(), rnd.random()), (rnd.random(), rnd.random())
        t = rnd.random()
        # A point on the line a b, rounded to doubles: the float cross product is ~1e-17.
        c = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
        assert orientation(a, b, c) == exact_orientation(a, b, c)
    assert orientation((0.1, 0.1), (0.3, 0.3), (0.7, 0.7)) == exact_orientation(
        (0.1, 0.1), (0.3, 0.3), (0.7, 0.7)
    )


def exact_segments_intersect(a, b, c, d):
    def within(p, q, r):  # r inside the box of p q
        return min(p[0], q[0]) <= r[0] <= max(p[0], q[0]) and min(p[1], q[1]) <= r[1] <= max(
            p[1], q[1]
        )

    o1, o2 = exact_orientation(a, b, c), exact_orientation(a, b, d)
    o3, o4 = exact_orientation(c, d, a), exact_orientation(c, d, b)
    if o1 * o2 < 0 and o3 * o4 < 0:
        return True
    return any(
        o == 0 and within(p, q, r)
        for o, p, q, r in ((o1, a, b, c), (o2, a, b, d), (o3, c, d, a), (o4, c, d, b))
    )


def brute_force(points):
    """Adjacent edges doubling back, then any non-adjacent pair sharing a point."""
    n = len(points)
    for k in range(n):
        a, b, c = points[k], points[(k + 1) % n], points[(k + 2) % n]
        if exact_orientation(a, b, c) == 0:
            dot = sum(
                (Fraction(b[i]) - Fraction(a[i])) * (Fraction(c[i]) - Fraction(b[i]))
                for i in (0, 1)
            )
            if dot < 0:
                return (k, k + 1) if k + 1 < n else (0, n - 1)
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue
            if exact_segments_intersect(points[i], points[i + 1], points[j], points[(j + 1) % n]):
                return (i, j)
    return None


@pytest.mark.parametrize("vectorised", [False, True])
def test_self_intersection_matches_brute_force(monkeypatch, vectorised):
    """Random outlines, float and grid-snapped (touching vertices, collinear edges), through
    the Python loops and the numpy sweep."""
    monkeypatch.setattr(geometry, "_VECTOR_MIN", 4 if vectorised else 10**9)
    rnd = random.Random(1)
    found = 0
    for trial in range(800):
        kind = "grid" if trial % 2 else "float"
        n = rnd.randint(3, 12)
        points = [random_point(rnd, kind) for _ in range(n)]
        if any(points[k] == points[(k + 1) % n] for k in range(n)):
            continue  # zero-length edges are the parser's to refuse first
        expected = brute_force(points)
        assert find_self_intersection(points) == expected, points
        found += expected is not None
    assert 100 < found  # the random outlines did intersect


def test_simple_polygons_pass_and_areas():
    square = [(0.4, 0.4), (0.6, 0.4), (0.6, 0.6), (0.4, 0.6)]
    assert find_self_intersection(square) is None
    assert segments_intersect((0, 0), (1, 1), (0, 1), (1, 0))
    assert not segments_intersect((0, 0), (0.4, 0.4), (0.5, 0.5), (1, 1))  # collinear, apart
    assert polygon_area(square) == pytest.approx(0.04, abs=1e-15)
    assert polygon_area(square[::-1]) == pytest.approx(-0.04, abs=1e-15)
    assert point_in_polygon(0.5, 0.5, square) and not point_in_polygon(0.3, 0.5, square)
    notch = [(0.2, 0.2), (0.8, 0.2), (0.8, 0.8), (0.5, 0.3), (0.2, 0.8)]  # non-convex, simple
    assert find_self_intersection(notch) is None
    assert not point_in_polygon(0.5, 0.6, notch) and point_in_polygon(0.3, 0.3, notch)
