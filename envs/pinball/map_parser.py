"""The Pinball instance file format (Konidaris & Barto's ``.cfg``): read, and checked.

A file holds one record per line; the first whitespace-separated token selects the record:

* ``ball r``: ball radius;
* ``target x y R``: centre and radius of the goal disc;
* ``start x1 y1 [x2 y2 ...]``: one or more start positions (several ``start`` lines are
  concatenated in file order);
* ``polygon x1 y1 ... xn yn``: an obstacle, with the closing edge n -> 1 implied.

Blank lines and lines of any other type are skipped, as in the original Java parser. Every
problem in a file raises ``ValueError`` naming the file, the line and the problem; polygons,
vertices and starts are counted from 1 in messages, as lines are.

Beyond the syntax, a map must describe a board the physics can simulate faithfully (the
original Java code checked none of this, and would run such maps with wrong results):

* radii: ``ball`` and ``target`` radii lie in ``[RADIUS_MIN, RADIUS_MAX) = [1e-6, 0.5)``. The
  board is the unit square and the shipped maps use 0.015 to 0.04. A ball of radius 0.5 or
  more cannot fit between the walls (nor a target disc that large on the board); below 1e-6
  a substep's displacement ``v r / 20`` approaches the resolution of float64 positions near 1
  (1e-16), and a radius like 1e-320 is subnormal, so ``r * r`` rounds to 0;
* polygons: simple outlines of non-zero area. No two edges may cross or touch except
  neighbours at their shared vertex, and the outline may not double back on itself; a
  self-intersecting outline has no well-defined inside. "Zero area": ``|area|`` at most
  ``FLAT_RATIO`` (1e-9) times the perimeter squared, i.e. thinner than about 2e-9 of its
  length (collinear vertices);
* starts: the ball at each start must not touch any edge (distance greater than the ball
  radius, the contact test of the physics), lie inside a polygon (it could never leave), or
  lie inside the target disc (every episode would end on its first substep).

Obstacles may overlap each other (the shipped walls do at the corners, and one map lists a
polygon twice): the physics handles that as the original did.

:func:`parse_map` returns plain Python floats; :class:`~.maps.PinballMap` makes tensors of them.

Example:
    >>> parse_map("ball 0.02\\ntarget 0.9 0.2 0.04\\nstart 0.2 0.9\\n", "x.cfg")["starts"]
    [(0.2, 0.9)]
    >>> parse_map("ball 0.02\\ntarget 0.9 0.2 0.04\\n", "x.cfg")
    Traceback (most recent call last):
    ...
    ValueError: x.cfg: missing 'start' record (a line 'start x y')
"""

from __future__ import annotations

import math
import re

import numpy as np

from .geometry import (
    _crossings,
    find_self_intersection,
    orientation,
    point_segment_distance2,
    polygon_area,
)

__all__ = ["parse_map", "RADIUS_MIN", "RADIUS_MAX", "FLAT_RATIO"]

_RECORDS = ("ball", "target", "start", "polygon")
# Plain ASCII decimals only: float() would also take "1_0", "nan" and non-ASCII digits.
_DECIMAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
# Line breaks as Java's BufferedReader.readLine sees them, so line numbers match an editor's.
_LINE_BREAK = re.compile(r"\r\n|\r|\n")
# Allowed ball and target radii, [min, max): see the module docstring for why.
RADIUS_MIN = 1e-6
RADIUS_MAX = 0.5
# A polygon with |area| <= FLAT_RATIO * perimeter^2 is flat (zero area).
FLAT_RATIO = 1e-9


class _Line:
    """Where a record came from, for error messages."""

    def __init__(self, source: str, lineno: int):
        self.source, self.lineno = source, lineno

    def fail(self, problem: str):
        raise ValueError(f"{self.source}, line {self.lineno}: {problem}")

    def number(self, token: str) -> float:
        if _DECIMAL.fullmatch(token):
            value = float(token)  # may still overflow to inf, e.g. "1e999"
        else:
            try:
                value = float(token)
            except ValueError:
                value = 0.0
            if math.isfinite(value):  # a word, or a finite non-decimal such as "1_0"
                self.fail(f"{token!r} is not a number")
        if not math.isfinite(value):
            self.fail(f"{token!r} is not a finite number")
        return value


def parse_map(text: str, source: str) -> dict:
    """The text of a ``.cfg`` file as plain Python floats (no tensors yet): ``{"ball",
    "target", "starts", "polygons"}``; ``source`` names the file in error messages."""
    if "\x00" in text:
        raise ValueError(f"{source}: contains NUL characters; not a text map file")
    first_line: dict[str, int] = {}
    scalars: dict[str, list[float]] = {}
    starts: list[tuple[float, float]] = []
    polygons: list[list[tuple[float, float]]] = []
    start_lines: list[int] = []  # the line of each start, for the geometry checks' messages
    polygon_lines: list[int] = []
    for lineno, line in enumerate(_LINE_BREAK.split(text.removeprefix("\ufeff")), start=1):
        tokens = line.split()
        if not tokens or tokens[0] not in _RECORDS:
            continue
        at = _Line(source, lineno)
        kind, values = tokens[0], [at.number(tok) for tok in tokens[1:]]
        if kind in ("ball", "target"):
            if kind in scalars:
                at.fail(f"duplicate {kind!r} record (first on line {first_line[kind]})")
            need = 1 if kind == "ball" else 3
            if len(values) != need:
                at.fail(
                    f"{kind!r} needs exactly {need} number{'s' * (need > 1)} (got {len(values)})"
                )
            if values[-1] <= 0:
                at.fail(f"{kind!r} radius must be positive (got {values[-1]!r})")
            if not RADIUS_MIN <= values[-1] < RADIUS_MAX:
                at.fail(
                    f"{kind!r} radius {values[-1]!r} is outside the allowed range "
                    f"[{RADIUS_MIN}, {RADIUS_MAX}) (the board is the unit square; the original "
                    "maps use 0.015 to 0.04)"
                )
            first_line[kind], scalars[kind], coords = lineno, values, values[:-1]
        else:
            if len(values) % 2:
                at.fail(f"{kind!r} needs an even number of coordinates (got {len(values)})")
            least = 1 if kind == "start" else 3
            if len(values) < 2 * least:
                at.fail(
                    f"{kind!r} needs at least {least} x y pair{'s' * (least > 1)} "
                    f"(got {len(values) // 2})"
                )
            coords = values
        for v in coords:
            if not 0.0 <= v <= 1.0:
                at.fail(f"coordinate {v!r} is outside the unit square (allowed range [0, 1])")
        points = list(zip(values[0::2], values[1::2], strict=False))
        if kind == "start":
            starts.extend(points)
            start_lines.extend([lineno] * len(points))
        elif kind == "polygon":
            n = len(points)
            for j in range(n):
                # The closest-point test of the collision code divides by an edge's squared
                # length: a repeated vertex, or two closer than about 1e-154 (the square
                # underflows to 0), would divide by zero.
                (x0, y0), (x1, y1) = points[j], points[(j + 1) % n]
                if (x1 - x0) * (x1 - x0) + (y1 - y0) * (y1 - y0) == 0.0:
                    at.fail(
                        f"'polygon' vertices {j + 1} and {(j + 1) % n + 1} coincide "
                        f"{points[j]!r}, {points[(j + 1) % n]!r} (zero-length edge)"
                    )
            polygons.append(points)
            polygon_lines.append(lineno)
    present = {"ball": "ball" in scalars, "target": "target" in scalars, "start": bool(starts)}
    for kind, example in (("ball", "ball r"), ("target", "target x y R"), ("start", "start x y")):
        if not present[kind]:
            raise ValueError(f"{source}: missing {kind!r} record (a line '{example}')")
    for k, (points, lineno) in enumerate(zip(polygons, polygon_lines, strict=True)):
        _check_polygon(points, k, _Line(source, lineno))
    _check_starts(
        scalars["ball"][0], scalars["target"], starts, start_lines, polygons, polygon_lines, source
    )
    return {
        "ball": scalars["ball"][0],
        "target": scalars["target"],
        "starts": starts,
        "polygons": polygons,
    }


def _check_polygon(points: list, k: int, at: _Line) -> None:
    """Polygon ``k`` (0-based) must be a simple outline of non-zero area; see the docstring."""
    n = len(points)
    perimeter = sum(math.dist(points[j], points[(j + 1) % n]) for j in range(n))
    flat = abs(polygon_area(points)) <= FLAT_RATIO * perimeter * perimeter
    hit = find_self_intersection(points)
    # Collinear vertices always fold the outline onto itself; call that what it is, zero area.
    # A flat outline that is not a line (a symmetric bow tie) is reported as self-intersecting.
    if flat and (hit is None or all(orientation(points[0], points[1], p) == 0 for p in points)):
        at.fail(
            f"polygon {k + 1} has zero area (|area| {abs(polygon_area(points)):.3g} for a "
            f"perimeter of {perimeter:.3g}; its vertices are collinear or nearly so)"
        )
    if hit is not None:
        i, j = hit
        at.fail(
            f"polygon {k + 1} is self-intersecting: its edge from vertex {i + 1} to "
            f"{(i + 1) % n + 1} {points[i]!r} -> {points[(i + 1) % n]!r} meets its edge from "
            f"vertex {j + 1} to {(j + 1) % n + 1} {points[j]!r} -> {points[(j + 1) % n]!r} "
            "(only neighbouring edges may meet, at their shared vertex)"
        )


def _check_starts(ball, target, starts, start_lines, polygons, polygon_lines, source) -> None:
    """Each start must leave the ball clear of every edge, outside every polygon and outside
    the target disc; see the module docstring."""
    tx, ty, tr = target
    if polygons:
        a = np.array([v for p in polygons for v in p], dtype=np.float64)
        sizes = np.array([len(p) for p in polygons])
        first_vertex = np.cumsum(sizes) - sizes
        poly_of = np.repeat(np.arange(len(polygons)), sizes)
        following = np.arange(1, a.shape[0] + 1)
        following[first_vertex + sizes - 1] = first_vertex  # each polygon's closing edge
        b = a[following]
    for s, ((x, y), lineno) in enumerate(zip(starts, start_lines, strict=True)):
        at = _Line(source, lineno)
        where = f"start {s + 1} {(x, y)!r}"
        if (x - tx) * (x - tx) + (y - ty) * (y - ty) < tr * tr:  # the physics' goal test
            at.fail(
                f"{where} lies inside the target disc (centre {(tx, ty)!r}, radius {tr!r}): "
                "every episode would end on its first substep"
            )
        if not polygons:
            continue
        d2 = point_segment_distance2(x, y, a[:, 0], a[:, 1], b[:, 0], b[:, 1])
        touching = np.flatnonzero(d2 <= ball * ball)  # the physics' contact test
        if touching.size:
            e = int(touching[0])
            k = int(poly_of[e])
            v = e - int(first_vertex[k])
            at.fail(
                f"{where}: the ball (radius {ball!r}) overlaps polygon {k + 1} (line "
                f"{polygon_lines[k]}) at its edge from vertex {v + 1} to "
                f"{(v + 1) % int(sizes[k]) + 1} (distance {math.sqrt(float(d2[e])):.6g}, "
                "not more than the radius)"
            )
        # Clear of every edge by more than the radius, so the float even-odd test is exact.
        crossed = _crossings(x, y, a[:, 0], a[:, 1], b[:, 0], b[:, 1])
        inside = np.flatnonzero(np.bincount(poly_of[crossed], minlength=len(polygons)) % 2)
        if inside.size:
            k = int(inside[0])
            at.fail(
                f"{where} lies inside polygon {k + 1} (line {polygon_lines[k]}): the ball "
                "could never leave it"
            )
