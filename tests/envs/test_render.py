"""Tests for board rendering (skillchain_torch.envs.pinball.render)."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.path import Path as MplPath  # noqa: E402

from skillchain_torch.envs.pinball import render  # noqa: E402
from skillchain_torch.envs.pinball.maps import PinballMap, load_map  # noqa: E402
from skillchain_torch.envs.pinball.render import (  # noqa: E402
    BACKGROUND_COLOR,
    BALL_COLOR,
    POLYGON_COLOR,
    TARGET_COLOR,
    plot_trajectories,
    render_frame,
)

SIMPLE = load_map("pinball_simple_single")


def pixel(frame, x, y):
    size = frame.shape[0]
    return tuple(frame[int(y * size), int(x * size)].tolist())


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def test_frame_shape_dtype_and_colours():
    frame = render_frame(SIMPLE, size=400)
    assert frame.shape == (400, 400, 3) and frame.dtype == np.uint8
    assert pixel(frame, 0.9, 0.2) == TARGET_COLOR  # target centre
    assert pixel(frame, 0.7, 0.83) == POLYGON_COLOR  # inside the obstacle near the start
    assert pixel(frame, 0.55, 0.5) == BACKGROUND_COLOR  # free space
    assert pixel(frame, 0.5, 0.002) == POLYGON_COLOR  # wall strip along y = 0
    assert pixel(frame, 0.2, 0.9) == BACKGROUND_COLOR  # start cell, no ball drawn


def test_obstacles_match_matplotlib_point_in_polygon():
    # At this size no pixel centre lies exactly on an edge of this map, where the two
    # tests may legitimately disagree (at 100, (0.705, 0.025) is on an edge).
    size = 128
    frame = render_frame(SIMPLE, size=size)
    c = (np.arange(size) + 0.5) / size
    pts = np.stack(np.meshgrid(c, c), axis=-1).reshape(-1, 2)  # (x = column, y = row)
    ref = np.zeros(len(pts), dtype=bool)
    for poly in SIMPLE.polygons:
        ref |= MplPath(poly.numpy()).contains_points(pts)
    ours = (frame.reshape(-1, 3) == POLYGON_COLOR).all(axis=1)
    target = (frame.reshape(-1, 3) == TARGET_COLOR).all(axis=1)
    assert ref.sum() > 1000
    assert not (ours & ~ref).any()
    assert not (ref & ~ours & ~target).any()


@pytest.mark.parametrize("name", ["pinball_hard_single", "pinball_medium"])
def test_even_odd_test_matches_matplotlib_on_random_points(name):
    rng = np.random.default_rng(0)
    px, py = rng.random((1, 500)), rng.random((500, 1))
    grid = np.stack(np.broadcast_arrays(px, py), axis=-1).reshape(-1, 2)
    for poly in load_map(name).polygons:
        ours = render._inside_polygon(poly.numpy(), px, py).reshape(-1)
        assert np.array_equal(ours, MplPath(poly.numpy()).contains_points(grid))


def test_ball_position_and_orientation():
    empty = load_map("pinball_empty")
    frame = render_frame(empty, state=(0.5, 0.1, 0.3, -0.2), size=200)
    assert pixel(frame, 0.5, 0.1) == BALL_COLOR
    rows, cols = np.nonzero((frame == BALL_COLOR).all(axis=-1))
    assert rows.max() < 0.2 * 200  # y = 0.1 is near the top of the picture
    assert abs(rows.mean() - 0.1 * 200) < 1 and abs(cols.mean() - 0.5 * 200) < 1
    # Disc area matches pi r^2 in pixels.
    assert abs(len(rows) - np.pi * (empty.ball_radius * 200) ** 2) < 3
    low = render_frame(empty, state=torch.tensor([0.5, 0.9, 0.0, 0.0]), size=200)
    assert np.nonzero((low == BALL_COLOR).all(axis=-1))[0].min() > 0.8 * 200


def test_ball_on_simple_start():
    frame = render_frame(SIMPLE, state=SIMPLE.starts[0])
    assert pixel(frame, 0.2, 0.9) == BALL_COLOR
    assert pixel(frame, 0.2, 0.9 + 2 * SIMPLE.ball_radius) != BALL_COLOR


def test_ball_partly_or_fully_off_board():
    frame = render_frame(SIMPLE, state=np.array([0.995, 0.5]), size=100)
    assert (frame == BALL_COLOR).all(axis=-1).any()
    outside = render_frame(SIMPLE, state=[3.0, -2.0], size=100)
    assert np.array_equal(outside, render_frame(SIMPLE, size=100))
    with pytest.raises(ValueError, match="non-finite"):
        render_frame(SIMPLE, state=[float("nan"), 0.5])
    with pytest.raises(ValueError, match="at least x and y"):
        render_frame(SIMPLE, state=[0.5])
    with pytest.raises(ValueError, match="positive"):
        render_frame(SIMPLE, size=0)


def test_background_is_cached_per_map_and_size(monkeypatch):
    m = load_map("pinball_box")  # a fresh map object: nothing cached yet
    calls = []
    original = render._inside_polygon
    monkeypatch.setattr(render, "_inside_polygon", lambda *a: calls.append(1) or original(*a))
    first = render_frame(m, size=64)
    assert len(calls) == m.n_polygons
    second = render_frame(m, state=(0.2, 0.9), size=64)
    assert len(calls) == m.n_polygons  # no re-rasterisation
    assert render._BACKGROUNDS[m][64] is render._background(m, 64)
    render_frame(m, size=32)
    assert len(calls) == 2 * m.n_polygons  # another size is another picture
    # Callers get writable copies; drawing the ball never touched the cache.
    first[:] = 0
    assert not (render._BACKGROUNDS[m][64] == BALL_COLOR).all(axis=-1).any()
    assert (second == BALL_COLOR).all(axis=-1).any()
    assert not render._BACKGROUNDS[m][64].flags.writeable


def test_map_without_polygons_and_float32():
    m = PinballMap.from_string("ball 0.05\ntarget 0.5 0.5 0.1\nstart 0.2 0.2")
    frame = render_frame(m.to(dtype=torch.float32), state=(0.2, 0.2), size=50)
    assert pixel(frame, 0.5, 0.5) == TARGET_COLOR and pixel(frame, 0.2, 0.2) == BALL_COLOR
    assert pixel(frame, 0.9, 0.9) == BACKGROUND_COLOR


def test_plot_trajectories_single_colours():
    trajs = [
        np.array([[0.2, 0.9, 0, 0], [0.3, 0.8, 0, 0], [0.4, 0.7, 0, 0]]),
        torch.tensor([[0.2, 0.9], [0.25, 0.95]]),
    ]
    ax = plot_trajectories(SIMPLE, trajs, colors=["red", (0, 0, 1)], labels=["a", "b"])
    assert len(ax.lines) == 2
    assert ax.lines[0].get_xydata().tolist() == [[0.2, 0.9], [0.3, 0.8], [0.4, 0.7]]
    assert ax.lines[1].get_color() == (0, 0, 1)
    assert len(ax.patches) == SIMPLE.n_polygons + 1  # obstacles + target circle
    assert ax.get_ylim() == (1.0, 0.0) and ax.get_xlim() == (0.0, 1.0)
    assert ax.get_legend() is not None
    # Drawing again into the same axes keeps y = 0 at the top.
    plot_trajectories(SIMPLE, trajs, ax=ax)
    assert ax.get_ylim() == (1.0, 0.0) and len(ax.lines) == 4


def test_plot_trajectories_per_step_colours():
    traj = torch.tensor([[0.2, 0.9], [0.3, 0.85], [0.4, 0.8], [0.5, 0.7]])
    fig, ax = plt.subplots()
    out = plot_trajectories(
        SIMPLE, [traj, traj], ax=ax, show_starts=False, colors=[["C0", "C0", "C1", "C2"], "black"]
    )
    assert out is ax and len(ax.lines) == 1
    (lc,) = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert len(lc.get_segments()) == 3
    assert np.allclose(lc.get_colors(), matplotlib.colors.to_rgba_array(["C0", "C0", "C1"]))
    # A [T - 1, 4] RGBA array works too, and the start markers form one more collection.
    ax2 = plot_trajectories(SIMPLE, traj[None], colors=[np.ones((3, 4)) * 0.5])
    assert len(ax2.collections) == 2 and len(ax2.lines) == 0


def test_plot_trajectories_bad_input():
    traj = np.zeros((4, 2))
    with pytest.raises(ValueError, match="4 steps but 2 colours"):
        plot_trajectories(SIMPLE, [traj], colors=[["C0", "C1"]])
    with pytest.raises(ValueError, match="colours for 1 trajector"):
        plot_trajectories(SIMPLE, [traj], colors=["C0", "C1"])
    with pytest.raises(ValueError, match=r"shape \[T, >=2\]"):
        plot_trajectories(SIMPLE, [np.zeros(4)])
