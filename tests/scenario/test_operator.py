"""The operator's arm law (eq. 4.1), adaptation, limits, intent and population."""

import numpy as np
import pytest

from coassist.scenario.operator import (
    AUTHOR,
    OperatorArm,
    OperatorProfile,
    deformed_path,
    intent_trajectory,
    operator_profile,
)
from coassist.scenario.tasks import make_task

DT = 0.008


def _arm(profile, intent, noise=None):
    n = len(intent)
    return OperatorArm(profile, np.asarray(intent, float), DT, np.zeros((n, 2)) if noise is None else noise)


def test_force_is_eq_4_1_without_delay_or_adaptation():
    p = OperatorProfile("t", stiffness_min=700.0, stiffness_max=700.0, stiffness_gain=0.0, damping=12.0,
                        reaction_delay=0.0, force_limit=1e6)
    intent = np.array([[0.3, -0.5]] * 3)
    arm = _arm(p, intent)
    # u_h = K_h (x_ref,h − x) − C_h ẋ, by hand
    fx, fy = arm.force(0, 0.28, -0.49, 0.05, -0.02)
    assert fx == pytest.approx(700.0 * 0.02 - 12.0 * 0.05)
    assert fy == pytest.approx(700.0 * -0.01 - 12.0 * -0.02)


def test_delayed_share_uses_the_error_d_ticks_ago():
    p = OperatorProfile("t", stiffness_min=500.0, stiffness_max=500.0, stiffness_gain=0.0, damping=0.0,
                        reaction_delay=3 * DT, reflex_share=0.4, force_limit=1e6)
    intent = np.zeros((10, 2))
    arm = _arm(p, intent)
    xs = [0.001 * (k + 1) for k in range(8)]
    forces = [arm.force(k, x, 0.0, 0.0, 0.0)[0] for k, x in enumerate(xs)]
    for k in range(3, 8):  # e(k) = −x(k): 0.6 of it now, 0.4 of it 3 ticks ago
        assert forces[k] == pytest.approx(500.0 * (0.6 * -xs[k] + 0.4 * -xs[k - 3]))
    assert forces[0] == pytest.approx(500.0 * -xs[0])  # before d ticks: the first error


def test_stiffness_adapts_to_error_and_force_is_limited():
    p = OperatorProfile("t", stiffness_min=400.0, stiffness_max=1500.0, stiffness_gain=20000.0,
                        adaptation_time=0.1, damping=0.0, reaction_delay=0.0, force_limit=30.0)
    n = 200
    small, large = _arm(p, np.zeros((n, 2))), _arm(p, np.zeros((n, 2)))
    for k in range(n):
        small.force(k, 0.002, 0.0, 0.0, 0.0)
        f_large = large.force(k, 0.05, 0.05, 0.0, 0.0)
    assert small.stiffness == pytest.approx(400.0 + 20000.0 * 0.002, rel=1e-3)
    assert large.stiffness == pytest.approx(1500.0)  # clipped at K_max
    assert np.hypot(*f_large) == pytest.approx(30.0)  # scaled to the limit ...
    assert f_large[0] == pytest.approx(f_large[1])  # ... keeping its direction


def test_profile_validation_names_the_field():
    with pytest.raises(ValueError, match="OperatorProfile.damping"):
        OperatorProfile("t", damping=-1.0)
    with pytest.raises(ValueError, match="stiffness_max"):
        OperatorProfile("t", stiffness_min=900.0, stiffness_max=800.0)
    with pytest.raises(ValueError, match="user_index"):
        operator_profile(-1)


def test_population_is_seeded_and_user_0_is_the_author():
    assert operator_profile(0) is AUTHOR and operator_profile(0, 5) is AUTHOR
    assert operator_profile(3, 1) == operator_profile(3, 1)
    assert operator_profile(3, 1) != operator_profile(3, 2)
    users = [operator_profile(i) for i in range(1, 6)]
    assert len({u.stiffness_min for u in users}) == 5
    assert all(u.name == f"user-{i}" for i, u in enumerate(users, 1))


@pytest.mark.parametrize("kind", ["linear", "curved", "sinusoidal", "z"])
@pytest.mark.parametrize("side", [1, -1])
def test_intent_clears_the_obstacle(kind, side):
    for seed in range(5):
        task = make_task(kind, np.random.default_rng(seed))
        pts, amp, taken = deformed_path(task, side, clearance=0.02, anticipation=0.06)
        assert taken in (1, -1)
        assert task.obstacle.signed_distance(pts).min() >= 0.01 - 1e-12
        np.testing.assert_allclose(pts[0], task.path.start, atol=1e-9)
        np.testing.assert_allclose(pts[-1], task.path.end, atol=1e-9)
        assert amp >= 0.03 + 0.02 - 1e-12  # half the box plus the clearance at least


def test_intent_trajectory_ends_at_the_target_at_rest():
    task = make_task("curved", np.random.default_rng(1))
    intent = intent_trajectory(task, AUTHOR, np.random.default_rng(2), 3000, DT)
    np.testing.assert_allclose(intent.positions[-1], task.target, atol=1e-9)
    np.testing.assert_allclose(intent.velocities[-1], 0.0)
    np.testing.assert_allclose(intent.positions[0], task.start, atol=1e-9)
    assert intent.end_time == pytest.approx(task.planner.start_delay + AUTHOR.start_delay + task.planner.duration / intent.pace)
