"""FrankaWorld through the real franky client against franky-sim on loopback.

franky-sim (``tests/robot/franky_sim_server.py``, its own process) speaks libfranka's
network protocol with MuJoCo behind it; nothing here fakes the protocol. franky-sim
reports no external-force estimate (``O_F_ext_hat_K`` is always 0 in 1.0.4), so the
hand is a constant force applied to the simulated hand body and an external F/T sensor
(:class:`PushSensor`) that reads that same force.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("franky", reason="the Franka world needs franky: pip install 'coassist[franka]'")
pytest.importorskip("franky_sim", reason="the tests need franky-sim: pip install 'coassist[franka]'")
# franky-sim runs the arm's real-time loop in threads of this process: beside another test on
# a 2-core machine the loop lags and the timed checks fail, so ./dev test runs these alone
pytestmark = pytest.mark.realtime
pytest.importorskip("pinocchio", reason="the Panda kinematics need the robot extra: pip install 'coassist[robot]'")

import franky  # noqa: E402

from coassist.interfaces import Fault, fault_names  # noqa: E402
from coassist.robot import franka_world  # noqa: E402
from coassist.robot.arms import arm_kinematics  # noqa: E402
from coassist.robot.drive import ZERO_READINGS, DriveConfig, drive  # noqa: E402
from coassist.robot.franka_world import FrankaLinkError, FrankaWorld  # noqa: E402
from coassist.runtime.operators import ScriptedForce  # noqa: E402
from coassist.runtime.safety_limits import SafetyLimits, within_limits  # noqa: E402
from coassist.runtime.wrench import WrenchConfig  # noqa: E402

SERVER = Path(__file__).with_name("franky_sim_server.py")
D = 100.0  # the preset's damping [N·s/m]: MG renders M a + D v = F
#: [s] the link timeout of the runs that are not about the link: beside two busy loops on 2 cores the
#: server process (its 1 kHz clock) and this one are starved for longer than FrankaWorld's 0.1 s
#: default now and then (the server also runs at a higher priority where it may: franky_sim_server.py)
LINK_TIMEOUT = 1.0


class SimServer:
    """franky-sim in a subprocess; ``push`` sets the force on the simulated hand."""

    def __init__(self) -> None:
        env = dict(os.environ, OMP_NUM_THREADS="1")
        self.proc = subprocess.Popen(
            [sys.executable, str(SERVER)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env
        )
        line = self.proc.stdout.readline().split()
        if line[:1] != ["HOST"]:
            self.proc.kill()
            raise RuntimeError(f"franky-sim did not start: {line}")
        self.host = line[1]

    def push(self, f) -> None:
        self.proc.stdin.write("push {} {} {}\n".format(*f))
        self.proc.stdin.flush()

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait(10)

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.proc.stdin.write("quit\n")
                self.proc.stdin.flush()
                self.proc.wait(10)
            except (OSError, subprocess.TimeoutExpired):
                self.kill()


class PushSensor:
    """An F/T sensor on the hand: zero at the readings drive zeroes the pipeline on (its first ZERO_READINGS), then
    the push it starts in the simulator at the next reading, the loop's first (so the two agree to a tick)."""

    # Noise-free and says so (as MuJoCo's sensor does), so drive leaves out the frozen-sensor check,
    # which a real sensor's noise never trips.
    noise_force = noise_torque = 0.0

    def __init__(self, server: SimServer, force) -> None:
        self.server, self.force, self.n = server, np.asarray(force, dtype=float), 0

    def read(self):
        self.n += 1
        if self.n == ZERO_READINGS + 1:
            self.server.push(self.force)
        w = np.zeros(6)
        if self.n > ZERO_READINGS:
            w[:3] = self.force
        return w, np.eye(3), self.n


@pytest.fixture
def server():
    s = SimServer()
    yield s
    s.close()


@pytest.fixture(scope="module")
def mg_run():
    s = SimServer()
    try:
        world = FrankaWorld(s.host, arm="fr3", ft_sensor=PushSensor(s, (10.0, 0.0, 0.0)), link_timeout=LINK_TIMEOUT)
        sent = []
        trial = drive(
            DriveConfig(world="franka", robot="fr3", controller="manual", time_limit=1.4),
            world=world,
            on_tick=lambda k, st, out: sent.append(np.asarray(out.command.qd, dtype=float).copy()),
        )
        world.close()
    finally:
        s.close()
    return trial, np.array(sent), world


def test_the_model_matches_the_simulated_arm(server):
    # Start-up check: the Panda model with libfranka's F_T_EE puts the TCP where the robot reports it
    # (FrankaWorld raises otherwise); the FR3 simulated by franky-sim has the Panda's DH table.
    world = FrankaWorld(server.host, arm="fr3")
    s = world.read()
    p, _ = world.kinematics().forward(s.q)
    np.testing.assert_allclose(p, s.tool_pose[:3], atol=1e-4)
    np.testing.assert_allclose(world.tcp_offset_pose[:3], (0.0, 0.0, 0.1034), atol=1e-9)  # the hand's TCP
    world.close()


@pytest.mark.alone  # franky-sim's own loop tracks at the push's speed only with a core to itself: beside another
# franky-sim test on this 2-core VM it settled at 0.090 m/s for 0.1 (CI, 2026-12-06, 1 run in 3)
def test_mg_with_a_constant_push_settles_at_f_over_d(mg_run):
    trial, sent, world = mg_run
    assert trial.meta.extra["ended"] == "time_limit"
    v = trial.velocity
    # M a + D v = F − deadband: 9.8 N / 100 N·s/m = 0.098 m/s (the wrench pipeline takes its 0.2 N deadband off
    # the push); time constant M/D = 0.1 s, so from 0.4 s on the admittance has settled. 5 %: the arm follows it
    # through the position loop (10/s) and franky-sim's joint velocity loop, a finite damper (kv = 200-450
    # N·m·s/rad) that the push on the hand leads, so the window still holds their transient: measured 0.4-1.5 %
    # below at rest, 3.3 % below in CI on a slower machine (2026-12-07).
    # A busy machine makes the loop miss deadlines now and then (flagged: the layer decelerates a step, the
    # admittance restarts from the command): the 25 ticks (2 time constants) from one on are left out.
    settled = np.zeros(trial.n_samples, dtype=bool)
    settled[50:150] = True
    for k in np.flatnonzero(trial.fault & int(Fault.DEADLINE_MISS | Fault.DECELERATING)):
        settled[k : k + 25] = False
    assert settled.sum() >= 40, f"the machine left {settled.sum()} undisturbed ticks of 100"
    assert v[settled, 0].mean() == pytest.approx((10.0 - WrenchConfig().deadband_force) / D, rel=0.05)
    assert np.abs(v[settled, 1]).max() < 5e-3
    # the 7th DOF: the null space holds the start posture, the tool's orientation held too
    assert np.abs(trial.joints[settled][:, [0, 2, 4, 6]] - trial.joints[0, [0, 2, 4, 6]]).max() < 0.02
    # every command inside the joint speed limit, every step inside the acceleration limit
    lim = SafetyLimits()
    assert np.abs(sent).max() <= lim.joint_velocity + 1e-12
    steps = np.abs(np.diff(np.vstack([np.zeros(7), sent]), axis=0)).max(axis=1)
    # but where the loop saw a stall (DEADLINE_MISS): there the layer steps from the joints' measured speed when
    # the arm braked on its own, not from the last command (SafetyLayer._resume_from; 0.35 rad/s from the last
    # command once in CI at load 3.5)
    stalled = (trial.fault[: len(steps)] & int(Fault.DEADLINE_MISS)) != 0
    assert (~stalled).sum() >= 100 and steps[~stalled].max() <= lim.joint_acceleration * 0.008 + 1e-12
    assert world.commands_sent == len(sent)


def test_a_lost_link_ends_the_run_with_what_to_do(server):
    world = FrankaWorld(server.host, arm="fr3", ft_sensor=PushSensor(server, (5.0, 0.0, 0.0)), link_timeout=0.1)

    def cut(k, state, out):
        if k == 40:
            server.kill()

    trial = drive(
        DriveConfig(world="franka", robot="fr3", controller="manual", time_limit=3.0), world=world, on_tick=cut
    )
    assert trial.meta.extra["ended"] == "link_lost"
    assert "check the cable and the robot, then rerun" in trial.meta.extra["stop_message"]
    assert 40 <= len(trial.time) <= 42
    world.close()  # safe on a dead link


class ReflexAfter:
    """The real franky.Robot, but its n-th move raises franky's ControlException (the reflex a real
    arm would report; franky-sim 1.0.4 simulates no reflexes)."""

    def __init__(self, robot, n: int) -> None:
        self.robot, self.n, self.moves = robot, n, 0

    @property
    def state(self):
        return self.robot.state

    def move(self, motion, asynchronous=False):
        self.moves += 1
        if self.moves == self.n:
            raise franky.ControlException(
                "libfranka: Move command aborted: motion aborted by reflex! [cartesian_reflex]"
            )
        return self.robot.move(motion, asynchronous=asynchronous)

    def join_motion(self, timeout=None):
        return self.robot.join_motion(timeout)


def test_a_reflex_ends_the_run_safely_with_what_to_do(server):
    real = franky.Robot(server.host, realtime_config=franky.RealtimeConfig.Ignore)
    robot = ReflexAfter(real, 30)
    world = FrankaWorld(
        server.host, robot=robot, arm="fr3", ft_sensor=PushSensor(server, (5.0, 0.0, 0.0)), link_timeout=LINK_TIMEOUT
    )
    sent = []
    trial = drive(
        DriveConfig(world="franka", robot="fr3", controller="manual", time_limit=3.0),
        world=world,
        on_tick=lambda k, st, out: sent.append(out.command),
    )
    assert trial.meta.extra["ended"] == "robot_stop"
    msg = trial.meta.extra["stop_message"]
    assert "reflex" in msg and "recover_from_errors" in msg
    assert sent[-1].stop and not np.any(sent[-1].qd)
    assert robot.moves <= 31  # nothing but the stop after the reflex
    world.close()


def test_bad_arguments_name_the_option(server):
    with pytest.raises(ValueError, match="frequency"):
        FrankaWorld(server.host, frequency=0)
    with pytest.raises(ValueError, match="ft_sensor"):
        FrankaWorld(server.host, ft_sensor=object())
    with pytest.raises(FrankaLinkError, match="could not connect"):
        FrankaWorld("127.0.0.254")


@pytest.mark.parametrize(
    "field, value",
    [
        ("link_timeout", float("inf")),  # once accepted: a stuck robot clock was waited on without end
        ("link_timeout", 1e9),
        ("frequency", True),
        ("hold_ms", True),
        ("posture_gain", float("nan")),  # once refused only later, as NullSpacePosture.gain
    ],
)
def test_bad_values_are_refused_naming_them_before_connecting(field, value):
    with pytest.raises(ValueError, match=field):
        FrankaWorld("127.0.0.254", **{field: value})


def test_a_repeated_robot_clock_reads_forward_and_as_no_new_wrench_sample(server):
    """A state whose clock did not advance (or went back) once reached the tick as it was, and counted as a new
    wrench sample, so a stuck Franka's wrench never read as stale: the time goes on by a microsecond, the sample
    number stays."""
    real = franky.Robot(server.host, realtime_config=franky.RealtimeConfig.Ignore)

    class Stuck:  # the real robot, but for the state it reports once frozen
        frozen = None

        def __getattr__(self, name):
            return getattr(real, name)

        @property
        def state(self):
            return real.state if self.frozen is None else self.frozen

    robot = Stuck()
    world = FrankaWorld(server.host, arm="fr3", robot=robot, link_timeout=1.0)
    try:
        first = world.read()
        robot.frozen = real.state
        new, again, more = world.read(), world.read(), world.read()
        # 1 µs on, to the rounding of the clock's magnitude (a few ulp of t, whatever franky-sim's epoch)
        step = pytest.approx(1e-6, abs=4 * math.ulp(again.t))
        assert first.t < new.t < again.t < more.t and again.t - new.t == step
        assert new.wrench_seq == first.wrench_seq + 1 and more.wrench_seq == again.wrench_seq == new.wrench_seq
    finally:
        world.close()


def test_the_robots_force_estimate_is_read_as_the_hands(server):
    """libfranka's O_F_ext_hat_K is the robot's force on the environment (franky's documentation of the field): a
    hand pushing the tool along +x reads −x there, and coassist's wrench is the hand's, +x. Taken as it came, the
    arm moved against the push. (franky-sim reports 0: the robot's state is the real one but for this field.)"""
    real = franky.Robot(server.host, realtime_config=franky.RealtimeConfig.Ignore)
    estimate = np.array([-10.0, 2.0, -3.0, 0.1, -0.2, 0.3])  # the robot's on the environment

    class Pushed:  # the state franky reports, with the estimate of a hand pushing along +x
        def __init__(self, state):
            self._state = state

        def __getattr__(self, name):
            return estimate if name == "O_F_ext_hat_K" else getattr(self._state, name)

    class Robot:
        def __getattr__(self, name):
            return getattr(real, name)

        @property
        def state(self):
            return Pushed(real.state)

    world = FrankaWorld(server.host, arm="fr3", robot=Robot(), link_timeout=1.0)
    try:
        s = world.read()
        np.testing.assert_array_equal(s.wrench, -estimate)
        np.testing.assert_array_equal(s.sensor_rotation, np.eye(3))  # base-frame axes
    finally:
        world.close()


def test_the_world_takes_the_limits_of_the_arm_it_is_told(server, monkeypatch):
    # franky-sim simulates an FR3: told "fr3", the world holds the FR3's joint range and speeds
    world = FrankaWorld(server.host, arm="fr3")
    fr3, panda = arm_kinematics("fr3"), arm_kinematics("panda")
    np.testing.assert_array_equal(world.kinematics().joint_position_limit, fr3.joint_position_limit)
    np.testing.assert_array_equal(world._vmax, fr3.joint_velocity_limit)
    assert world.kinematics().joint_position_limit[5, 0] != panda.joint_position_limit[5, 0]
    world.close()
    with pytest.raises(ValueError, match=r"arm must be one of \('panda', 'fr3'\), got 'ur5'"):
        FrankaWorld(server.host, arm="ur5")
    # drive --world franka --robot fr3 builds the world for the FR3
    seen = []

    class Spy(FrankaWorld):
        def __init__(self, host, *, frequency, arm):
            seen.append(arm)
            super().__init__(host, frequency=frequency, arm=arm)

    monkeypatch.setattr(franka_world, "FrankaWorld", Spy)
    trial = drive(DriveConfig(world="franka", robot="fr3", controller="manual", time_limit=0.2), host=server.host)
    assert seen == ["fr3"] and trial.meta.extra["ended"] == "time_limit"


#: Flags a stall of this shared machine raises (the robot's clock ran > 12 ms between two reads, so the
#: safety layer ramps): the loop reacting correctly to the machine, not the controller's doing.
MACHINE_STALL = int(Fault.DEADLINE_MISS | Fault.DECELERATING)


def _assistive_run():
    """One assistive run through franky-sim; rerun (up to 3 tries, fresh simulator each time) while
    a stall of the machine flagged it: on a loaded 2-core CI machine one 8 ms period in a few
    hundred runs late. Any other flag fails at once."""
    for attempt in range(3):
        server = SimServer()
        try:
            world = FrankaWorld(
                server.host, arm="fr3", ft_sensor=PushSensor(server, (10.0, 0.0, 0.0)), link_timeout=LINK_TIMEOUT
            )
            seen = []
            # The preset this comparison's 1.5 mm was measured with (nominal intent: no learned predictor).
            config = DriveConfig(
                world="franka",
                robot="fr3",
                controller="cooperative",
                preset="thesis-application-dm",
                intent="nominal",
                time_limit=2.0,
            )
            trial = drive(
                config,
                world=world,
                on_tick=lambda k, st, out, seen=seen: seen.append(
                    (
                        np.asarray(out.command.qd, dtype=float).copy(),
                        st.q.copy(),
                        np.asarray(st.tool_pose, dtype=float).copy(),
                    )
                ),
            )
            flags = int(np.bitwise_or.reduce(trial.fault))
            if flags & ~MACHINE_STALL or not flags or attempt == 2:
                sent = world.commands_sent
                world.stop()
                rest = np.abs(world.robot.state.dq).max()
                kin = world.kinematics()
                world.close()
                return trial, seen, sent, rest, kin
            world.close()
        finally:
            server.close()
    raise AssertionError("unreachable")


def _late_ticks(monkeypatch, flagged) -> None:
    """Make the MuJoCo arm report its period ran over before each tick of ``flagged`` (the loop then
    flags DEADLINE_MISS on it, as FrankaWorld's clock did), and on no other."""
    from coassist.robot.mujoco_world import MujocoArmWorld

    late = {int(k) - 1 for k in flagged}
    apply = MujocoArmWorld.apply

    def applying(self, command):
        k = getattr(self, "_test_ticks", 0)
        apply(self, command)
        self.last_overrun = 0.004 if k in late else 0.0
        self._test_ticks = k + 1

    monkeypatch.setattr(MujocoArmWorld, "last_overrun", 0.0, raising=False)
    monkeypatch.setattr(MujocoArmWorld, "apply", applying)


@pytest.mark.alone  # a track against MuJoCo's, as the UR simulator's are: beside another franky-sim test on this
# 2-core VM it drifted 1.75 mm from MuJoCo's for 1.5 (CI, 2026-12-06)
def test_the_assistive_controller_through_franky_sim(monkeypatch):
    # A short assistive run (the cooperative game, nominal intent) with a 10 N push along +x.
    trial, seen, sent, rest, kin = _assistive_run()
    # it ends cleanly: at the time limit, nothing flagged but the machine's own stalls (measured by the
    # robot's clock; a loaded machine can stall every try), every tick's command sent, the arm at rest after stop
    flags = int(np.bitwise_or.reduce(trial.fault))
    assert trial.meta.extra["ended"] == "time_limit" and not flags & ~MACHINE_STALL, fault_names(flags)
    assert sent == len(seen) == trial.n_samples
    assert rest < 0.01  # rad/s
    # every command inside every limit, with the Jacobian and pose of the tick that sent it
    limits, prev, bad = SafetyLimits(), np.zeros(7), []
    for k, (qd, q, pose) in enumerate(seen):
        bad += [f"tick {k}: {b}" for b in within_limits(qd, prev, kin.forward_and_jacobian(q)[2], pose, limits, 0.008)]
        prev = qd
    assert bad == []
    # the same controller and push on the MuJoCo Panda move the tool the same way: the game holds
    # the tool near the plan (which starts to move at 1.5 s), so both creep 17 mm. 1.5 mm: the push
    # here starts a tick late and franky-sim's joint velocity loop lags its command. The machine's
    # stalls above, if any, are replayed there: the same ticks late, the same ramp of the safety layer.
    _late_ticks(monkeypatch, np.flatnonzero(trial.fault & int(Fault.DEADLINE_MISS)))
    mj = drive(
        DriveConfig(
            robot="panda", controller="cooperative", preset="thesis-application-dm", intent="nominal", time_limit=2.0
        ),
        operator=ScriptedForce.constant((10.0, 0.0, 0.0, 0.0, 0.0, 0.0)),
    )
    np.testing.assert_allclose(trial.pose[:, 0] - trial.pose[0, 0], mj.pose[:, 0] - mj.pose[0, 0], atol=1.5e-3)


def test_franky_holds_the_joints_to_the_accelerations_the_drive_caps_a_franka_arm_at(server):
    """What franky's own motion generator holds the joints to (franky-sim's FR3) is FRANKY_JOINT_ACCELERATION, which
    the drive's layer takes the smaller of with the arm's own: the layer's steps are what franky follows."""
    from coassist.robot.arm_descriptions import FRANKY_JOINT_ACCELERATION

    real = franky.Robot(server.host, realtime_config=franky.RealtimeConfig.Ignore)
    assert tuple(float(a) for a in real.joint_acceleration_limit.max) == FRANKY_JOINT_ACCELERATION
