"""The safety layer: each limit, the stops, the bad-tick ramp, and no command outside a limit for any input."""

import math

import numpy as np
import pytest

from coassist.interfaces import Fault
from coassist.runtime.safety import BAD_TICK_FAULTS, SafetyLayer
from coassist.runtime.safety_limits import SafetyLimits, within_limits

DT = 0.008
I6 = np.eye(6)
POSE = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
NO_HAND = np.zeros(6)
BOX = dict(workspace_lower=(-0.5, -0.5, -0.5), workspace_upper=(0.5, 0.5, 0.5))
# limits under which only the one limit a test looks at can act
FREE = dict(tool_speed=100.0, tool_angular_speed=100.0, joint_acceleration=1e6, min_manipulability=0.0)


def step(layer, qd, J=I6, pose=POSE, hand=NO_HAND, upstream=Fault.NONE, robot=Fault.NONE):
    return layer.limit_joint_velocity(np.asarray(qd, dtype=float), J, pose, hand, upstream, robot)


def run_to_steady(layer, qd, J=I6, pose=POSE, ticks=200):
    for _ in range(ticks):
        out, flags, stop = step(layer, qd, J, pose)
    return out, flags, stop


def parallel(a, b):
    return np.allclose(a / np.linalg.norm(a), b / np.linalg.norm(b), atol=1e-12)


# ---------------------------------------------------------------------- velocity sets
def test_joint_velocity_scaled_keeping_direction():
    lim = SafetyLimits(**FREE)
    layer = SafetyLayer(lim, DT, 6)
    req = np.array([3.0, -1.0, 0.5, 0.0, 2.0, -0.2])
    out, flags, stop = step(layer, req)
    assert not stop and flags == Fault.JOINT_VELOCITY_LIMIT
    assert parallel(out, req)
    assert np.max(np.abs(out)) == pytest.approx(lim.margin * math.pi / 2, rel=1e-12)
    assert within_limits(out, np.zeros(6), I6, POSE, lim, DT) == []


def test_per_joint_velocity_limits():
    lim = SafetyLimits(joint_velocity=(1.0, 1.0, 1.0, 2.0, 2.0, 0.1), **FREE)
    layer = SafetyLayer(lim, DT, 6)
    req = np.ones(6)
    out, flags, _ = step(layer, req)
    assert flags & Fault.JOINT_VELOCITY_LIMIT
    assert parallel(out, req)
    assert out[5] == pytest.approx(0.098, rel=1e-12)  # the slowest joint sets the scale
    with pytest.raises(ValueError, match="SafetyLimits.joint_velocity"):
        SafetyLayer(lim, DT, 7)


def test_acceleration_ramp_on_a_step():
    lim = SafetyLimits(tool_speed=100.0, tool_angular_speed=100.0)
    layer = SafetyLayer(lim, DT, 6)
    v = 1.0
    target = np.full(6, v)
    a_dt = lim.joint_acceleration * DT
    expected = math.ceil(v / (lim.margin * a_dt))
    prev, ticks = np.zeros(6), 0
    while True:
        out, flags, _ = step(layer, target)
        assert np.max(np.abs(out - prev)) <= a_dt + 1e-12  # each step within a·dt
        assert parallel(out, target)
        ticks += 1
        if np.array_equal(out, target):
            break
        assert flags == Fault.JOINT_ACCELERATION_LIMIT
        prev = out
        assert ticks < 100
    assert ticks == expected
    out, flags, _ = step(layer, target)  # steady: no intervention
    assert flags == Fault.NONE and np.array_equal(out, target)


def test_tool_speed_with_a_block_identity_jacobian():
    lim = SafetyLimits(joint_acceleration=1e6)
    layer = SafetyLayer(lim, DT, 6)
    req = np.array([1.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    out, flags, _ = step(layer, req)
    assert flags == Fault.TOOL_SPEED_LIMIT
    assert parallel(out, req)
    assert np.linalg.norm(out[:3]) == pytest.approx(lim.margin * lim.tool_speed, rel=1e-12)
    req = np.array([0.0, 0.0, 0.1, 0.0, 1.0, 1.0])  # angular speed binds
    out, flags, _ = step(layer, req)
    assert flags == Fault.TOOL_SPEED_LIMIT
    assert np.linalg.norm(out[3:]) == pytest.approx(lim.margin * lim.tool_angular_speed, rel=1e-12)
    assert out[2] == pytest.approx(0.1 * lim.margin / math.sqrt(2), rel=1e-12)


def test_tool_speed_with_random_jacobians():
    rng = np.random.default_rng(1)
    lim = SafetyLimits(min_manipulability=0.0)
    for _ in range(20):
        J = rng.normal(size=(6, 6))
        layer = SafetyLayer(lim, DT, 6)
        req = rng.normal(size=6) * 3.0
        out, flags, _ = run_to_steady(layer, req, J)
        assert parallel(out, req)
        lin, ang = np.linalg.norm((J @ out)[:3]), np.linalg.norm((J @ out)[3:])
        assert lin <= lim.margin * lim.tool_speed * (1 + 1e-12)
        assert ang <= lim.margin * lim.tool_angular_speed * (1 + 1e-12)
        assert flags & (Fault.TOOL_SPEED_LIMIT | Fault.JOINT_VELOCITY_LIMIT)
        # the binding limit is reached exactly: the layer slows no more than it must
        ratio = max(
            lin / (lim.margin * lim.tool_speed),
            ang / (lim.margin * lim.tool_angular_speed),
            np.max(np.abs(out)) / (lim.margin * lim.joint_velocity),
        )
        assert ratio == pytest.approx(1.0, rel=1e-9)


# ---------------------------------------------------------------------- workspace
def test_twist_stage_workspace_and_speed():
    lim = SafetyLimits(**BOX)
    layer = SafetyLayer(lim, DT, 6)
    at_face = np.array([0.5, 0.0, 0.0, 0, 0, 0])
    tw, flags = layer.limit_twist(np.array([0.1, 0.05, 0, 0, 0, 0]), at_face)
    assert flags == Fault.WORKSPACE_LIMIT and tw[0] == 0.0 and tw[1] == 0.05  # along the face: kept
    outside = np.array([0.6, 0.0, -0.7, 0, 0, 0])
    tw, flags = layer.limit_twist(np.array([0.1, 0.05, -0.1, 0, 0, 0.3]), outside)
    assert flags == Fault.WORKSPACE_LIMIT and np.array_equal(tw, [0.0, 0.05, 0.0, 0, 0, 0.3])
    tw, flags = layer.limit_twist(np.array([-0.1, 0.05, 0.1, 0, 0, 0]), outside)  # back in: allowed
    assert flags == Fault.NONE and np.array_equal(tw, [-0.1, 0.05, 0.1, 0, 0, 0])
    near = np.array([0.499, 0.0, 0.0, 0, 0, 0])
    tw, _ = layer.limit_twist(np.array([0.2, 0, 0, 0, 0, 0]), near)
    assert near[0] + tw[0] * DT <= 0.5 + 1e-15
    tw, flags = layer.limit_twist(np.array([1.0, 0, 0, 0, 0, 3.0]), POSE)
    assert flags == Fault.TOOL_SPEED_LIMIT
    assert tw[0] == pytest.approx(0.245) and tw[5] == pytest.approx(0.98)
    for bad in (np.array([np.nan, 0, 0, 0, 0, 0]), np.zeros(5), None, "fast"):
        tw, flags = layer.limit_twist(bad, POSE)
        assert flags == Fault.INVALID_INPUT and np.array_equal(tw, np.zeros(6))


def test_approaching_a_face_stops_at_it_and_keeps_the_motion_along_it():
    """The tick's path: twist stage, J⁻¹, joint stage; p += J_v q̇ dt for 500 ticks."""
    lim = SafetyLimits(**BOX)
    layer = SafetyLayer(lim, DT, 6)
    J = np.diag([0.5, 0.5, 0.5, 1.0, 1.0, 1.0])
    Jinv = np.linalg.inv(J)
    pose = np.array([0.2, -0.3, 0.0, 0, 0, 0])
    request = np.array([0.2, 0.05, 0.0, 0, 0, 0])  # outward in x, along the face in y
    prev = np.zeros(6)
    for _ in range(500):
        tw, _ = layer.limit_twist(request, pose)
        qd, flags, stop = step(layer, Jinv @ tw, J, pose)
        assert not stop
        assert within_limits(qd, prev, J, pose, lim, DT) == []  # acceleration included
        pose[:3] += (J @ qd)[:3] * DT
        assert pose[0] <= 0.5
        prev = qd
    assert pose[0] == pytest.approx(0.5, abs=1e-6)  # reached the face
    assert (J @ qd)[1] == pytest.approx(0.05, rel=1e-9)  # still sliding along it
    assert layer.limit_conflicts == 0


def test_joint_stage_alone_brakes_to_the_face_within_the_acceleration_limit():
    rng = np.random.default_rng(2)
    lim = SafetyLimits(min_manipulability=0.0, **BOX)
    for _ in range(10):
        J = rng.normal(size=(6, 6))
        layer = SafetyLayer(lim, DT, 6)
        pose = np.zeros(6)
        req = rng.normal(size=6)
        prev = np.zeros(6)
        for _ in range(500):
            qd, flags, _ = step(layer, req, J, pose)
            assert within_limits(qd, prev, J, pose, lim, DT) == []
            pose[:3] += (J @ qd)[:3] * DT
            assert np.all(pose[:3] <= 0.5) and np.all(pose[:3] >= -0.5)
            prev = qd
        assert layer.limit_conflicts == 0
        assert layer.interventions["WORKSPACE_LIMIT"] > 0
        assert np.max(np.abs(pose[:3])) == pytest.approx(0.5, abs=1e-3)  # it got there


def test_outside_the_box_the_outward_component_is_removed():
    lim = SafetyLimits(**BOX, **FREE)
    layer = SafetyLayer(lim, DT, 6)
    outside = np.array([0.55, 0.0, 0.0, 0, 0, 0])
    out, flags, _ = step(layer, [0.1, 0.05, 0, 0, 0, 0], I6, outside)
    assert flags & Fault.WORKSPACE_LIMIT and out[0] <= 0.0
    assert within_limits(out, np.zeros(6), I6, outside, lim, DT) == []
    out, flags, _ = step(layer, [-0.1, 0.05, 0, 0, 0, 0], I6, outside)  # inward is allowed
    assert flags == Fault.NONE and np.allclose(out, [-0.1, 0.05, 0, 0, 0, 0])


# ---------------------------------------------------------------------- singularity
def test_manipulability_guard():
    lim = SafetyLimits(**{**FREE, "min_manipulability": 0.01})
    layer = SafetyLayer(lim, DT, 6)
    singular = I6.copy()
    singular[4, 4] = 0.0
    out, flags, _ = step(layer, np.full(6, 0.1), singular)
    assert flags == Fault.SINGULARITY and np.array_equal(out, np.zeros(6))
    c = 0.0075 ** (1 / 6)  # w = 0.75 w_min: scale (0.0075 − 0.005) / 0.005 = 0.5
    out, flags, _ = step(layer, np.full(6, 0.1), c * I6)
    assert flags == Fault.SINGULARITY and np.allclose(out, 0.05, rtol=1e-9)
    out, flags, _ = step(layer, np.full(6, 0.1), I6)
    assert flags == Fault.NONE
    # n ≠ 6: the product of the singular values (√det(Jᵀ J) for n < 6, √det(J Jᵀ) for n > 6)
    for n in (3, 7):
        layer = SafetyLayer(lim, DT, n)
        J = np.zeros((6, n))
        J[:n, :n] = np.eye(min(n, 6))[:n, :n] if n <= 6 else 0
        if n == 7:
            J[:, :6] = I6
        _, flags, _ = step(layer, np.full(n, 0.1), J)
        assert flags == Fault.NONE
        J[0, :] = 0.0
        _, flags, _ = step(layer, np.full(n, 0.1), J)
        assert flags & Fault.SINGULARITY


# ---------------------------------------------------------------------- stops
@pytest.mark.parametrize(
    "hand, robot",
    [
        (np.array([100.0, 80.0, 0, 0, 0, 0]), Fault.NONE),  # 128 N > 120 N
        (np.array([0, 0, 0, 0, 0, 16.0]), Fault.NONE),  # 16 N·m > 15 N·m
        (NO_HAND, Fault.ROBOT_PROTECTIVE_STOP),
        (NO_HAND, Fault.ROBOT_EMERGENCY_STOP),
    ],
)
def test_contact_force_and_robot_stops_latch(hand, robot):
    layer = SafetyLayer(SafetyLimits(), DT, 6)
    run_to_steady(layer, np.full(6, 0.05), ticks=20)
    out, flags, stop = step(layer, np.full(6, 0.05), hand=hand, robot=robot)
    assert stop and flags & Fault.STOPPED and np.array_equal(out, np.zeros(6))
    assert flags & (Fault.CONTACT_FORCE_LIMIT if robot == Fault.NONE else robot)
    assert layer.stopped
    for _ in range(5):  # latched: good input does not move the robot again
        out, flags, stop = step(layer, np.full(6, 0.05))
        assert stop and flags == Fault.STOPPED and np.array_equal(out, np.zeros(6))
    layer.reset()
    out, flags, stop = step(layer, np.full(6, 0.05))
    assert not stop and not layer.stopped and np.allclose(out, 0.05)


def test_a_saturated_sensor_stops_as_a_contact_force():
    """The wrench pipeline holds its last good reading on a saturated channel (SENSOR_SATURATED): the
    wrench the layer sees is small, but the hand pushes at least the sensor's range, over the contact limit."""
    layer = SafetyLayer(SafetyLimits(), DT, 6)
    run_to_steady(layer, np.full(6, 0.05), ticks=20)
    held = np.array([9.8, 0, 0, 0, 0, 0])  # the last reading before the channel reached its 300 N
    out, flags, stop = step(layer, np.full(6, 0.05), hand=held, upstream=Fault.SENSOR_SATURATED)
    assert stop and flags == Fault.CONTACT_FORCE_LIMIT | Fault.STOPPED and not out.any() and layer.stopped
    effort = SafetyLayer(SafetyLimits(), DT, 6)
    u, f, stop = effort.limit_effort(np.array([3.0, 4.0]), np.array([0.1, 0.0]), held, Fault.SENSOR_SATURATED)
    assert stop and f == Fault.CONTACT_FORCE_LIMIT | Fault.STOPPED and not u.any() and effort.stopped


def test_hand_force_at_the_threshold_does_not_stop():
    layer = SafetyLayer(SafetyLimits(), DT, 6)
    _, flags, stop = step(layer, np.zeros(6), hand=np.array([120.0, 0, 0, 0, 0, 15.0]))
    assert not stop and flags == Fault.NONE


# ---------------------------------------------------------------------- bad ticks
def test_bad_ticks_decelerate_then_stop():
    lim = SafetyLimits(tool_speed=100.0, tool_angular_speed=100.0)
    layer = SafetyLayer(lim, DT, 6)
    v = np.full(6, 1.0)
    prev, _, _ = run_to_steady(layer, v)
    a_dt = lim.joint_acceleration * DT
    for k in range(1, lim.max_bad_ticks + 1):
        out, flags, stop = step(layer, v, upstream=Fault.DEADLINE_MISS)
        assert layer.bad_ticks == k
        if k < lim.max_bad_ticks:
            assert not stop and flags == Fault.DECELERATING and layer.decelerating
            assert np.max(np.abs(out - prev)) <= a_dt + 1e-12 and np.all(np.abs(out) <= np.abs(prev))
            assert not out.any() or parallel(out, v)
        else:
            assert stop and flags == Fault.STOPPED and layer.stopped
        prev = out
    # 1 rad/s at 0.98 · 8 rad/s² takes 16 ticks: at rest well before the stop
    assert layer.interventions["DECELERATING"] == lim.max_bad_ticks - 1
    assert layer.interventions["STOPPED"] == 1


@pytest.mark.parametrize("fault", list(BAD_TICK_FAULTS))
def test_every_bad_fault_decelerates(fault):
    layer = SafetyLayer(SafetyLimits(), DT, 6)
    run_to_steady(layer, np.full(6, 0.05), ticks=10)
    out, flags, stop = step(layer, np.full(6, 0.05), upstream=fault | Fault.PREDICTION_STALE)
    assert flags == Fault.DECELERATING and not stop and np.all(out < 0.05)


def test_a_fault_that_is_not_bad_does_not_decelerate():
    layer = SafetyLayer(SafetyLimits(), DT, 6)
    out, flags, stop = step(layer, np.full(6, 0.05), upstream=Fault.PREDICTION_FALLBACK | Fault.SATURATED)
    assert flags == Fault.NONE and np.allclose(out, 0.05)


@pytest.mark.parametrize(
    "which, value",
    [
        ("qd", np.array([np.nan, 0, 0, 0, 0, 0])),
        ("qd", np.zeros(5)),
        ("J", np.full((6, 6), np.inf)),
        ("J", np.eye(5)),
        ("pose", np.array([0, 0, np.nan, 0, 0, 0])),
        ("hand", None),
        ("upstream", "ok"),
    ],
)
def test_invalid_inputs_are_bad_ticks(which, value):
    layer = SafetyLayer(SafetyLimits(), DT, 6)
    run_to_steady(layer, np.full(6, 0.2), ticks=10)
    args = dict(qd=np.full(6, 0.2), J=I6, pose=POSE, hand_wrench=NO_HAND, upstream=Fault.NONE)
    args[{"hand": "hand_wrench"}.get(which, which)] = value
    out, flags, stop = layer.limit_joint_velocity(**args)
    assert flags == Fault.DECELERATING and not stop and layer.decelerating
    assert np.all(np.isfinite(out)) and np.all(out < 0.2)


def test_recovery_after_a_few_bad_ticks():
    lim = SafetyLimits(tool_speed=100.0, tool_angular_speed=100.0)
    layer = SafetyLayer(lim, DT, 6)
    v = np.full(6, 0.5)
    prev, _, _ = run_to_steady(layer, v)
    for _ in range(3):
        prev, flags, _ = step(layer, v, upstream=Fault.SENSOR_STALE)
    assert layer.bad_ticks == 3
    out, flags, stop = step(layer, v)
    assert layer.bad_ticks == 0 and not stop and not layer.decelerating
    assert flags == Fault.JOINT_ACCELERATION_LIMIT and np.all(out > prev)  # ramps back, bumpless
    out, _, _ = run_to_steady(layer, v, ticks=10)
    assert np.allclose(out, v)
    for _ in range(2 * lim.max_bad_ticks):  # bad ticks that never run max_bad_ticks in a row
        _, _, stop = step(layer, v, upstream=Fault.DEADLINE_MISS if _ % 5 else Fault.NONE)
        assert not stop


def test_an_internal_error_ramps_and_does_not_raise(monkeypatch):
    lim = SafetyLimits(tool_speed=100.0, tool_angular_speed=100.0)
    layer = SafetyLayer(lim, DT, 6)
    prev, _, _ = run_to_steady(layer, np.full(6, 1.0))

    def boom(_J):
        raise RuntimeError("kinematics exploded")

    monkeypatch.setattr(layer, "_manipulability", boom)
    out, flags, stop = step(layer, np.full(6, 1.0))
    assert flags == Fault.INTERNAL_ERROR | Fault.DECELERATING and not stop and layer.decelerating
    assert np.max(np.abs(out - prev)) <= lim.joint_acceleration * DT and np.all(out < prev)


def test_reset_ramps_from_the_given_velocity():
    lim = SafetyLimits(tool_speed=100.0, tool_angular_speed=100.0)
    layer = SafetyLayer(lim, DT, 6)
    layer.reset(np.full(6, 1.0))
    out, flags, _ = step(layer, np.zeros(6))
    assert flags == Fault.JOINT_ACCELERATION_LIMIT and np.allclose(out, 1.0 - 0.98 * 8.0 * DT)
    layer.reset(np.full(6, 10.0))  # faster than the limit: scaled into it
    assert np.allclose(layer.previous, lim.margin * math.pi / 2)
    with pytest.raises(ValueError, match="qd"):
        layer.reset(np.array([np.nan] * 6))


# ---------------------------------------------------------------------- after a stall (step 2)
def _stalled(prev, measured, history=()):
    """The command of the tick after a stall: a layer whose commands were ``history`` then ``prev``,
    told the arm measures ``measured``."""
    lim = SafetyLimits(tool_speed=100.0, tool_angular_speed=100.0, min_manipulability=0.0)
    layer = SafetyLayer(lim, DT, 6)
    layer.reset(history[0] if history else prev)
    for qd in [*history[1:], prev]:
        step(layer, qd)
    assert np.allclose(layer.previous, prev)
    out, flags, _ = layer.limit_joint_velocity(
        np.asarray(prev, dtype=float), I6, POSE, NO_HAND, Fault.DEADLINE_MISS, measured=np.asarray(measured)
    )
    return layer, out, flags


def test_after_a_stall_a_braked_arm_is_ramped_from_what_it_measures():
    # a Franka brakes to rest when its hold runs out: one acceleration step from the measured velocity
    prev = np.array([0.5, -0.3, 0.2, 0.0, 0.1, -0.05])
    measured = np.array([0.01, -0.02, 0.0, 0.0, 0.0, 0.0])
    layer, out, flags = _stalled(prev, measured)
    a_dt = 0.98 * 8.0 * DT
    assert layer.resumed_from_measured == 1 and flags == Fault.DECELERATING
    assert np.max(np.abs(out - measured)) <= a_dt + 1e-12
    # an arm that kept its command (tracking lag ≤ 2 m a dt): ramped from the command, as on any bad tick
    layer, out, _ = _stalled(prev, prev - 0.1 * np.sign(prev))
    assert layer.resumed_from_measured == 0 and np.allclose(out, prev * (1 - a_dt / 0.5))


def test_a_measured_velocity_the_arm_showed_a_few_ticks_late_is_no_brake():
    # ramping up 0.0784 rad/s a tick, a joint state 3 ticks late reads 0.235 rad/s below the command:
    # the arm kept its commands (issue 42: a stamp-0 flood delayed the joint states; a 0.071 rad/s step)
    a_dt = 0.98 * 8.0 * DT
    ramp = [np.full(6, a_dt * k) for k in range(1, 8)]
    layer, out, _ = _stalled(ramp[-1], ramp[-4], history=ramp[:-1])
    assert layer.resumed_from_measured == 0 and np.max(np.abs(out - ramp[-1])) <= a_dt + 1e-12


def test_no_measured_velocity_makes_a_joint_speed_up_or_reverse():
    """Whatever is measured after a stall (another publisher's joint states, a glitch), every joint's
    command lies between rest and its last command: a step away from rest never follows from a
    measured value (issue 42: 0.166 rad/s in one tick against the 0.064 rad/s limit)."""
    rng = np.random.default_rng(7)
    refused = resumed = 0
    for _ in range(400):
        prev = rng.uniform(-1.0, 1.0, 6) * rng.choice([0.05, 0.5, 1.5])
        measured = rng.uniform(-1.5, 1.5, 6) * rng.choice([0.01, 0.2, 1.0])
        layer, out, flags = _stalled(prev, measured)
        lo, hi = np.minimum(prev, 0.0), np.maximum(prev, 0.0)
        assert np.all(out >= lo - 1e-12) and np.all(out <= hi + 1e-12), (prev, measured, out)
        assert flags == Fault.DECELERATING
        refused += layer.refused_measured
        resumed += layer.resumed_from_measured
    assert refused > 100 and resumed > 20  # both branches taken
    # the case: the arm held 0.1 rad/s, the other publisher's velocity is -0.066: not used
    layer, out, _ = _stalled(np.full(6, 0.1), np.full(6, -0.166))
    assert layer.refused_measured == 1 and np.all(out >= 0.0) and np.all(out <= 0.1)


# ---------------------------------------------------------------------- the residual case
def test_jacobian_jump_brakes_at_the_acceleration_limit():
    """q̇⁻ was inside for the old J but J grew ×20: no command within the acceleration limit
    keeps the tool speed, so the layer brakes at that limit (step 6c), never beyond it."""
    lim = SafetyLimits(min_manipulability=0.0)
    layer = SafetyLayer(lim, DT, 6)
    J = 0.1 * I6
    prev, _, _ = run_to_steady(layer, np.full(6, 1.0), J)
    out, flags, _ = step(layer, np.full(6, 1.0), 20 * J)
    assert flags & Fault.TOOL_SPEED_LIMIT
    assert within_limits(out, prev, 20 * J, POSE, lim, DT) == []  # accepted as the residual case
    assert layer.limit_conflicts == 1 and parallel(out, prev) and np.all(out < prev)
    # one margin acceleration step toward rest (hand: m a dt = 0.98 · 8 · 0.008)
    assert np.max(np.abs(out - prev)) == pytest.approx(lim.margin * lim.joint_acceleration * DT, rel=1e-12)
    # a command that speeds up along the violated set is not braking: rejected
    assert within_limits(1.01 * prev, prev, 20 * J, POSE, lim, DT)
    # a milder jump (+5 %) while the request turns: the ramp toward the new target would
    # still be too fast, one braking step is not; the acceleration limit is kept (6b)
    layer.reset()
    prev, _, _ = run_to_steady(layer, np.array([5.0, 5.0, 5.0, 0, 0, 0]), J)
    assert np.linalg.norm(prev[:3]) * 0.1 == pytest.approx(lim.margin * lim.tool_speed)
    out, flags, _ = step(layer, np.full(6, 5.0), 1.05 * J)
    assert flags & Fault.TOOL_SPEED_LIMIT and layer.limit_conflicts == 0
    assert np.max(np.abs(out - prev)) <= lim.joint_acceleration * DT
    assert within_limits(out, prev, 1.05 * J, POSE, lim, DT) == []
    assert np.linalg.norm(out[:3]) * 0.105 == pytest.approx(lim.tool_speed, rel=1e-6)  # on the true limit


def test_a_jacobian_turning_under_a_command_along_a_face_is_corrected_not_stopped():
    """On the +x face, J turns a little every tick while the operator reverses along the face:
    the ramped command gains a tiny outward velocity, which step 6a removes."""
    lim = SafetyLimits(min_manipulability=0.0, **BOX)
    layer = SafetyLayer(lim, DT, 6)
    pose = np.array([0.5, 0.0, 0.0, 0, 0, 0])
    prev, seen, speeds = np.zeros(6), Fault.NONE, []
    for k in range(200):
        c, s = math.cos(0.002 * k), math.sin(0.002 * k)
        J = I6.copy()
        J[:2, :2] = [[c, -s], [s, c]]
        vy = 0.2 if (k // 20) % 2 == 0 else -0.2
        out, flags, stop = step(layer, np.linalg.solve(J, [0, vy, 0, 0, 0, 0]), J, pose)
        assert not stop and within_limits(out, prev, J, pose, lim, DT) == []
        seen |= flags
        speeds.append(abs((J @ out)[1]))
        prev = out
    assert seen & Fault.WORKSPACE_LIMIT and layer.limit_conflicts == 0
    assert min(speeds[20:]) < 0.07 and np.mean(speeds) > 0.1  # reversing, never stuck


def test_within_limits_finds_each_violation():
    lim = SafetyLimits(**BOX)
    zeros = np.zeros(6)
    assert within_limits(zeros, zeros, I6, POSE, lim, DT) == []
    [msg] = within_limits(np.array([2.0, 0, 0, 0, 0, 0]), None, 0.01 * I6, POSE, lim, DT)
    assert msg.startswith("joint_velocity")
    [msg] = within_limits(np.array([0.3, 0, 0, 0, 0, 0]), None, I6, POSE, lim, DT)
    assert msg.startswith("tool_speed")
    [msg] = within_limits(np.array([0, 0, 0, 1.1, 0, 0]), None, I6, POSE, lim, DT)
    assert msg.startswith("tool_angular_speed")
    [msg] = within_limits(np.array([0.2, 0, 0, 0, 0, 0]), None, I6, np.array([0.499, 0, 0, 0, 0, 0]), lim, DT)
    assert msg.startswith("workspace")
    [msg] = within_limits(np.array([0.1, 0, 0, 0, 0, 0]), zeros, I6, POSE, lim, DT)
    assert msg.startswith("joint_acceleration")
    # a sudden stop from a feasible command is not the residual case
    fast = np.array([0.2, 0, 0, 0, 0, 0])
    [msg] = within_limits(zeros, fast, I6, POSE, lim, DT)
    assert msg.startswith("joint_acceleration")
    assert within_limits(np.array([np.nan] * 6), zeros, I6, POSE, lim, DT)[0].startswith("qd")


# ---------------------------------------------------------------------- anything at all
def _garbage(rng, shape, scale):
    """A valid array most of the time, otherwise one of the ways an input goes wrong."""
    r = rng.random()
    if r < 0.9:
        return rng.normal(size=shape) * scale
    r = 0.75 + (r - 0.9) * 2.5  # the rest spread over the bad kinds below
    a = rng.normal(size=shape) * scale
    if r < 0.80:
        a.flat[rng.integers(a.size)] = np.nan
    elif r < 0.84:
        a.flat[rng.integers(a.size)] = rng.choice([np.inf, -np.inf])
    elif r < 0.88:
        a.flat[rng.integers(a.size)] = rng.choice([1e300, -1e300, 1e200])
    elif r < 0.91:
        return np.zeros(tuple(s + 1 for s in shape))
    elif r < 0.93:
        return None
    elif r < 0.95:
        return "0.1"
    elif r < 0.97:
        return a.tolist()
    else:
        return a.astype(complex)
    return a


def test_randomised_inputs_never_raise_and_never_leave_the_limits():
    rng = np.random.default_rng(12345)
    layers = [
        SafetyLayer(SafetyLimits(**BOX), DT, 6),
        SafetyLayer(SafetyLimits(), DT, 6),
        SafetyLayer(SafetyLimits(joint_velocity=(1.0, 2.0, 0.5, 3.0, 3.0, 3.0, 1.0), **BOX), DT, 7),
    ]
    words = [Fault.NONE] * 12 + [
        Fault.DEADLINE_MISS,
        Fault.PREDICTION_STALE,
        Fault.SENSOR_STALE,
        Fault.WRENCH_SPIKE | Fault.SATURATED,
        -1,
        None,
        "x",
        2**70,
        1.5,
    ]
    checked = moved = conflicts = 0
    kinds = Fault.NONE
    for i in range(5000):
        layer = layers[i % 3]
        n = layer.n_joints
        if rng.random() < 0.02:
            layer.reset(rng.normal(size=n) * rng.choice([0.01, 1.0, 100.0]))
        lim = layer.limits
        if rng.random() < 0.2:  # singular, or close
            Jc = rng.normal(size=(6, n))
            Jc[rng.integers(6)] *= rng.choice([0.0, 1e-3])
            J = Jc
        else:
            J = _garbage(rng, (6, n), rng.choice([0.01, 0.3, 1.0, 30.0]))
        qd = _garbage(rng, (n,), rng.choice([1e-3, 0.1, 1.0, 1e3]))
        pose = _garbage(rng, (6,), rng.choice([0.1, 0.3, 1.0]))
        hand = _garbage(rng, (6,), 200.0 if rng.random() < 0.01 else rng.choice([0.1, 1.0, 3.0]))
        upstream = words[rng.integers(len(words))]
        robot = Fault.ROBOT_PROTECTIVE_STOP if rng.random() < 0.003 else Fault.NONE
        prev, c0 = layer.previous, layer.limit_conflicts
        out, flags, stop = layer.limit_joint_velocity(qd, J, pose, hand, upstream, robot)
        conflicts += layer.limit_conflicts - c0
        assert isinstance(out, np.ndarray) and out.shape == (n,) and out.dtype == float
        assert np.all(np.isfinite(out)) and isinstance(flags, Fault) and isinstance(stop, bool)
        if stop:
            assert np.array_equal(out, np.zeros(n)) and flags & Fault.STOPPED
            assert within_limits(out, None, J, pose, lim, DT) == []
            if rng.random() < 0.5:
                layer.reset()
            continue
        assert within_limits(out, prev, J, pose, lim, DT) == [], (i, flags)
        checked += 1
        moved += bool(out.any())
        kinds |= flags
        tw, tf = layer.limit_twist(_garbage(rng, (6,), 1.0), pose)
        assert tw.shape == (6,) and np.all(np.isfinite(tw))
    assert checked > 3000 and moved > 1000, (checked, moved)  # the check was not vacuous
    for f in (
        Fault.JOINT_VELOCITY_LIMIT,
        Fault.JOINT_ACCELERATION_LIMIT,
        Fault.TOOL_SPEED_LIMIT,
        Fault.WORKSPACE_LIMIT,
        Fault.SINGULARITY,
        Fault.DECELERATING,
    ):
        assert kinds & f, f
    assert conflicts > 0  # the residual case did occur (J and the pose jump every call)


# ---------------------------------------------------------------------- parameters
@pytest.mark.parametrize(
    "field, value",
    [
        ("joint_velocity", 0.0),
        ("joint_velocity", (1.0, -1.0)),
        ("joint_velocity", "fast"),
        ("joint_velocity", [[1.0]]),
        ("joint_acceleration", float("nan")),
        ("tool_speed", -0.1),
        ("tool_angular_speed", "x"),
        ("contact_force", 0.0),
        ("contact_torque", float("inf")),
        ("min_manipulability", -1.0),
        ("max_bad_ticks", 0),
        ("max_bad_ticks", 2.5),
        ("margin", 1.5),
        ("margin", 0.0),
        ("workspace_lower", (0.0, 0.0, 0.0)),
        ("workspace_upper", (1.0, 1.0)),
    ],
)
def test_limits_validation_names_the_field(field, value):
    kwargs = {field: value}
    if field == "workspace_upper":
        kwargs["workspace_lower"] = (0.0, 0.0, 0.0)
    if field == "workspace_lower":
        kwargs["workspace_upper"] = (1.0, 1.0, -1.0)  # upper below lower on z
        with pytest.raises(ValueError, match="SafetyLimits.workspace_upper"):
            SafetyLimits(**kwargs)
        with pytest.raises(ValueError, match="SafetyLimits.workspace_upper"):
            SafetyLimits(workspace_lower=value)
        return
    with pytest.raises(ValueError, match=f"SafetyLimits.{field}"):
        SafetyLimits(**kwargs)


def test_layer_parameters():
    with pytest.raises(ValueError, match="SafetyLayer.dt"):
        SafetyLayer(SafetyLimits(), 0.0, 6)
    with pytest.raises(ValueError, match="SafetyLayer.n_joints"):
        SafetyLayer(SafetyLimits(), DT, 0)


def test_describe_mentions_every_limit():
    text = SafetyLimits(**BOX).describe()
    for part in (
        "joint speed ≤ 90 °/s",
        "joint acceleration ≤ 458 °/s²",
        "tool speed ≤ 0.25 m/s",
        "tool rotation ≤ 57 °/s",
        "x ∈ [-0.500, 0.500] m",
        "z ∈ [-0.500, 0.500] m",
        "120 N",
        "15 N·m",
        "manipulability 0.01",
        "25 bad ticks",
        "98%",
    ):
        assert part in text, part
    assert "no box" in SafetyLimits().describe()
    assert "joints 1…6" in SafetyLimits(joint_velocity=(1.0,) * 6).describe()


def test_a_jacobian_whose_manipulability_overflows_is_treated_as_singular():
    layer = SafetyLayer(SafetyLimits(), DT, 7)
    J = np.zeros((6, 7))
    J[:, :6] = 1e200 * np.random.default_rng(0).normal(size=(6, 6))  # J Jᵀ overflows: det is NaN
    with np.errstate(all="ignore"):
        assert np.isnan(np.linalg.det(J @ J.T))
    out, flags, _ = step(layer, np.full(7, 1e-250), J)
    assert np.all(np.isfinite(out)) and flags & Fault.SINGULARITY and not out.any()


def test_effort_stage_brakes_above_the_tool_speed_and_latches_on_contact_force():
    layer = SafetyLayer(SafetyLimits(tool_speed=0.25, contact_force=120.0), 0.008, 6)
    calm = np.array([5.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    # below the speed limit the effort passes untouched
    u, f, stop = layer.limit_effort(np.array([3.0, 4.0]), np.array([0.1, 0.0]), calm, Fault.NONE)
    np.testing.assert_array_equal(u, [3.0, 4.0])
    assert f == Fault.NONE and not stop
    # above it, the effort may only brake: forward and sideways parts removed (hand-computed: v along x). The
    # sideways part was kept until the review of 3063e1e: 50 N across v took a 10 kg tool from 0.30 to 0.50 m/s
    u, f, stop = layer.limit_effort(np.array([3.0, 4.0]), np.array([0.3, 0.0]), calm, Fault.NONE)
    np.testing.assert_array_equal(u, [0.0, 0.0])
    assert f == Fault.TOOL_SPEED_LIMIT and not stop
    u, f, _ = layer.limit_effort(np.array([-3.0, 4.0]), np.array([0.3, 0.0]), calm, Fault.NONE)
    np.testing.assert_allclose(u, [-3.0, 0.0], rtol=1e-15)
    assert f == Fault.TOOL_SPEED_LIMIT
    # a braking effort above the limit is kept as it is, on any direction of v (its sideways part only rounding)
    u, f, _ = layer.limit_effort(np.array([-3.0, 0.0]), np.array([0.3, 0.0]), calm, Fault.NONE)
    np.testing.assert_array_equal(u, [-3.0, 0.0])
    assert f == Fault.NONE
    v = np.array([0.21, -0.17])
    u, f, _ = layer.limit_effort(-7.3 * v, v, calm, Fault.NONE)
    np.testing.assert_array_equal(u, -7.3 * v)
    assert f == Fault.NONE
    # a hand force over the threshold latches the stop, for good
    hard = np.array([100.0, 80.0, 0.0, 0.0, 0.0, 0.0])  # 128 N
    u, f, stop = layer.limit_effort(np.array([3.0, 4.0]), np.array([0.1, 0.0]), hard, Fault.NONE)
    assert stop and f & Fault.CONTACT_FORCE_LIMIT and f & Fault.STOPPED
    np.testing.assert_array_equal(u, [0.0, 0.0])
    u, f, stop = layer.limit_effort(np.array([3.0, 4.0]), np.array([0.1, 0.0]), calm, Fault.NONE)
    assert stop and f & Fault.STOPPED and not u.any()


@pytest.mark.parametrize("upstream", [Fault.NONFINITE_WRENCH, Fault.INVALID_INPUT, Fault.INTERNAL_ERROR])
def test_the_effort_stage_limits_the_tool_speed_after_a_wrench_fault_too(upstream):
    """A wrench fault zeroes the hand's force (the pipeline), not the controller's effort: above the tool speed the
    forward and sideways parts are still removed (hand-computed as above), and a zero effort passes unflagged."""
    layer = SafetyLayer(SafetyLimits(tool_speed=0.25), 0.008, 6)
    u, f, stop = layer.limit_effort(np.array([3.0, 4.0]), np.array([0.3, 0.0]), np.zeros(6), upstream)
    np.testing.assert_array_equal(u, [0.0, 0.0])
    assert f == Fault.TOOL_SPEED_LIMIT and not stop
    u, f, stop = layer.limit_effort(np.zeros(2), np.array([0.3, 0.0]), np.zeros(6), upstream)
    assert not u.any() and f == Fault.NONE and not stop


def test_the_batch_effort_stage_passes_u_r_where_each_layer_does():
    """SafetyLayerBatch.limit_effort row for row against each SafetyLayer.limit_effort on a tick
    without an upstream fault: where the batch says clean the layer gives u_r back unchanged
    (bit for bit) with no flag; where the layer changes it or flags anything (tool speed,
    contact force, a non-finite u_r, v or hand force) the batch is not clean. Rows near both limits and
    exactly at the contact force (where the layer's np.dot may round either way)."""
    from coassist.runtime.safety import SafetyLayerBatch

    rng = np.random.default_rng(5)
    n = 400
    limits = [SafetyLimits(tool_speed=0.25), SafetyLimits(tool_speed=1.0, contact_force=40.0)]
    layers = [SafetyLayer(limits[i % 2], DT, 6) for i in range(n)]
    batch = SafetyLayerBatch(layers)
    u = rng.normal(0.0, 20.0, (n, 2))
    u[::37] = np.nan
    v = rng.normal(0.0, 0.3, (n, 2))
    hand = np.zeros((n, 3))
    hand[:, :2] = rng.normal(0.0, 25.0, (n, 2))
    at_limit = np.arange(n)[5::41]  # a hand force exactly at the contact limit
    for i in at_limit:
        hand[i] = [layers[i].limits.contact_force, 0.0, 0.0]
    v[3::53] = np.nan  # a velocity or a hand force that is not finite: the layer's to flag
    hand[11::59, 1] = np.nan
    clean = batch.limit_effort(np.arange(n), u, v, hand)
    assert not clean[3::53].any() and not clean[11::59].any()
    seen = Fault.NONE
    for i in range(n):
        w = np.array([*hand[i], 0.0, 0.0, 0.0])
        effort, flags, stop = layers[i].limit_effort(u[i].copy(), v[i], w, Fault.NONE)
        seen |= flags
        passed = flags == Fault.NONE and not stop and effort.tolist() == u[i].tolist()
        if clean[i]:
            assert passed, (i, flags)
        if not passed:
            assert not clean[i], (i, flags)
    assert seen & Fault.TOOL_SPEED_LIMIT and seen & Fault.STOPPED and seen & Fault.NONFINITE_EFFORT
    assert 100 < int(clean.sum()) < n - 50  # both kinds of row, many of each
    assert not clean[at_limit].any()
    stopped = [layer for layer in layers if layer.stopped]  # the contact force latched STOPPED
    assert stopped and not any(SafetyLayerBatch.accepts(layer) for layer in stopped)
    assert SafetyLayerBatch.accepts(SafetyLayer(limits[0], DT, 6))


def test_the_effort_stage_alone_and_batched_agree_on_which_efforts_pass_above_the_tool_speed():
    """SafetyLayerBatch.limit_effort says which rows the layer leaves alone (the array path keeps those): a sideways
    effort above the tool speed is the layer's to change, as a forward one is; braking straight against v is not."""
    from coassist.runtime.safety import SafetyLayerBatch

    # the last two: a velocity whose square overflows (its speed read inf, and the sideways 40 N passed unflagged: a
    # review, 2026-12-07) and one at the plausibility bound, both INVALID_INPUT with zero effort
    layers = [SafetyLayer(SafetyLimits(tool_speed=0.25), 0.008, 6) for _ in range(7)]
    v = np.array([[0.3, 0.0], [0.3, 0.0], [0.3, 0.0], [0.21, -0.17], [0.1, 0.0], [1e155, 0.0], [0.0, -1e3]])
    u = np.array([[0.0, 50.0], [3.0, 0.0], [-3.0, 0.0], -7.3 * v[3], [0.0, 50.0], [0.0, 40.0], [0.0, 40.0]])
    hand = np.zeros((7, 3))
    clean = SafetyLayerBatch(layers).limit_effort(np.arange(7), u, v, hand)
    out = [layer.limit_effort(u[i], v[i], np.zeros(6), Fault.NONE) for i, layer in enumerate(layers)]
    alone = [f == Fault.NONE for _, f, _ in out]
    assert clean.tolist() == alone == [False, False, True, True, True, False, False]
    for effort, f, _ in out[5:]:
        assert f == Fault.INVALID_INPUT and not effort.any()
