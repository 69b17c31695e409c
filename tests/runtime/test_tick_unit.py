"""ControlTick and run_loop on fake kinematics and scripted worlds (no MuJoCo, no pinocchio).

Each check has a reference computed here, independently of the tick: the admittance
with scipy's exact ZOH (``cont2discrete``), the twist law of the tick's docstring with
scipy's rotations, q̇ = J⁻¹ ẋ by a linear solve, u_r = K (x_ref(k+1) − x) by hand, the
dwell rule's end tick by counting, and the safety layer's ramp toward rest.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import cont2discrete
from scipy.spatial.transform import Rotation

from coassist.control.controllers import ImpedanceControl, ManualGuidance
from coassist.errors import CoassistError
from coassist.interfaces import Fault, TrialContext
from coassist.model.impedance import ImpedanceModel
from coassist.runtime.loop import TargetDwell, TargetDwellBatch, run_loop
from coassist.runtime.safety import SafetyLayer
from coassist.runtime.safety_limits import SafetyLimits
from coassist.runtime.tick import ControlTick, Plan, TickConfig, human_reference
from coassist.runtime.wrench import WrenchConfig, WrenchPipeline

from .fakes import DT, FakeArmWorld, LinearKinematics, NominalStage, ScriptedEffortWorld, well_conditioned_jacobian

M = np.array([4.0, 6.0])  # [kg] x, y
D = np.array([30.0, 20.0])  # [N·s/m]
H = 3
N_REF = 200
POSE0 = np.array([0.4, -0.1, 0.3, 0.2, -0.1, 0.3])  # [m, rad] a tilted tool
OFFSET = np.array([0.002, -0.001, 0.005, 0.02, -0.01, 0.015])  # [m, rad]
# the raw reading is the hand wrench: sensor frame = base frame, no bias, no payload, no filter, no deadband
CLEAN = WrenchConfig(cutoff_hz=None, deadband_force=0.0, deadband_torque=0.0)
WIDE = SafetyLimits(
    joint_velocity=100.0, joint_acceleration=1e4, tool_speed=100.0, tool_angular_speed=100.0, min_manipulability=0.0
)  # nothing binds: the tick's own law is seen


def _context(ref: np.ndarray) -> TrialContext:
    return TrialContext(
        dt=DT,
        horizon=H,
        start=ref[0, :2].copy(),
        target=ref[-1, :2].copy(),
        reference=ref,
        task="test",
        user="fake",
        object="none",
    )


def _reference(start_xy, velocity=(0.0, 0.0)) -> np.ndarray:
    t = np.arange(N_REF)[:, None] * DT
    ref = np.zeros((N_REF, 4))
    ref[:, :2] = np.asarray(start_xy) + t * np.asarray(velocity)
    ref[:, 2:] = velocity
    return ref


def _arm_tick(kin: LinearKinematics, limits: SafetyLimits, config: TickConfig | None = None) -> ControlTick:
    model = ImpedanceModel(M, D, 0.0, DT)
    tick = ControlTick(
        ManualGuidance(model),
        NominalStage(H),
        WrenchPipeline(CLEAN, DT),
        SafetyLayer(limits, DT, 6),
        command_space="joint_velocity",
        kinematics=kin,
        config=config,
    )
    ref = _reference(POSE0[:2])
    tick.reset(Plan(ref, POSE0), _context(ref))
    return tick


def _zoh_reference() -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3.5 for M a + D v = f (K = 0), z = [Δx; v], exactly (matrix exponential), by scipy."""
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [np.zeros((2, 2)), -np.diag(D / M)]])
    B = np.vstack([np.zeros((2, 2)), np.diag(1.0 / M)])
    Ad, Bd, *_ = cont2discrete((A, B, np.eye(4), np.zeros((4, 2))), DT, method="zoh")
    return Ad, Bd


# ---------------------------------------------------------------------------- the arm tick


def test_joint_velocity_is_J_inverse_of_the_twist_from_the_exact_admittance():
    J = well_conditioned_jacobian()
    # the arm starts off the plan's start pose (2 mm, 5 mm, 0.02 rad), so the pull and hold terms act too
    kin = LinearKinematics(J, POSE0 + OFFSET)
    hand = np.array([5.0, -3.0, 0.0, 0.0, 0.0, 0.0])  # [N] a constant push in the x-y plane
    world = FakeArmWorld(kin, lambda k: hand)
    cfg = TickConfig()
    tick = _arm_tick(kin, WIDE, cfg)
    Ad, Bd = _zoh_reference()
    za = np.zeros(4)
    R_start = Rotation.from_rotvec(POSE0[3:])
    for k in range(12):
        state = world.read()
        out = tick.step(k, state)
        world.apply(out.command)
        # reference: the admittance driven by the hand alone (MG: u_r = 0), then the twist law
        za = Ad @ za + Bd @ hand[:2]
        p = state.tool_pose
        tw = np.empty(6)
        tw[0:3] = cfg.hold_gain * (POSE0[:3] - p[:3])
        tw[0:2] = za[2:] + cfg.position_gain * (POSE0[:2] + za[:2] - p[:2])
        tw[3:6] = cfg.hold_rotation_gain * (R_start * Rotation.from_rotvec(p[3:]).inv()).as_rotvec()
        qd = np.linalg.solve(J, tw)
        assert out.fault == Fault.NONE, f"tick {k}: {out.fault!r}"
        np.testing.assert_array_equal(out.u_r, 0.0)
        np.testing.assert_array_equal(out.wrench, hand[:2])
        # cond(J) = 3.3, ‖A_d‖ ≤ 1 and 12 ticks: rounding stays near 1e2·cond·eps ≈ 1e-13 of |q̇| ≈ 0.1;
        # 1e-10 leaves room for any expm / LAPACK build
        np.testing.assert_allclose(out.command.qd, qd, rtol=0, atol=1e-10)
        np.testing.assert_allclose(out.command.twist, tw, rtol=0, atol=1e-10)
        assert not out.command.stop
    # the push moved the tool: the check above was not on a resting arm
    assert np.linalg.norm(world.commands[-1].qd) > 0.05
    # z is held: J q̇ = ẋ exactly here, so its error shrinks by (1 − k_hold dt) a tick, by hand
    z_end = world.kin.pose(world.q)[2]
    np.testing.assert_allclose(z_end - POSE0[2], OFFSET[2] * (1.0 - cfg.hold_gain * DT) ** 12, rtol=1e-9)


def test_a_nan_wrench_is_flagged_and_the_command_ramps_to_rest_within_the_acceleration_limit():
    J = well_conditioned_jacobian()
    kin = LinearKinematics(J, POSE0)
    push = np.array([40.0, 25.0, 0.0, 0.0, 0.0, 0.0])
    bad = range(40, 43)
    world = FakeArmWorld(kin, lambda k: np.full(6, np.nan) if k in bad else push)
    limits = SafetyLimits(tool_speed=2.0, min_manipulability=0.0)  # the UR's 8 rad/s², π/2 rad/s
    tick = _arm_tick(kin, limits)
    step_max = limits.margin * limits.joint_acceleration * DT  # the ramp's step [rad/s]
    faults, cmds = [], [np.zeros(6)]
    for k in range(50):
        out = tick.step(k, world.read())
        world.apply(out.command)
        faults.append(out.fault)
        cmds.append(np.array(out.command.qd))
        assert np.isfinite(out.command.qd).all() and np.isfinite(out.wrench).all()
    qd = np.array(cmds)  # qd[k + 1] is tick k's command
    assert np.max(np.abs(qd[40])) > 4 * step_max, "the arm must be moving when the NaN arrives"
    # no tick, good or bad, moves any joint by more than the true limit a·dt
    assert np.max(np.abs(np.diff(qd, axis=0))) <= limits.joint_acceleration * DT + 1e-12
    for k in bad:
        assert faults[k] & Fault.NONFINITE_WRENCH and faults[k] & Fault.DECELERATING, f"tick {k}: {faults[k]!r}"
        assert not faults[k] & Fault.STOPPED
        prev = qd[k]
        # the ramp toward rest: along the previous command, its largest joint one margin·a·dt smaller
        np.testing.assert_allclose(qd[k + 1], prev * (1.0 - step_max / np.max(np.abs(prev))), rtol=0, atol=1e-12)
    for k in (*range(40), *range(44, 50)):
        assert not faults[k] & (Fault.NONFINITE_WRENCH | Fault.DECELERATING), f"tick {k}: {faults[k]!r}"


# ---------------------------------------------------------------------------- the effort tick


def test_an_effort_world_gets_the_controllers_u_r_unchanged_within_the_limits():
    K = np.diag([120.0, 80.0])  # [N/m]
    model = ImpedanceModel(M, D, 0.0, DT)
    start = np.array([0.1, 0.2])
    ref = _reference(start, velocity=(0.05, -0.02))
    # the tool lags the plan by a few mm, at the plan's speed (0.054 m/s: below the 0.25 m/s tool speed)
    poses = ref[:20, :2] - np.array([0.003, -0.002])
    world = ScriptedEffortWorld(poses)
    tick = ControlTick(
        ImpedanceControl(model, K, effort_limit=50.0),
        NominalStage(H),
        WrenchPipeline(CLEAN, DT),
        SafetyLayer(SafetyLimits(), DT, 6),
        command_space="effort",
    )
    tick.reset(Plan(ref, np.array([*start, 0.0, 0.0, 0.0, 0.0])), _context(ref))
    for k in range(15):
        out = tick.step(k, world.read())
        world.apply(out.command)
        # eq. 5.4 by hand: the spring toward the plan's next row, on the measured position
        u = K @ (ref[k + 1, :2] - poses[k])
        np.testing.assert_allclose(out.u_r, u, rtol=1e-12, atol=1e-12)  # a 2x2 product of O(0.1) numbers
        np.testing.assert_array_equal(world.efforts[-1], out.u_r)  # unchanged by the safety layer
        assert out.fault == Fault.NONE and out.command.qd is None and not out.command.stop
    assert np.all(np.abs(np.array(world.efforts)) > 0.1)  # a real effort was passed, not zeros


# ---------------------------------------------------------------------------- run_loop


def _effort_tick(ref: np.ndarray) -> ControlTick:
    tick = ControlTick(
        ManualGuidance(ImpedanceModel(M, D, 0.0, DT)),
        NominalStage(H),
        WrenchPipeline(CLEAN, DT),
        SafetyLayer(SafetyLimits(), DT, 6),
        command_space="effort",
    )
    tick.reset(Plan(ref, np.array([*ref[0, :2], 0.0, 0.0, 0.0, 0.0])), _context(ref))
    return tick


@pytest.mark.parametrize(
    ("inside", "after_tick", "dwell", "last_tick"),
    [
        # inside from tick 3, but the rule may count only from tick 6: ticks 6, 7, 8, 9
        (lambda k: k >= 3, 6, 4, 9),
        # inside from tick 8, past after_tick: ticks 8, 9, 10, 11
        (lambda k: k >= 8, 6, 4, 11),
        # inside 6-7, out at 8 (the count restarts), inside from 9: ticks 9, 10, 11, 12
        (lambda k: k >= 6 and k != 8, 2, 4, 12),
    ],
)
def test_the_run_ends_at_the_hand_counted_dwell_tick(inside, after_tick, dwell, last_tick):
    target = np.array([0.3, 0.1])
    radius = 0.01
    far = target + np.array([0.0, 2 * radius])
    poses = np.array([target if inside(k) else far for k in range(40)])
    world = ScriptedEffortWorld(poses)
    ref = _reference(target)
    log = run_loop(world, _effort_tick(ref), 30, TargetDwell(target, radius, dwell, after_tick))
    assert log.ended == "target"
    assert log.n == last_tick + 1 == len(world.efforts)
    np.testing.assert_array_equal(log.pose, poses[: log.n])


def test_the_run_ends_at_the_time_limit_when_the_target_is_never_held():
    target = np.array([0.3, 0.1])
    poses = np.tile(target + 0.05, (40, 1))
    world = ScriptedEffortWorld(poses)
    log = run_loop(world, _effort_tick(_reference(target)), 17, TargetDwell(target, 0.01, 3, 0))
    assert log.ended == "time_limit" and log.n == 17 == len(world.efforts)
    assert log.compute.shape == (17,) and np.all(log.compute >= 0.0)


class _FailingStage:
    """An intent stage that raises where it should answer (a predictor's answer of the wrong type, a bug)."""

    nominal = False
    horizon = H
    batcher = None

    def reset(self, context: object) -> None:
        pass

    def update(self, k: int, row: tuple[float, ...], nominal: np.ndarray):
        raise ValueError("setting an array element with a sequence")


def _impedance_tick(ref: np.ndarray, stage) -> ControlTick:
    tick = ControlTick(
        ImpedanceControl(ImpedanceModel(M, D, 0.0, DT), 200.0 * np.eye(2), effort_limit=50.0),
        stage,
        WrenchPipeline(CLEAN, DT),
        SafetyLayer(SafetyLimits(), DT, 6),
        command_space="effort",
    )
    tick.reset(Plan(ref, np.array([*ref[0, :2], 0.0, 0.0, 0.0, 0.0])), _context(ref))
    return tick


def test_an_intent_stage_that_raises_falls_back_to_the_plan_and_the_run_goes_on():
    """The loop's intent stage raising is a failing predictor: the plan's rows, PREDICTION_FALLBACK on every tick,
    the run to its end (before, the exception left run_loop with the world never stopped). The commands are those of
    the nominal stage's run, bit for bit (the fallback is the plan's rows), in run_loop and in lockstep."""
    from coassist.runtime.batched_loops import Loop, run_loops

    ref = _reference((0.1, 0.2), velocity=(0.05, 0.0))
    poses = ref[:40, :2] + 0.01
    world, nominal = ScriptedEffortWorld(poses), ScriptedEffortWorld(poses)
    log = run_loop(world, _impedance_tick(ref, _FailingStage()), 30)
    want = run_loop(nominal, _impedance_tick(ref, NominalStage(H)), 30)
    assert log.ended == "time_limit" and log.n == 30 == len(world.efforts)
    assert all(int(f) & Fault.PREDICTION_FALLBACK for f in log.fault)
    np.testing.assert_array_equal(np.array(world.efforts), np.array(nominal.efforts))
    assert np.abs(np.array(world.efforts)).max() > 0.1  # the spring pulled: a real effort was compared
    worlds = [ScriptedEffortWorld(poses), ScriptedEffortWorld(poses)]
    logs = run_loops([Loop(w, _impedance_tick(ref, _FailingStage()), 30) for w in worlds])
    for w, lg in zip(worlds, logs):
        assert lg.ended == "time_limit" and all(int(f) & Fault.PREDICTION_FALLBACK for f in lg.fault)
        np.testing.assert_array_equal(np.array(w.efforts), np.array(nominal.efforts))
    np.testing.assert_array_equal(want.effort_r, log.effort_r)


def test_the_batch_dwell_rule_decides_as_each_rule():
    """TargetDwellBatch row for row against each TargetDwell: targets, radii, dwell and start ticks
    of their own, tools wandering in and out of the ball, a run without a rule, runs leaving."""
    rng = np.random.default_rng(3)
    n = 12
    targets = rng.normal(0.0, 0.1, (n, 2))
    rules = [TargetDwell(targets[i], 0.01 + 0.002 * i, 2 + i % 5, i % 7) for i in range(n)]
    twins = [TargetDwell(targets[i], 0.01 + 0.002 * i, 2 + i % 5, i % 7) for i in range(n)]
    twins[4] = rules[4] = None  # no rule: never ends on the target
    batch = TargetDwellBatch(twins)
    rows = np.arange(n)
    ended = 0
    for k in range(200):
        if k == 50:
            rows = rows[rows % 3 != 0]  # some runs left the batch
        near = rng.random(rows.size) < 0.8
        pose = targets[rows] + np.where(near[:, None], 0.5, 3.0) * rng.normal(0.0, 0.01, (rows.size, 2))
        done = batch(k, rows, pose)
        for j, i in enumerate(rows.tolist()):
            want = rules[i](k, pose[j]) if rules[i] is not None else False
            assert bool(done[j]) == want, (k, i)
            assert rules[i] is None or batch.inside[i] == rules[i].inside
        ended += int(done.sum())
        rows = rows[~done]
    assert ended >= 5 and 4 in rows.tolist()
    assert not TargetDwellBatch.accepts(lambda k, pose: False) and TargetDwellBatch.accepts(None)


@pytest.mark.parametrize("m", [1, 2, 5])
def test_human_reference_is_the_docstrings_rows_for_one_tick_and_a_batch(m):
    """ref_h[i] = [p̂(k+1+i) − x0, (p̂(k+1+i) − p̂(k+i))/dt] (the first velocity the second's, 0 for
    one row), against a hand-written loop; a batch's rows equal each tick's own call bit for bit
    (the tick and the array path build ref_h with this one function); the other DOFs' columns untouched."""
    rng = np.random.default_rng(m)
    dt = 0.008
    positions = rng.normal(0.0, 0.2, (4, m, 2))
    x0 = rng.normal(0.0, 0.2, (4, 2))
    d = 3  # x, y and one more DOF: columns [x, y, z, vx, vy, vz]
    batch = np.full((4, m + 2, 2 * d), 7.0)
    human_reference(positions, x0, 1.0 / dt, batch)
    for b in range(4):
        one = np.full((m + 2, 2 * d), 7.0)
        human_reference(positions[b], x0[b], 1.0 / dt, one)
        assert one.tolist() == batch[b].tolist()
        want = np.full((m + 2, 2 * d), 7.0)
        for i in range(m):
            want[i, :2] = positions[b, i] - x0[b]
            if m >= 2:
                want[i, d : d + 2] = (positions[b, max(i, 1)] - positions[b, max(i, 1) - 1]) / dt
            else:
                want[i, d : d + 2] = 0.0
        np.testing.assert_allclose(one, want, rtol=1e-12, atol=1e-12)


class _LinkError(CoassistError, ConnectionError):
    """As the robot worlds' link errors (RobotLinkError, FrankaLinkError): a CoassistError and a ConnectionError."""


@pytest.mark.parametrize("where", ["read", "apply"])
def test_a_lost_link_ends_the_run_and_stops_the_arm(where):
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    fail = {"fail_read_at": 7} if where == "read" else {"fail_apply_at": 7}
    world = FakeArmWorld(kin, lambda k: np.array([5.0, 0.0, 0.0, 0.0, 0.0, 0.0]), link_error=_LinkError, **fail)
    tick = _arm_tick(kin, SafetyLimits(min_manipulability=0.0))
    log = run_loop(world, tick, 50)
    assert log.ended == "link_lost" and log.n == 7  # ticks 0-6 were sent and logged, tick 7 was not
    assert "link to the robot was lost" in log.message
    assert world.stops == 1 and len(world.commands) == 7
    assert log.joints.shape == (7, 6) and log.joint_velocity.shape == (7, 6)
    np.testing.assert_array_equal(log.joint_velocity, [c.qd for c in world.commands])


def test_a_tick_over_the_deadline_flags_the_next_tick():
    spent = np.full(12, 0.002)
    spent[3] = 0.012  # over the 8 ms budget
    calls = []

    def clock() -> float:  # two calls per tick: before read, after step
        k, second = divmod(len(calls), 2)
        calls.append(None)
        return 10.0 * k + (spent[k] if second else 0.0)

    target = np.array([0.3, 0.1])
    world = ScriptedEffortWorld(np.tile(target, (20, 1)), overrun_at=7)
    log = run_loop(world, _effort_tick(_reference(target)), 12, deadline=DT, clock=clock)
    assert log.n == 12 and len(calls) == 24
    np.testing.assert_allclose(log.compute, spent, rtol=0, atol=1e-12)  # 10 k + s − 10 k: rounding of 1e2
    # the late tick's command was already sent: the flag lands on the next one; tick 7's world overran
    missed = [k for k in range(12) if log.fault[k] & int(Fault.DEADLINE_MISS)]
    assert missed == [4, 8]
    # without a deadline the clock flags nothing (the world's own overrun still does)
    calls.clear()
    world = ScriptedEffortWorld(np.tile(target, (20, 1)), overrun_at=7)
    log = run_loop(world, _effort_tick(_reference(target)), 12, clock=clock)
    assert [k for k in range(12) if log.fault[k] & int(Fault.DEADLINE_MISS)] == [8]


def test_a_contact_force_over_the_threshold_ends_the_run_with_a_safety_stop():
    target = np.array([0.3, 0.1])
    world = ScriptedEffortWorld(np.tile(target, (20, 1)), wrench=np.array([100.0, 80.0, 0.0, 0.0, 0.0, 0.0]))
    log = run_loop(world, _effort_tick(_reference(target)), 12)  # |f| = 128 N > the 120 N contact threshold
    assert log.ended == "safety_stop" and log.n == 1 and world.stops == 1
    assert log.fault[0] & int(Fault.CONTACT_FORCE_LIMIT) and log.fault[0] & int(Fault.STOPPED)
    np.testing.assert_array_equal(world.efforts[0], 0.0)
    assert "contact threshold" in log.message


# ---------------------------------------------------------------------------- the tick's stages, checked


@pytest.mark.parametrize(
    "safety_dt, wrench_dt, field",
    [(4 * DT, DT, "safety.dt"), (DT / 2, DT, "safety.dt"), (DT, DT / 2, "wrench.dt")],
)
def test_a_stage_built_for_another_period_than_the_ticks_is_refused(safety_dt, wrench_dt, field):
    """The safety layer's acceleration limit is a step of a·dt per tick: a layer built for 32 ms in an 8 ms tick
    allowed 4× the limit (31 rad/s² against 8), and nothing checked. ControlTick refuses it, and a wrench pipeline
    on another period, naming both periods; the same period computed two ways is the same."""
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    model = ImpedanceModel(M, D, 0.0, DT)

    def build(s_dt, w_dt):
        return ControlTick(
            ManualGuidance(model),
            NominalStage(H),
            WrenchPipeline(CLEAN, w_dt),
            SafetyLayer(SafetyLimits(), s_dt, 6),
            command_space="joint_velocity",
            kinematics=kin,
        )

    with pytest.raises(
        ValueError,
        match=rf"{field} \({(safety_dt if field == 'safety.dt' else wrench_dt)!r} s.*"
        rf"model\.dt \({DT!r} s\)",
    ):
        build(safety_dt, wrench_dt)
    # a period computed otherwise (seven substeps of DT/7 summed: DT + 1 ulp) is the same period; one a millionth
    # longer is another (no rate a world runs at is within 1e-9 of another's)
    summed = sum([DT / 7] * 7)
    assert summed != DT
    assert build(summed, DT).dt == DT
    with pytest.raises(ValueError, match=r"safety\.dt"):
        build(DT * (1.0 + 1e-6), DT)


def test_the_safety_ramp_starts_from_rest_whatever_the_state_read_before_the_run_says():
    """reset(plan, context, state): the safety layer's ramp starts from q̇⁻ = 0 (ControlTick.reset: a velocity read
    before the run may be stale, and seeding from it would command a motion the arm may not be making). An arm
    measured at 0.5 rad/s gets the same first command as one given no state: within one margin·a·dt step of rest."""
    from dataclasses import replace

    limits = replace(WIDE, joint_acceleration=8.0)  # only the acceleration limit binds
    step = limits.margin * limits.joint_acceleration * DT  # 0.06272 rad/s
    ref = _reference(POSE0[:2])

    def first_command(qd0, with_state: bool):
        kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
        world = FakeArmWorld(kin, lambda k: np.zeros(6))
        world.qd = np.array(qd0, dtype=float)
        tick = _arm_tick(kin, limits)
        tick.reset(Plan(ref, POSE0), _context(ref), state=world.read() if with_state else None)
        return tick.step(0, world.read())

    rest = first_command(np.zeros(6), with_state=False)
    moving = first_command(np.full(6, 0.5), with_state=True)
    assert moving.command.qd.tobytes() == rest.command.qd.tobytes()
    assert np.abs(moving.command.qd).max() <= step


class _ComplexSource:
    """A source whose answer is of a dtype that is no real number's (complex, object): zeros, finite as numbers."""

    history, horizon, model_id = 0, H, "odd-dtype"

    def __init__(self, dtype) -> None:
        self.dtype = dtype

    def reset(self, context: object) -> None:
        pass

    def predict(self, window: np.ndarray) -> np.ndarray:
        return np.zeros((H, 2), dtype=self.dtype)


@pytest.mark.parametrize("dtype", [np.complex128, object])
def test_a_complex_prediction_falls_back_to_the_plan_and_the_run_goes_on(dtype):
    """A source answering in complex (or object) numbers is a failing predictor: PREDICTION_FALLBACK on every tick
    and the plan's rows, the run to its end with the nominal stage's commands bit for bit (it passed as a clean
    row and ended the run at tick 0 with internal_error), in run_loop and in lockstep."""
    from coassist.runtime.batched_loops import Loop, run_loops
    from coassist.runtime.intent import WindowIntent

    ref = _reference((0.1, 0.2), velocity=(0.05, 0.0))
    poses = ref[:40, :2] + 0.01
    world, nominal = ScriptedEffortWorld(poses), ScriptedEffortWorld(poses)

    def stage():
        return WindowIntent(_ComplexSource(dtype), H, stall_ticks=1000)  # no stall: the plan's rows throughout

    log = run_loop(world, _impedance_tick(ref, stage()), 30)
    run_loop(nominal, _impedance_tick(ref, NominalStage(H)), 30)
    assert log.ended == "time_limit" and log.n == 30
    assert [int(f) for f in log.fault] == [int(Fault.PREDICTION_FALLBACK)] * 30
    np.testing.assert_array_equal(np.array(world.efforts), np.array(nominal.efforts))
    assert np.abs(np.array(world.efforts)).max() > 0.1  # the spring pulled: a real effort was compared
    worlds = [ScriptedEffortWorld(poses), ScriptedEffortWorld(poses)]
    logs = run_loops([Loop(w, _impedance_tick(ref, stage()), 30) for w in worlds])
    for w, lg in zip(worlds, logs):
        assert lg.ended == "time_limit" and [int(f) for f in lg.fault] == [int(Fault.PREDICTION_FALLBACK)] * 30
        np.testing.assert_array_equal(np.array(w.efforts), np.array(nominal.efforts))


def test_a_finite_joint_glitch_is_a_state_mismatch_and_moves_nothing():
    """The review of 3063e1e: joint 0 read 0.3 rad high for 10 ticks (the tool pose reported true), nobody pushing:
    the tick drove the arm at up to 0.63 rad/s to correct an error it did not have, and the tool drifted 67 mm with
    only motion-limit flags. The joints' forward kinematics leaving the reported pose is now STATE_MISMATCH, a bad
    tick: the arm is held (here at rest), and the admittance is not moved by it."""
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    world = FakeArmWorld(kin, lambda k: np.zeros(6))
    read = world.read

    def glitched():
        state = read()
        if 50 <= world.k < 60:
            state.q = state.q + np.array([0.3, 0, 0, 0, 0, 0])
        return state

    world.read = glitched
    tick = _arm_tick(kin, SafetyLimits(min_manipulability=0.0))
    log = run_loop(world, tick, 120)
    flagged = np.flatnonzero(log.fault & int(Fault.STATE_MISMATCH)).tolist()
    assert flagged == list(range(50, 60))
    assert all(Fault(int(f)) & Fault.DECELERATING for f in log.fault[50:60])
    # the true arm never moved: commands of rounding only (the hold terms' rotation arithmetic, ~1e-16), where the
    # glitch drove 0.63 rad/s
    assert np.abs(log.joint_velocity).max() < 1e-12 and np.abs(world.q).max() < 1e-12
    assert np.isfinite(tick._za).all() and np.abs(tick._za).max() < 1e-12


@pytest.mark.parametrize("glitched_ticks", ["the first", "every even"])
def test_a_glitch_at_the_first_tick_does_not_become_the_reference(glitched_ticks):
    """A review (2026-12-07): the check's reference is the first tick's offset, taken on trust. Joint 0 read 0.3 rad
    high at tick 0 alone: every correct tick after it was flagged and the run stopped. On every even tick from 0: the
    wrong ticks passed unflagged, the correct ones were flagged, and the arm moved on its own (39 mm in 2 s) until
    5.4 s. Now two agreeing ticks replace a first tick no tick agreed with, and a flip-flop flags every tick."""
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    world = FakeArmWorld(kin, lambda k: np.zeros(6))
    read = world.read
    wrong = (lambda k: k == 0) if glitched_ticks == "the first" else (lambda k: k % 2 == 0)

    def glitched():
        state = read()
        if wrong(world.k):
            state.q = state.q + np.array([0.3, 0, 0, 0, 0, 0])
        return state

    world.read = glitched
    log = run_loop(world, _arm_tick(kin, SafetyLimits(min_manipulability=0.0)), 120)
    flagged = np.flatnonzero(log.fault & int(Fault.STATE_MISMATCH)).tolist()
    if glitched_ticks == "the first":
        assert flagged == [1] and log.ended == "time_limit"  # tick 1 disagreed with tick 0; ticks 1 and 2 agreed
    else:
        assert flagged == list(range(1, log.n)) and log.ended == "safety_stop"
    # tick 0's wrong reading, which nothing can tell from a true one, moves the arm by its acceleration-limited step
    # (8 rad/s² over 8 ms, for a tick or two: 0.5 mrad a tick) before the flags brake it; the flip-flop drifted 39 mm
    assert np.abs(world.q).max() < 1e-3


def test_a_glitch_under_the_tolerance_or_a_constant_offset_is_not_a_mismatch():
    """The reported pose may sit off the forward kinematics by a constant (a TCP or a calibration): that is the
    run's first tick's, held in the tool's frame; 0.5 mm, 0.01 rad of glitch are under the tolerance (1 cm, 0.05 rad)."""
    from coassist.runtime.tick import STATE_MISMATCH_ANGLE, STATE_MISMATCH_POSITION

    assert (STATE_MISMATCH_POSITION, STATE_MISMATCH_ANGLE) == (0.01, 0.05)
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    hand = np.array([6.0, -4.0, 0, 0, 0, 0])
    world = FakeArmWorld(kin, lambda k: hand)
    read = world.read

    def offset():
        state = read()
        state.tool_pose = state.tool_pose + np.array([0.03, -0.02, 0.01, 0.0, 0.0, 0.0])  # 3.7 cm, all along
        if 40 <= world.k < 45:
            state.tool_pose = state.tool_pose + np.array([0.0005, 0, 0, 0.01, 0, 0])
        return state

    world.read = offset
    log = run_loop(world, _arm_tick(kin, SafetyLimits(min_manipulability=0.0)), 100)
    assert not (np.bitwise_or.reduce(log.fault) & int(Fault.STATE_MISMATCH))
    assert world.q.any()  # followed the hand


class _NaNController:
    """Manual guidance whose effort is NaN on the ticks ``at`` (a controller plugged in that fails to guard itself)."""

    def __init__(self, at) -> None:
        self.inner, self.at, self.k = ManualGuidance(ImpedanceModel(M, D, 0.0, DT)), at, -1
        self.model, self.horizon = self.inner.model, self.inner.horizon

    def step(self, z, ref_h, ref_r, wrench):
        self.k += 1
        out = self.inner.step(z, ref_h, ref_r, wrench)
        return out._replace(u_r=np.full(2, np.nan)) if self.k in self.at else out


@pytest.mark.parametrize("at, stops", [(range(60, 61), False), (range(40, 10_000), True)])
def test_a_controllers_nan_is_a_bad_tick_never_the_admittance_state(at, stops):
    """The review of 3063e1e: one NaN effort from a controller (arm worlds) made the admittance state NaN for the rest
    of the run: every later command zero, the tool still under a push, only INVALID_INPUT flagged, never a stop, and
    the log's effort NaN. Now it is NONFINITE_EFFORT, a bad tick (decelerate; 25 in a row stop), the effort logged 0."""
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    world = FakeArmWorld(kin, lambda k: np.array([2.0, 0, 0, 0, 0, 0]))
    tick = ControlTick(
        _NaNController(at),
        NominalStage(H),
        WrenchPipeline(CLEAN, DT),
        SafetyLayer(SafetyLimits(min_manipulability=0.0), DT, 6),
        command_space="joint_velocity",
        kinematics=kin,
    )
    ref = _reference(POSE0[:2])
    tick.reset(Plan(ref, POSE0), _context(ref))
    log = run_loop(world, tick, 150)
    first = at[0]
    assert Fault(int(log.fault[first])) & (Fault.NONFINITE_EFFORT | Fault.DECELERATING) == (
        Fault.NONFINITE_EFFORT | Fault.DECELERATING
    )
    assert np.isfinite(log.effort_r).all() and np.isfinite(tick._za).all()
    if stops:  # the layer's max_bad_ticks (25) in a row
        assert log.ended == "safety_stop" and log.n == first + 25
    else:  # the push moves the tool on after the one bad tick
        assert log.ended == "time_limit" and not log.fault[first + 5 :].any()
        assert log.pose[-1, 0] - log.pose[first + 1, 0] > 0.01


class _ScriptedAlphaController(_NaNController):
    """Manual guidance whose ``alpha`` is set by its own step: 0.5 + 0.001·k at step k, NaN at step 7 (a bad read)."""

    def __init__(self) -> None:
        super().__init__(at=())
        self.alpha = 0.5

    def step(self, z, ref_h, ref_r, wrench):
        out = super().step(z, ref_h, ref_r, wrench)
        self.alpha = math.nan if self.k == 7 else 0.5 + 0.001 * self.k
        return out


def test_the_log_keeps_the_alpha_each_ticks_command_was_computed_with():
    # the arbitration's online α was in no record of a run (only the plain game's constant, on the MCAP's /alpha);
    # one value that is no α keeps the tick before's, the row never lost
    target = np.array([0.3, 0.1])
    world = ScriptedEffortWorld(np.tile(target + 0.05, (40, 1)))
    ref = _reference(target)
    tick = ControlTick(
        _ScriptedAlphaController(),
        NominalStage(H),
        WrenchPipeline(CLEAN, DT),
        SafetyLayer(SafetyLimits(), DT, 6),
        command_space="effort",
    )
    tick.reset(Plan(ref, np.array([*ref[0, :2], 0.0, 0.0, 0.0, 0.0])), _context(ref))
    log = run_loop(world, tick, 12)
    expected = 0.5 + 0.001 * np.arange(12)
    expected[7] = expected[6]
    np.testing.assert_array_equal(log.alpha, expected)
    assert run_loop(ScriptedEffortWorld(np.tile(target + 0.05, (40, 1))), _effort_tick(ref), 5).alpha is None  # MG


@pytest.mark.parametrize("overrun", ["late", np.array([0.01, 0.02]), float("nan")])
def test_an_overrun_that_is_not_a_number_counts_as_late_and_raises_nothing(overrun):
    """A world's last_overrun of the wrong type raised out of run_loop with the last command standing and no
    world.stop(); a NaN was taken as on time (a review, 2026-12-07). Each counts as a missed deadline."""
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    world = FakeArmWorld(kin, lambda k: np.array([6.0, 0, 0, 0, 0, 0]))
    world.last_overrun = 0.0
    apply = world.apply

    def late_from_tick_20(command):
        apply(command)
        world.last_overrun = overrun if world.k > 20 else 0.0

    world.apply = late_from_tick_20
    log = run_loop(world, _arm_tick(kin, SafetyLimits(min_manipulability=0.0)), 80)
    late = np.flatnonzero(log.fault & int(Fault.DEADLINE_MISS))
    assert late.size and late[0] <= 22 and not (log.fault[:20] & int(Fault.DEADLINE_MISS)).any()
    assert log.ended == "safety_stop" and world.stops >= 1  # late every tick: the layer stopped the arm


def test_a_simulated_hand_that_raises_ends_the_run_with_the_arm_stopped():
    """hand_force() raising escaped run_loop, world.stop() never called, the last command (0.126 rad/s) standing (a
    review, 2026-12-07): it ends the run as internal_error with the rows so far."""
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    world = FakeArmWorld(kin, lambda k: np.array([6.0, 0, 0, 0, 0, 0]))

    def hand_force():
        if world.k > 30:
            raise RuntimeError("the simulated operator failed")
        return np.zeros(6)

    world.hand_force = hand_force
    log = run_loop(world, _arm_tick(kin, SafetyLimits(min_manipulability=0.0)), 80)
    assert log.ended == "internal_error" and "hand_force failed" in log.message and world.stops == 1
    assert log.n == 30


@pytest.mark.parametrize(
    "field, value, flag",
    [
        ("tool_pose", np.array([0.3, 0.1, 0.4, 1e200, 0.0, 0.0]), Fault.INVALID_INPUT),  # raised: math domain error
        ("tool_twist", np.array([1e200, 0.0, 0.0, 0.0, 0.0, 0.0]), Fault.INVALID_INPUT),
        # at the plausibility bound (1e3), on either side: no measurement of a tool
        ("tool_pose", np.array([0.3, 0.1, 0.4, 0.0, 0.0, -1e3]), Fault.INVALID_INPUT),
        ("tool_twist", np.array([0.0, 0.0, 0.0, 0.0, 1e3, 0.0]), Fault.INVALID_INPUT),
        ("qd", np.full(6, np.nan), Fault.NONFINITE_STATE),  # not flagged at all
    ],
)
def test_a_finite_but_implausible_or_a_nan_joint_speed_state_is_flagged_and_the_run_goes_on(field, value, flag):
    """A review (2026-12-07): a pose rotation of 1e200 ended the run (internal_error) where a glitch is flagged and
    the last good value held; a NaN joint velocity was not flagged. Five glitched ticks: flagged, decelerated, and
    the run goes on to its end."""
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    world = FakeArmWorld(kin, lambda k: np.array([6.0, 0, 0, 0, 0, 0]))
    read = world.read

    def glitched():
        state = read()
        if 40 <= world.k < 45:
            setattr(state, field, value)
        return state

    world.read = glitched
    log = run_loop(world, _arm_tick(kin, SafetyLimits(min_manipulability=0.0)), 100)
    assert log.ended == "time_limit" and log.n == 100
    flagged = np.flatnonzero(log.fault & int(flag)).tolist()
    assert flagged == list(range(40, 45))
    assert all(Fault(int(f)) & Fault.DECELERATING for f in log.fault[40:45])
    assert np.isfinite(np.array([c.qd for c in world.commands])).all()


def test_a_stop_flag_that_is_no_truth_value_reads_as_a_stop():
    """protective_stop reported as an array raised in the tick (internal_error): it is read as a stop."""
    kin = LinearKinematics(well_conditioned_jacobian(), POSE0)
    world = FakeArmWorld(kin, lambda k: np.array([6.0, 0, 0, 0, 0, 0]))
    read = world.read

    def glitched():
        state = read()
        if world.k >= 30:
            state.protective_stop = np.array([False, False])
        return state

    world.read = glitched
    log = run_loop(world, _arm_tick(kin, SafetyLimits(min_manipulability=0.0)), 100)
    assert log.ended == "robot_stop" and log.fault[30] & int(Fault.ROBOT_PROTECTIVE_STOP) and world.stops >= 1
