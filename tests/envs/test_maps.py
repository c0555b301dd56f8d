"""Tests for the .cfg map parser (skillchain_torch.envs.pinball.map_parser) and the maps it
makes (skillchain_torch.envs.pinball.maps)."""

import doctest
import math
from pathlib import Path

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skillchain_torch.envs.pinball import map_parser, maps
from skillchain_torch.envs.pinball.map_parser import RADIUS_MAX, RADIUS_MIN
from skillchain_torch.envs.pinball.maps import MAP_NAMES, PinballMap, load_map

SETTINGS = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
GOOD = "ball 0.02\ntarget 0.9 0.2 0.04\nstart 0.2 0.9\npolygon 0.1 0.1 0.3 0.1 0.2 0.3\n"
REAL_TEXTS = {n: Path(load_map(n).source).read_text() for n in MAP_NAMES}


def test_doctests():
    for module in (map_parser, maps):
        assert doctest.testmod(module, optionflags=doctest.ELLIPSIS).failed == 0


def parse(text):
    return PinballMap.from_string(text, source="pinball_x.cfg")


def naive_records(text):
    """Independent reading of a file: {kind: [list of float lists]}."""
    out = {}
    for line in text.splitlines():
        tok = line.split()
        if tok:
            out.setdefault(tok[0], []).append([float(t) for t in tok[1:]])
    return out


# ---------------------------------------------------------------- the shipped maps


def test_map_names():
    assert MAP_NAMES == (
        "pinball_box",
        "pinball_empty",
        "pinball_hard_single",
        "pinball_hard_two_starts",
        "pinball_medium",
        "pinball_simple_single",
    )


@pytest.mark.parametrize("name", MAP_NAMES)
def test_every_map_loads_exactly(name):
    m = load_map(name)
    rec = naive_records(REAL_TEXTS[name])
    assert m.name == name and m.dtype == torch.float64 and m.device.type == "cpu"
    assert m.ball_radius == rec["ball"][0][0]
    assert [*m.target, m.target_radius] == rec["target"][0]
    assert m.starts.reshape(-1).tolist() == [v for s in rec["start"] for v in s]
    assert [p.reshape(-1).tolist() for p in m.polygons] == rec["polygon"]
    assert m.n_edges == sum(len(p) for p in m.polygons) == m.edge_polygon.shape[0]
    assert m.edge_polygon.dtype == torch.int64 and m.bbox.shape == (m.n_polygons, 4)
    for i, poly in enumerate(m.polygons):
        es, ee = m.edge_start[m.edge_polygon == i], m.edge_end[m.edge_polygon == i]
        assert torch.equal(es, poly)
        assert torch.equal(ee[:-1], poly[1:])
        assert torch.equal(ee[-1], poly[0])  # closing edge n -> 1
        assert m.bbox[i].tolist() == [*poly.min(0).values.tolist(), *poly.max(0).values.tolist()]
    assert name in repr(m) and f"polygons={m.n_polygons}" in repr(m)


def test_simple_single():
    m = load_map("pinball_simple_single")
    assert m.n_polygons == 10 and m.ball_radius == 0.02
    assert (*m.target, m.target_radius) == (0.9, 0.2, 0.04)
    assert m.starts.tolist() == [[0.2, 0.9]]
    assert m.bbox[0].tolist() == [0.0, 0.0, 1.0, 0.01]  # the wall strip along y = 0
    assert m.polygons[4].shape == (7, 2)


def test_hard_maps():
    two = load_map("pinball_hard_two_starts")
    assert two.starts.tolist() == [[0.055, 0.95], [0.945, 0.95]]
    assert two.n_polygons == 18 and two.ball_radius == 0.015
    one = load_map("pinball_hard_single")
    assert one.starts.tolist() == [[0.055, 0.95]]
    assert all(torch.equal(a, b) for a, b in zip(one.polygons, two.polygons, strict=True))
    # Exact doubles are kept: this is not the double nearest 0.332.
    assert one.polygons[4][2].tolist() == [0.33199999999999996, 0.674]
    assert one.polygons[4][2, 0].item() != 0.332


def test_medium_has_duplicated_polygon():
    m = load_map("pinball_medium")
    dups = [
        (i, j)
        for i in range(m.n_polygons)
        for j in range(i + 1, m.n_polygons)
        if torch.equal(m.polygons[i], m.polygons[j])
    ]
    assert dups == [(5, 8)]
    assert m.polygons[5][0, 0].item() == 0.33399999999999996


def test_load_map_suffix_and_unknown():
    assert load_map("pinball_box.cfg").n_polygons == 5
    with pytest.raises(ValueError, match="unknown pinball map 'nope'.*pinball_simple_single"):
        load_map("nope")


def test_to_casts_and_keeps_values():
    m = load_map("pinball_hard_single")
    m32 = m.to(dtype=torch.float32)
    assert m32.dtype == torch.float32 and m32.polygons[0].dtype == torch.float32
    assert m32.bbox.dtype == m32.edge_end.dtype == torch.float32
    assert m32.edge_polygon.dtype == torch.int64 and m.dtype == torch.float64
    assert torch.equal(m32.starts, m.starts.float())
    assert torch.equal(m.to(dtype=torch.float64).polygons[4], m.polygons[4])
    assert load_map("pinball_box", dtype=torch.float32).dtype == torch.float32
    assert m.to().dtype == torch.float64
    with pytest.raises(ValueError, match="floating point"):
        m.to(dtype=torch.int32)


def test_every_original_map_loads(vectors_dir):
    """Every map of the original domain (shared/pinball/configs) loads from its own file, and
    the package ships each one unchanged, so the geometry checks accept all of them."""
    originals = sorted((vectors_dir.parent / "configs").glob("*.cfg"))
    assert [p.stem for p in originals] == list(MAP_NAMES)
    for path in originals:
        m = PinballMap.from_file(path)
        assert m.n_polygons >= 4 and m.starts.shape[0] >= 1, path
        assert Path(load_map(path.stem).source).read_bytes() == path.read_bytes()


# ---------------------------------------------------------------- format details


def test_whitespace_crlf_bom_and_ignored_lines():
    text = (
        "\ufeffball\t0.02  \r\n\r\n# comment 1 2\r\ndrag 0.9\r\ntarget 0.9   0.2 0.04\r\n"
        "start 0.2 0.9 \r\nstart 0.1 0.5\r\npolygon 0.1 0.1 0.3 0.1 0.2 0.3"
    )
    m = PinballMap.from_string(text)
    assert m.starts.tolist() == [[0.2, 0.9], [0.1, 0.5]]  # start lines are concatenated
    assert m.n_polygons == 1 and m.ball_radius == 0.02


def test_zero_polygons_allowed():
    m = PinballMap.from_string("ball 0.02\ntarget 0.9 0.2 0.04\nstart 0.2 0.9")
    assert m.n_polygons == 0 and m.n_edges == 0
    assert m.edge_start.shape == (0, 2) and m.bbox.shape == (0, 4)
    assert m.edge_polygon.dtype == torch.int64


def _replace_line(n, new):
    lines = GOOD.splitlines()
    lines[n - 1] = new
    return "\n".join(lines)


ERRORS = [
    (GOOD.replace("ball 0.02\n", ""), r"pinball_x\.cfg: missing 'ball' record"),
    (GOOD.replace("target 0.9 0.2 0.04\n", ""), r"pinball_x\.cfg: missing 'target' record"),
    (GOOD.replace("start 0.2 0.9\n", ""), r"pinball_x\.cfg: missing 'start' record"),
    (GOOD + "\nball 0.03", r"line 6: duplicate 'ball' record \(first on line 1\)"),
    (GOOD + "target 0.1 0.1 0.1", r"line 5: duplicate 'target' record \(first on line 2\)"),
    (_replace_line(1, "ball 0.02 0.03"), r"line 1: 'ball' needs exactly 1 number \(got 2\)"),
    (_replace_line(1, "ball"), r"line 1: 'ball' needs exactly 1 number \(got 0\)"),
    (_replace_line(2, "target 0.9 0.2"), r"line 2: 'target' needs exactly 3 numbers \(got 2\)"),
    (
        _replace_line(3, "start 0.2 0.9 0.5"),
        r"line 3: 'start' needs an even number of coordinates \(got 3\)",
    ),
    (_replace_line(3, "start"), r"line 3: 'start' needs at least 1 x y pair \(got 0\)"),
    (
        _replace_line(4, "polygon 0.1 0.1 0.3 0.1 0.2"),
        r"line 4: 'polygon' needs an even number of coordinates \(got 5\)",
    ),
    (
        _replace_line(4, "polygon 0.1 0.1 0.3 0.1"),
        r"line 4: 'polygon' needs at least 3 x y pairs \(got 2\)",
    ),
    (_replace_line(1, "ball abc"), r"line 1: 'abc' is not a number"),
    (_replace_line(2, "target 0.9 0.2 1_0"), r"line 2: '1_0' is not a number"),
    (_replace_line(3, "start 0.2 0x1"), r"line 3: '0x1' is not a number"),
    (_replace_line(3, "start nan 0.9"), r"line 3: 'nan' is not a finite number"),
    (_replace_line(1, "ball inf"), r"line 1: 'inf' is not a finite number"),
    (
        _replace_line(4, "polygon 0.1 1e999 0.3 0.1 0.2 0.3"),
        r"line 4: '1e999' is not a finite number",
    ),
    (
        _replace_line(3, "start 1.5 0.9"),
        r"line 3: coordinate 1\.5 is outside the unit square \(allowed range \[0, 1\]\)",
    ),
    (_replace_line(4, "polygon 0.1 -0.1 0.3 0.1 0.2 0.3"), r"line 4: coordinate -0\.1 is outside"),
    (_replace_line(2, "target 0.9 1.2 0.04"), r"line 2: coordinate 1\.2 is outside"),
    (_replace_line(1, "ball 0"), r"line 1: 'ball' radius must be positive \(got 0\.0\)"),
    (_replace_line(1, "ball -0.02"), r"line 1: 'ball' radius must be positive"),
    (_replace_line(2, "target 0.9 0.2 0"), r"line 2: 'target' radius must be positive"),
    (
        _replace_line(4, "polygon 0.1 0.1 0.3 0.1 0.3 0.1"),
        r"line 4: 'polygon' vertices 2 and 3 coincide .*zero-length edge",
    ),
    (
        _replace_line(4, "polygon 0.1 0.1 0.3 0.1 0.2 0.3 0.1 0.1"),
        r"line 4: 'polygon' vertices 4 and 1 coincide",
    ),
    ("\n\r\n" + GOOD.replace("ball 0.02", "ball x"), r"line 3: 'x' is not a number"),
    (GOOD + "\x00", r"pinball_x\.cfg: contains NUL"),
]


@pytest.mark.parametrize(("text", "match"), ERRORS)
def test_validation_errors(text, match):
    with pytest.raises(ValueError, match=match):
        parse(text)


def test_from_file(tmp_path):
    good = tmp_path / "good.cfg"
    good.write_text(GOOD)
    m = PinballMap.from_file(good)
    assert m.name == "good" and m.source == str(good)
    assert PinballMap.from_file(str(good)).n_polygons == 1
    bad = tmp_path / "bad.cfg"
    bad.write_text(GOOD.replace("0.04", "-1"))
    with pytest.raises(ValueError, match=r"bad\.cfg, line 2: 'target' radius"):
        PinballMap.from_file(bad)
    junk = tmp_path / "junk.cfg"
    junk.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(ValueError, match=r"junk\.cfg: not UTF-8 text"):
        PinballMap.from_file(junk)
    with pytest.raises(FileNotFoundError):
        PinballMap.from_file(tmp_path / "missing.cfg")
    with pytest.raises(TypeError):
        PinballMap.from_string(b"ball 0.02")


# ---------------------------------------------------------------- property-based


def parses_or_value_error(text):
    try:
        m = PinballMap.from_string(text, source="fuzz.cfg")
    except ValueError as err:
        assert str(err).startswith("fuzz.cfg")
        return None
    # Whatever loads must satisfy the documented invariants.
    assert RADIUS_MIN <= m.ball_radius < RADIUS_MAX and RADIUS_MIN <= m.target_radius < RADIUS_MAX
    assert m.starts.shape[0] >= 1
    assert m.n_edges == sum(len(p) for p in m.polygons)
    for t in (m.starts, m.edge_start, m.edge_end, m.bbox):
        assert bool(((t >= 0) & (t <= 1)).all())
    return m


KEYWORDS = st.sampled_from(["ball", "target", "start", "polygon", "drag", "#", "", "Ball"])
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(-0.5, 1.5).map(str),
    st.sampled_from(["nan", "inf", "-inf", "1e999", "-0", "1_0", "0x1p-2", "½", "٠.٥", "1e"]),
    st.text(min_size=1, max_size=4).filter(lambda s: not s.isspace()),
)
LINES = st.builds(
    lambda k, nums, sep: sep.join([k, *nums]),
    KEYWORDS,
    st.lists(NUMBERS, max_size=9),
    st.sampled_from([" ", "  ", "\t", " \x0b"]),
)


@SETTINGS
@given(st.text())
def test_fuzz_random_text(text):
    parses_or_value_error(text)


@SETTINGS
@given(st.lists(LINES, max_size=12), st.sampled_from(["\n", "\r\n", "\r"]))
def test_fuzz_token_soup(lines, newline):
    parses_or_value_error(newline.join(lines))


@SETTINGS
@given(st.sampled_from(sorted(REAL_TEXTS)), st.data())
def test_fuzz_mutated_real_files(name, data):
    lines = [line.split(" ") for line in REAL_TEXTS[name].split("\n")]
    for _ in range(data.draw(st.integers(1, 3))):
        op = data.draw(
            st.sampled_from(
                ["del_line", "dup_line", "del_tok", "ins_tok", "dup_tok", "replace", "truncate"]
            )
        )
        if not lines:
            break
        i = data.draw(st.integers(0, len(lines) - 1))
        line = lines[i]
        j = data.draw(st.integers(0, max(len(line) - 1, 0)))
        if op == "del_line":
            del lines[i]
        elif op == "dup_line":
            lines.insert(i, list(line))
        elif op == "del_tok" and line:
            del line[j]
        elif op in ("ins_tok", "replace"):
            tok = data.draw(NUMBERS | KEYWORDS)
            line[j : j + (op == "replace")] = [tok]
        elif op == "dup_tok" and line:
            line.insert(j, line[j])
        elif op == "truncate":
            text = "\n".join(" ".join(t) for t in lines)
            cut = data.draw(st.integers(0, len(text)))
            lines = [t.split(" ") for t in text[:cut].split("\n")]
    parses_or_value_error("\n".join(" ".join(t) for t in lines))


# Valid by construction (the geometry checks must accept every such map): starts in the
# strip x <= 0.1, polygons at x >= 0.2 and the target at x >= 0.5, so with a ball radius at
# most 0.05 and a target radius under 0.35 no start touches an obstacle or the goal.
BALL = st.floats(RADIUS_MIN, 0.05)
TARGET_R = st.floats(RADIUS_MIN, 0.35)
START = st.tuples(st.floats(0.0, 0.1), st.floats(0.0, 1.0))


@st.composite
def star_polygon(draw):
    """A random star-shaped polygon around a centre: one vertex per sector of 2 pi / n, each
    angle jittered by at most 15% of a sector, so neighbouring angles differ by at least 0.48
    and by less than pi: simple, of clearly non-zero area, inside [0.2, 1] x [0.01, 0.99]."""
    cx, cy = draw(st.floats(0.3, 0.9)), draw(st.floats(0.11, 0.89))
    n = draw(st.integers(3, 9))
    phase = draw(st.floats(0.0, 2 * math.pi))
    jitter = draw(st.lists(st.floats(-0.15, 0.15), min_size=n, max_size=n))
    radii = draw(st.lists(st.floats(0.001, 0.1), min_size=n, max_size=n))
    return [
        (cx + r * math.cos(phase + 2 * math.pi * (k + u) / n),
         cy + r * math.sin(phase + 2 * math.pi * (k + u) / n))
        for k, (u, r) in enumerate(zip(jitter, radii, strict=True))
    ]  # fmt: skip


@SETTINGS
@given(
    BALL,
    st.floats(0.5, 1.0),
    st.floats(0.0, 1.0),
    TARGET_R,
    st.lists(START, min_size=1, max_size=3),
    st.lists(star_polygon(), max_size=6),
    st.sampled_from([" ", "  ", "\t"]),
    st.sampled_from(["\n", "\r\n", " \n", "\n\n"]),
    st.booleans(),
)
def test_valid_maps_round_trip(ball, tx, ty, tr, starts, polygons, sep, newline, trailing):
    def line(kind, values):
        return sep.join([kind, *map(repr, values)])

    lines = [
        line("ball", [ball]),
        line("target", [tx, ty, tr]),
        line("start", [v for s in starts for v in s]),
        "comment ignored 1 2",
    ]
    lines += [line("polygon", [v for p in poly for v in p]) for poly in polygons]
    m = parses_or_value_error(newline.join(lines) + (newline if trailing else ""))
    assert m is not None
    assert (m.ball_radius, m.target, m.target_radius) == (ball, (tx, ty), tr)
    assert m.starts.tolist() == [list(s) for s in starts]
    assert [p.tolist() for p in m.polygons] == [[list(v) for v in poly] for poly in polygons]
    assert m.edge_polygon.tolist() == [i for i, p in enumerate(polygons) for _ in p]


def test_an_edge_whose_squared_length_underflows_is_refused():
    # Found by the fuzz test: two distinct vertices 3.2e-305 apart; the edge's squared length
    # is 0, and the contact test divided by it.
    text = REAL_TEXTS["pinball_box"]
    line = next(t for t in text.split("\n") if t.startswith("polygon"))
    tiny = "polygon 0.0 0.0 3.2e-305 0.0 " + " ".join(line.split()[3:])
    with pytest.raises(ValueError, match="zero-length edge"):
        PinballMap.from_string(text.replace(line, tiny), source="tiny.cfg")
