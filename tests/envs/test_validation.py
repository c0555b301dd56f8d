"""Issue 17, part A: bad maps and bad calls end in one clear error, never in wrong results.

One test per reproducer of the issue: each asserts the exception type and that the message
names the input (file, line, polygon, vertex, field) and the allowed range.
"""

import math

import numpy as np
import pytest
import torch

from skillchain_torch.envs.pinball import GymPinballEnv, PinballEnv, PinballMap, grid

HEAD = "ball 0.02\ntarget 0.9 0.2 0.04\nstart 0.2 0.9\n"
BOX = "polygon 0.4 0.4 0.6 0.4 0.6 0.6 0.4 0.6\n"  # a 0.2 x 0.2 square at the centre


def load(tmp_path, text):
    path = tmp_path / "bad.cfg"
    path.write_text(text)
    return PinballMap.from_file(path)


def polygon_line(points):
    return "polygon " + " ".join(f"{x!r} {y!r}" for x, y in points) + "\n"


# ---------------------------------------------------------------- map geometry


@pytest.mark.parametrize(
    ("polygon", "edges"),
    [
        # a bow tie: edges 1-2 and 3-4 cross
        ("polygon 0.3 0.3 0.5 0.5 0.5 0.3 0.3 0.5\n", r"vertex 1 to 2 .* vertex 3 to 4"),
        # vertex 4 lies exactly on edge 1-2 (touching counts)
        ("polygon 0.3 0.3 0.6 0.3 0.6 0.6 0.45 0.3 0.3 0.6\n", r"vertex 1 to 2 .* vertex 3 to 4"),
        # the outline doubles back along itself at vertex 3 (a zero-width spike)
        ("polygon 0.3 0.3 0.6 0.3 0.6 0.6 0.6 0.45\n", r"vertex 2 to 3 .* vertex 3 to 4"),
    ],
)
def test_self_intersecting_polygon_is_refused(tmp_path, polygon, edges):
    """Line 5 holds the file's second polygon; the message names file, line, polygon, edges."""
    with pytest.raises(ValueError, match=r"bad\.cfg, line 5: polygon 2 is self-intersecting: "):
        load(tmp_path, HEAD + BOX + polygon)
    with pytest.raises(ValueError, match=edges):
        load(tmp_path, HEAD + BOX + polygon)


def test_self_intersection_found_in_a_20000_vertex_polygon(tmp_path):
    """Large outlines take the vectorised sweep; one vertex pulled across the circle is found."""
    n = 20000
    points = [
        (0.6 + 0.25 * math.cos(2 * math.pi * k / n), 0.5 + 0.25 * math.sin(2 * math.pi * k / n))
        for k in range(n)
    ]
    load(tmp_path, HEAD + polygon_line(points))  # the circle itself is fine
    points[5000] = (0.6 - 0.26, 0.5)  # vertex 5001 pulled from the top to beyond the left side
    with pytest.raises(ValueError, match=r"line 4: polygon 1 is self-intersecting: its edge") as e:
        load(tmp_path, HEAD + polygon_line(points))
    assert "vertex 5000 to 5001" in str(e.value) or "vertex 5001 to 5002" in str(e.value)


@pytest.mark.parametrize(
    "polygon",
    [
        "polygon 0.3 0.3 0.4 0.4 0.5 0.5\n",  # three collinear vertices
        "polygon 0.3 0.3 0.4 0.4 0.5 0.5 0.6 0.6\n",
        "polygon 0.3 0.3 0.5 0.3 0.4 0.300000000001\n",  # a sliver 1e-12 thick
    ],
)
def test_zero_area_polygon_is_refused(tmp_path, polygon):
    with pytest.raises(ValueError, match=r"bad\.cfg, line 4: polygon 1 has zero area"):
        load(tmp_path, HEAD + polygon)


def test_start_inside_an_obstacle_is_refused(tmp_path):
    inside = "ball 0.02\ntarget 0.9 0.2 0.04\nstart 0.2 0.9\nstart 0.5 0.5\n" + BOX
    with pytest.raises(
        ValueError,
        match=r"bad\.cfg, line 4: start 2 \(0\.5, 0\.5\) lies inside polygon 1 \(line 5\)",
    ):
        load(tmp_path, inside)
    # Outside, but the ball overlaps the box's left edge (vertex 4 -> 1, at x = 0.4).
    overlapping = "ball 0.02\ntarget 0.9 0.2 0.04\nstart 0.39 0.5\n" + BOX
    with pytest.raises(
        ValueError,
        match=r"line 3: start 1 \(0\.39, 0\.5\): the ball \(radius 0\.02\) overlaps polygon 1 "
        r"\(line 4\) at its edge from vertex 4 to 1",
    ):
        load(tmp_path, overlapping)
    load(tmp_path, overlapping.replace("0.39", "0.37"))  # clear of the edge by 0.01: fine


def test_start_inside_the_target_is_refused(tmp_path):
    with pytest.raises(
        ValueError,
        match=r"bad\.cfg, line 3: start 1 \(0\.91, 0\.2\) lies inside the target disc "
        r"\(centre \(0\.9, 0\.2\), radius 0\.04\)",
    ):
        load(tmp_path, "ball 0.02\ntarget 0.9 0.2 0.04\nstart 0.91 0.2\n")


@pytest.mark.parametrize(
    ("line", "field", "value"),
    [
        ("ball 5", "ball", "5.0"),
        ("ball 1e-320", "ball", "1e-320"),
        ("ball 0.5", "ball", "0.5"),
        ("ball 1e-7", "ball", "1e-07"),
        ("target 0.9 0.2 100", "target", "100.0"),
        ("target 0.9 0.2 0.5", "target", "0.5"),
    ],
)
def test_absurd_radii_are_refused(tmp_path, line, field, value):
    kind = line.split()[0]
    text = HEAD.replace(next(x for x in HEAD.splitlines() if x.startswith(kind)), line)
    number = 1 if kind == "ball" else 2
    with pytest.raises(
        ValueError,
        match=rf"bad\.cfg, line {number}: '{field}' radius {value} is outside the allowed "
        r"range \[1e-06, 0\.5\)",
    ):
        load(tmp_path, text)


def test_radii_at_the_edges_of_the_range_load(tmp_path):
    assert load(tmp_path, HEAD.replace("ball 0.02", "ball 1e-06")).ball_radius == 1e-6
    big_ball = "ball 0.49\ntarget 0.9 0.2 0.04\nstart 0.5 0.5\n"
    assert load(tmp_path, big_ball).ball_radius == 0.49
    big_goal = "ball 0.02\ntarget 0.5 0.5 0.49\nstart 0.0 0.0\n"
    assert load(tmp_path, big_goal).target_radius == 0.49


# ---------------------------------------------------------------- environments


@pytest.mark.parametrize("batch_size", [[0], [3, 0], (0,)])
def test_empty_batch_is_refused(batch_size):
    with pytest.raises(ValueError, match=r"batch_size must have every dimension >= 1, got \["):
        PinballEnv(batch_size=batch_size, seed=0)


def test_pinball_env_step_before_reset_is_refused():
    env = PinballEnv(batch_size=[3], seed=0)
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\): 3 of 3"):
        env.step_raw(torch.tensor([0, 1, 2]))
    td = env.fake_tensordict()
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        env.step(td)  # the TorchRL API goes through the same check
    assert torch.equal(env.state, torch.zeros(3, 4, dtype=torch.float64))  # nothing moved
    env.reset_raw(torch.tensor([True, False, True]))
    with pytest.raises(RuntimeError, match=r"1 of 3 environments \(flat indices 1\)"):
        env.step_raw(torch.tensor([0, 1, 2]))
    env.reset_raw(torch.tensor([False, True, False]))
    env.step_raw(torch.tensor([0, 1, 2]))  # every ball placed: steps
    assert env.state[:, 1].tolist() != [0.0, 0.0, 0.0]

    placed = PinballEnv(batch_size=[1], seed=0)
    placed.set_state(torch.tensor([[0.5, 0.5, 0.1, 0.0]], dtype=torch.float64))
    placed.step_raw(torch.tensor([4]))  # set_state places the balls too
    assert PinballEnv(batch_size=[2], seed=0).rollout(3).shape == (2, 3)  # rollout resets


def test_gym_env_step_before_reset_is_refused():
    env = GymPinballEnv("pinball_simple_single")
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        env.step(0)
    env.reset(seed=0)
    obs, reward, *_ = env.step(0)  # +x from the start (0.2, 0.9): 0.2 + 0.2 r
    assert obs[0] == pytest.approx(0.204, abs=1e-12) and obs[1] == 0.9 and reward == -5.0


@pytest.mark.parametrize(
    "action", [True, False, np.bool_(True), 1.0, np.float64(2.0), "1", None, np.array([1])]
)
def test_gym_env_refuses_bools_and_non_integers(action):
    env = GymPinballEnv("pinball_simple_single")
    env.reset(seed=0)
    with pytest.raises(TypeError, match=r"action must be an integer in 0\.\.4, got "):
        env.step(action)


@pytest.mark.parametrize("action", [5, -1, np.int64(7)])
def test_gym_env_refuses_out_of_range_actions(action):
    env = GymPinballEnv("pinball_simple_single")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"must be an integer in 0\.\.4, got .*out of range"):
        env.step(action)


@pytest.mark.parametrize("action", [0, np.int64(1), np.uint8(2), np.array(3)])
def test_gym_env_accepts_integers(action):
    env = GymPinballEnv("pinball_simple_single")
    env.reset(seed=0)
    _, reward, *_ = env.step(action)
    assert reward == -5.0


def test_map_too_large_for_memory_is_refused_before_building(monkeypatch):
    monkeypatch.setattr(grid, "MAX_GRID_BYTES", 1 << 20)  # 1 MiB: every map is too large
    pattern = (
        r"map 'pinball_hard_single' \(.*pinball_hard_single\.cfg\) is too large to simulate: "
        r"its collision grid would need about [0-9.]+ GiB \(85 edges, up to \d+ cell-edge "
        r"entries at resolution 128\), more than (the limit|the memory available)"
    )
    with pytest.raises(ValueError, match=pattern):
        PinballEnv("pinball_hard_single", batch_size=[2], seed=0)
    with pytest.raises(ValueError, match=pattern):
        GymPinballEnv("pinball_hard_single")
