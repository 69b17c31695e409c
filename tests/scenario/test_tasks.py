"""Nominal paths, the minimum-jerk planner and the obstacle placement."""

import numpy as np
import pytest

from coassist.scenario.tasks import (
    END,
    START,
    TASK_KINDS,
    Box,
    MotionPlanner,
    make_task,
    nominal_path,
)


@pytest.mark.parametrize("kind", TASK_KINDS)
def test_path_endpoints_and_arc_length(kind):
    path = nominal_path(kind)
    if kind == "z":  # spans the same x range, shrunk by 5 cm, from the top stroke to the bottom one
        np.testing.assert_allclose(path.start, [START[0] + 0.05, START[1] + 0.15], atol=1e-12)
        np.testing.assert_allclose(path.end, [END[0] - 0.05, END[1] - 0.15], atol=1e-12)
    else:
        np.testing.assert_allclose(path.start, START, atol=1e-12)
        np.testing.assert_allclose(path.end, END, atol=1e-12)
    np.testing.assert_allclose(path.position(0.0), path.start)
    np.testing.assert_allclose(path.position(path.length), path.end)
    assert path.length >= np.linalg.norm(path.end - path.start) - 1e-12
    # unit tangents, and a smooth path: no step in direction above 10° between samples
    t = path.tangents
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0)
    turn = np.degrees(np.arccos(np.clip(np.sum(t[1:] * t[:-1], axis=1), -1, 1)))
    assert turn.max() < 10.0


def test_path_lengths_match_the_real_references():
    # real user-a references: linear 0.50 m, arc 0.60 m, S 0.87 m
    assert nominal_path("linear").length == pytest.approx(0.50, abs=1e-9)
    assert nominal_path("curved").length == pytest.approx(0.60, abs=0.03)
    assert 0.7 < nominal_path("sinusoidal").length < 0.9


@pytest.mark.parametrize("kind", TASK_KINDS)
def test_planner_profile_zero_at_ends_and_peak_matches_closed_form(kind):
    planner = MotionPlanner(nominal_path(kind), 10.0, start_delay=1.0)
    dt = 0.001
    grid = planner.grid(int(12.0 / dt), dt)
    speed = np.linalg.norm(grid[:, 2:], axis=1)
    t = np.arange(len(grid)) * dt
    assert speed[0] == 0.0 and speed[-1] == 0.0
    assert np.all(speed[t <= 1.0] == 0.0) and np.all(speed[t >= 11.0] == 0.0)
    np.testing.assert_allclose(grid[0, :2], planner.path.start, atol=1e-12)
    np.testing.assert_allclose(grid[-1, :2], planner.path.end, atol=1e-12)
    # closed form of the quintic: peak 1.875 L/T at mid-motion
    assert planner.peak_speed == pytest.approx(1.875 * planner.path.length / 10.0)
    assert speed.max() == pytest.approx(planner.peak_speed, rel=2e-3)
    assert t[np.argmax(speed)] == pytest.approx(6.0, abs=0.05)
    # velocity is the derivative of position
    np.testing.assert_allclose(np.gradient(grid[:, 0], dt)[1:-1], grid[1:-1, 2], atol=2e-3)


def test_horizon_rows_hold_the_end_point():
    planner = MotionPlanner(nominal_path("linear"), 2.0, start_delay=0.0)
    rows = planner.horizon_rows(240, 50, 0.008)  # t = 1.928 … 2.32 s: crosses the end at 2 s
    assert rows.shape == (50, 4)
    np.testing.assert_allclose(rows[-20:, :2], np.tile(planner.path.end, (20, 1)))
    np.testing.assert_allclose(rows[-20:, 2:], 0.0)
    np.testing.assert_allclose(rows, planner.grid(291, 0.008)[241:291])


def test_obstacle_placement_is_seeded():
    a = make_task("curved", np.random.default_rng(7))
    b = make_task("curved", np.random.default_rng(7))
    c = make_task("curved", np.random.default_rng(8))
    assert a.obstacle == b.obstacle and a.obstacle_arc == b.obstacle_arc
    assert a.obstacle != c.obstacle
    for seed in range(20):
        task = make_task("sinusoidal", np.random.default_rng(seed))
        frac = task.obstacle_arc / task.path.length
        assert 0.3 <= frac <= 0.7
        np.testing.assert_allclose(task.obstacle.center, task.path.position(task.obstacle_arc))
        assert task.obstacle.signed_distance(task.path.position(task.obstacle_arc)) < 0  # on the path
    for seed in range(30):  # never on one of the Z's corners
        task = make_task("z", np.random.default_rng(seed))
        t0, t1 = task.path.tangent(task.obstacle_arc - 0.06), task.path.tangent(task.obstacle_arc + 0.06)
        assert np.dot(t0, t1) >= 0.5


def test_validation_names_the_field():
    with pytest.raises(ValueError, match="duration"):
        MotionPlanner(nominal_path("linear"), -1.0)
    with pytest.raises(ValueError, match="Box.size"):
        Box((0.0, 0.0), (0.0, 0.1))
    with pytest.raises(ValueError, match="task kind"):
        nominal_path("circle")
    with pytest.raises(ValueError, match="rng"):
        make_task("linear", 3)


def test_box_signed_distance():
    box = Box((0.0, 0.0), (0.2, 0.1))
    np.testing.assert_allclose(
        box.signed_distance(np.array([[0.0, 0.0], [0.3, 0.0], [0.1, 0.05], [0.2, 0.15]])),
        [-0.05, 0.2, 0.0, np.hypot(0.1, 0.1)],
    )


def test_a_plan_that_turns_straight_back_has_the_incoming_direction_at_the_turn():
    """np.gradient's central difference is zero where a plan turns straight back on itself (its two neighbours the
    same point): the tangent there was 0/0 = NaN, and every projection onto that vertex NaN. It is the incoming
    segment's direction; elsewhere the central one, as before."""
    from coassist.scenario.tasks import NominalPath

    path = NominalPath("back", np.array([[0.0, 0.0], [0.3, 0.0], [0.0, 0.0], [0.0, 0.2]]))
    assert np.isfinite(path.tangents).all()
    np.testing.assert_array_equal(path.tangents[1], [1.0, 0.0])
    # where the gradient is not zero, the central difference, normalised, as np.gradient gives it
    g = np.gradient(path.points, path.arc, axis=0)[2]
    np.testing.assert_allclose(path.tangents[2], g / np.linalg.norm(g), rtol=0, atol=1e-15)
