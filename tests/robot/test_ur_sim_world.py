"""The real ur-rtde client against ``coassist ur-sim``, and coassist's UR world and drive through them.

Nothing here fakes the client: ``rtde_control`` / ``rtde_receive`` (the compiled ur-rtde 1.6.5)
talk to the simulator (its own process, tests/ursim.py) over the UR's ports on a loopback
address. The runs keep the real-time loop alone (``realtime``): the simulator at SCHED_FIFO,
the test's loop too where the system allows (:func:`realtime_priority`), else a run a stall of
this machine flagged is run again.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from ..ursim import needs_ur_rtde, realtime_priority, simulator

needs_ur_rtde()
pytest.importorskip("mujoco", reason="the simulator's arm is the MuJoCo UR5: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")
pytestmark = pytest.mark.realtime

import rtde_control  # noqa: E402
import rtde_receive  # noqa: E402

from coassist.interfaces import Fault, fault_names  # noqa: E402
from coassist.robot.drive import DriveConfig, drive  # noqa: E402
from coassist.robot.mujoco_world import FTSensorModel, MujocoUR5World  # noqa: E402
from coassist.robot.ur_rtde_world import URProgramStopped, URRTDEWorld  # noqa: E402
from coassist.runtime.operators import ScriptedForce  # noqa: E402
from coassist.runtime.safety_limits import SafetyLimits, within_limits  # noqa: E402
from coassist.runtime.world import Command, RobotLinkError  # noqa: E402

#: Flags a stall of this machine raises (a late tick: the safety layer ramps), not the robot's doing.
MACHINE_STALL = int(Fault.DEADLINE_MISS | Fault.DECELERATING)
#: A quiet sensor for the comparisons with the MuJoCo world (each world's noise is its own draw).
QUIET = FTSensorModel(noise_force=0.005, noise_torque=0.0002, rate_hz=None)


# ur-rtde 1.6.5's ``disconnect()`` sleeps 0.5 s after closing, and its destructor calls it again: an
# interface disconnected, then destroyed, costs 1.0 s; destroyed alone (``del``, while the simulator still
# answers: against a dead one its receive thread would retry for ever), 0.5 s, closing the same connections.


def stamps(receive, seconds: float = 0.3) -> np.ndarray:
    """The distinct RTDE timestamps the client saw over ``seconds``."""
    out: list[float] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ts = receive.getTimestamp()
        if not out or ts != out[-1]:
            out.append(ts)
        time.sleep(0.0002)
    return np.array(out)


# ------------------------------------------------------------------ connection, recipes, rate


@pytest.mark.alone  # measures the stream's timing: no other test beside it (pyproject.toml's markers)
@pytest.mark.parametrize(
    ("series", "frequency", "step"), [("e-series", -1.0, 0.002), ("cb3", -1.0, 0.008), ("e-series", 125.0, 0.008)]
)
def test_the_stream_runs_at_the_rate_the_client_asked(series, frequency, step):
    with simulator(series=series) as sim, realtime_priority():
        r = rtde_receive.RTDEReceiveInterface(sim.host, frequency)
        steps = np.diff(stamps(r))
        del r  # disconnects (above)
    # the controller's clock: each package one step of k·dt later (a skipped one: a whole number of steps)
    assert steps.min() == pytest.approx(step, abs=1e-9) and np.median(steps) == pytest.approx(step, abs=1e-9)
    np.testing.assert_allclose(steps / step, np.round(steps / step), atol=1e-6)


@pytest.mark.alone
def test_rate_detection_uses_the_stream_not_get_step_time():
    for series, step, version in (("e-series", 0.002, "URSoftware 5.11"), ("cb3", 0.008, "URSoftware 3.15")):
        with simulator(series=series) as sim:
            c = rtde_control.RTDEControlInterface(sim.host)
            first = c.getStepTime()  # real-time: read before the script ran it
            time.sleep(0.05)
            later = c.getStepTime()
            c.stopScript()
            del c  # disconnects (above)
            world = URRTDEWorld(sim.host)  # frequency=-1
            info = world.robot_info()
            world.close()
        assert first == 0.0
        assert later == (step if series == "e-series" else 0.0)  # a CB3's script has no get_steptime
        assert world.dt == step and info["step_time"] == step and info["controller_version"].startswith(version)


def test_a_field_the_controller_lacks_and_registers_in_use_are_refused():
    with simulator() as sim:
        with pytest.raises(RuntimeError, match="actual_nothing"):
            rtde_receive.RTDEReceiveInterface(sim.host, 500.0, ["timestamp", "actual_nothing"])
        c = rtde_control.RTDEControlInterface(sim.host)
        with pytest.raises(RuntimeError, match="already in use"):
            rtde_control.RTDEControlInterface(sim.host)  # the first holds the input registers
        c.stopScript()
        del c  # disconnects (above)


# ------------------------------------------------------------------ every command coassist or a user's script uses


def wait_periods(c, n: int, send) -> None:
    for _ in range(n):
        t0 = c.initPeriod()
        send()
        c.waitPeriod(t0)


def test_each_command_through_the_real_client():
    with simulator() as sim, realtime_priority():
        r = rtde_receive.RTDEReceiveInterface(sim.host, 500.0)
        c = rtde_control.RTDEControlInterface(sim.host, 500.0)
        try:
            # speedJ: the joint reaches the speed (ramp 0.1 s at 2 rad/s², the servo's 20 ms lag)
            wait_periods(c, 150, lambda: c.speedJ([0.2, 0, 0, 0, 0, 0], 2.0, 0.002))
            assert r.getActualQd()[0] == pytest.approx(0.2, abs=0.01)
            # speedStop returns once the motion's target is at rest (0.2 rad/s at 4 rad/s²: 50 ms); the
            # joints follow it with the servo's lag
            t = time.monotonic()
            assert c.speedStop(4.0)
            returned, stamp = time.monotonic(), r.getTimestamp()
            while r.getTimestamp() <= stamp and time.monotonic() < returned + 1.0:  # the next package (a busy
                time.sleep(0.001)  # machine's receive thread read it late: 4 ms of sleep once gave a stale one)
            assert returned - t >= 0.045 and max(abs(v) for v in r.getTargetQd()) < 1e-9
            time.sleep(0.15)
            assert max(abs(v) for v in r.getActualQd()) < 1e-3
            # speedL: the TCP's speed in the base frame
            wait_periods(c, 150, lambda: c.speedL([0.05, 0, 0, 0, 0, 0], 0.5, 0.002))
            v = r.getActualTCPSpeed()
            assert v[0] == pytest.approx(0.05, abs=0.004) and max(abs(x) for x in v[1:]) < 0.004
            assert c.speedStop(2.0)
            # moveJ / moveL (blocking: they return at the target)
            q1 = np.array(r.getActualQ()) + [0.1, -0.05, 0.05, 0.0, 0.0, 0.1]
            assert c.moveJ(q1.tolist(), 0.5, 1.0)
            np.testing.assert_allclose(r.getActualQ(), q1, atol=3e-3)
            p1 = np.array(r.getActualTCPPose())
            p1[:3] += [0.05, 0.02, -0.03]
            assert c.moveL(p1.tolist(), 0.1, 0.5)
            np.testing.assert_allclose(r.getActualTCPPose()[:3], p1[:3], atol=3e-3)
            # servoJ tracks a target (lookahead 0.1 s), servoStop ends it
            q2 = np.array(r.getActualQ()) + [0.05, 0, 0, 0, 0, 0]
            wait_periods(c, 400, lambda: c.servoJ(q2.tolist(), 0.5, 0.5, 0.002, 0.1, 300))
            np.testing.assert_allclose(r.getActualQ(), q2, atol=3e-3)
            assert c.servoStop(2.0)
            # setTcp / getTCPOffset: the pose reported moves with the TCP (10 cm down the tool, which points down)
            before = c.getTCPOffset()
            z0 = r.getActualTCPPose()[2]
            assert c.setTcp([0.0, 0.0, 0.16, 0.0, 0.0, 0.0]) and c.getTCPOffset() == [0.0, 0.0, 0.16, 0.0, 0.0, 0.0]
            time.sleep(0.02)
            assert r.getActualTCPPose()[2] == pytest.approx(z0 - (0.16 - before[2]), abs=1e-4)
            # setPayload shows in the stream
            assert c.setPayload(1.2, [0.0, 0.0, 0.05])
            time.sleep(0.02)
            assert r.getPayload() == pytest.approx(1.2) and r.getPayloadCog() == pytest.approx([0.0, 0.0, 0.05])
            assert c.setPayload(0.3, [0.0, 0.0, 0.06])
            # zeroFtSensor: a steady push reads zero after it
            sim.push([5.0, 0.0, 0.0])
            time.sleep(0.1)
            assert r.getActualTCPForce()[0] == pytest.approx(5.0, abs=0.5)
            assert c.zeroFtSensor()
            time.sleep(0.02)
            assert abs(r.getActualTCPForce()[0]) < 0.3
            sim.push(None)
            # forceMode: z compliant, 10 N down in free space: a damper, 10 N / 100 N·s/m = 0.1 m/s down
            wait_periods(
                c,
                150,
                lambda: c.forceMode([0.0] * 6, [0, 0, 1, 0, 0, 0], [0.0, 0.0, -10.0, 0.0, 0.0, 0.0], 2, [0.2] * 6),
            )
            assert r.getActualTCPSpeed()[2] == pytest.approx(-0.1 + 0.0, abs=0.02)  # the zeroed push adds -5/100
            assert c.forceModeStop()
            # stopScript ends the program
            c.stopScript()
            assert not c.isProgramRunning()
            # the receive interface learns it from the stream's next package (2 ms at 500 Hz): on a loaded machine
            # that package can come after the call returns (seen: still PLAYING, 2, beside a busy test suite)
            deadline = time.monotonic() + 1.0
            while r.getRuntimeState() != 1 and time.monotonic() < deadline:
                time.sleep(0.002)
            assert r.getRuntimeState() == 1  # STOPPED
            status = sim.status()
        finally:
            c = r = None  # destroyed here, which disconnects (above; the lambdas share c, so no del)
    assert status["out_of_limits"] == 0 and status["unsupported_commands"] == {}


def test_the_tcp_force_is_signed_and_framed_as_coassist_reads_it():
    with simulator() as sim:
        world = URRTDEWorld(sim.host, frequency=500.0)
        try:
            sim.push([10.0, 0.0, -5.0])  # the hand pushes +x and down (base frame)
            time.sleep(0.15)
            state = world.read()
        finally:
            world.close()
    # tool down: the TCP frame is the base's turned π about x (y and z flipped)
    np.testing.assert_allclose(state.wrench[:3], [10.0, 0.0, 5.0], atol=0.3)
    np.testing.assert_allclose(state.sensor_rotation @ state.wrench[:3], [10.0, 0.0, -5.0], atol=0.3)
    np.testing.assert_allclose(state.tool_pose[:3], (-0.10, -0.615, 0.20), atol=1e-3)


# ------------------------------------------------------------------ coassist's drive through it


def _run(config: DriveConfig, push_at: int | None = None, wrench=(10.0, 0.0, 0.0), retries: int = 3, **sim_config):
    """A drive through a fresh simulator (commands and states recorded, the simulator's status after);
    run again while this machine disturbed it (:func:`_machine_stall`: a late tick flagged, the robot's data or the
    loop's own period 0.1 s late; at most ``retries``); any other flag ends the retries at once."""
    for attempt in range(retries):
        seen, periods = [], []
        with simulator(**sim_config) as sim:
            holder: list = []  # the world, once built (the callback runs only inside the drive)

            def on_tick(k, state, out, seen=seen, sim=sim, periods=periods, holder=holder):
                if push_at is not None and k == push_at - 1:
                    sim.push(list(wrench))
                seen.append(
                    (np.asarray(out.command.qd, dtype=float).copy(), state.q.copy(), np.asarray(state.tool_pose).copy())
                )
                periods.append(holder[0].last_period)  # initPeriod / waitPeriod's period, by the wall clock

            with realtime_priority() as granted:  # ur-rtde's receive threads, started here, inherit it
                world = URRTDEWorld(sim.host, frequency=float(config.rate_hz))
                holder.append(world)
                trial = drive(config, world=world, on_tick=on_tick)
            kin = world.kinematics()
            world.close()
            status = dict(sim.status(), loop_periods=periods[1:], granted=granted)
        # a late tick flagged, the loop held longer than the watchdog's 0.1 s, or the robot's data 0.1 s late (this
        # machine, not the code: the assistive run, beside two busy loops on 2026-12-04, "no new data ... for
        # 0.101 s"): as a stall
        if not _machine_stall(trial) or _unexplained(trial) or attempt == retries - 1:
            return trial, seen, kin, status
    raise AssertionError("unreachable")


def _flags(trial) -> int:
    """The trial's fault flags after its first 3 ticks (the controller's first call takes longer than a
    period: a deadline miss while the arm is still at rest, in every real-time world)."""
    return int(np.bitwise_or.reduce(trial.fault[3:]))


#: [ticks] after a deadline miss this machine made, the loop's next command may ask for more than the arm's
#: acceleration allows (the admittance ran on while the loop stood); the safety layer limits it and flags
#: JOINT_ACCELERATION_LIMIT, part of the stall (./dev test's realtime part, 2026-12-04: the assistive run's only
#: other flag with DEADLINE_MISS and DECELERATING). 25 ticks: 0.2 s, as the Franka settling test leaves out.
STALL_AFTERMATH = 25


def _unexplained(trial) -> int:
    """The flags of ticks 3 on that no stall of this machine explains: any but :data:`MACHINE_STALL`'s, and
    JOINT_ACCELERATION_LIMIT only where no deadline miss came in the :data:`STALL_AFTERMATH` ticks before.
    Every command stays checked against the limits (``_every_command_inside_the_limits``)."""
    f = np.asarray(trial.fault[3:], dtype=np.int64)
    after = np.zeros(f.size, dtype=bool)
    for k in np.flatnonzero(f & int(Fault.DEADLINE_MISS)):
        after[k : k + STALL_AFTERMATH + 1] = True
    out = f & ~MACHINE_STALL
    out[after] &= ~int(Fault.JOINT_ACCELERATION_LIMIT)
    return int(np.bitwise_or.reduce(out)) if out.size else 0


def _mujoco(config: DriveConfig, push_at: int | None, wrench=(10.0, 0.0, 0.0)):
    world = MujocoUR5World(control_dt=config.dt, start=(-0.10, -0.615, 0.20), sensor=QUIET, seed=config.seed)
    op = ScriptedForce.steps([(push_at * config.dt, [*wrench, 0, 0, 0])]) if push_at is not None else None
    try:
        return drive(config, world=world, operator=op or ScriptedForce.constant(np.zeros(6)))
    finally:
        world.close()


def _track_gap(a, b) -> float:
    """The largest distance [m] between two runs' tool paths, each from its own start (x-y)."""
    n = min(a.n_samples, b.n_samples)
    return float(np.linalg.norm((a.pose[:n, :2] - a.pose[0, :2]) - (b.pose[:n, :2] - b.pose[0, :2]), axis=1).max())


def _onset(trial, threshold: float = 5.0) -> int:
    """The first tick the hand force along x exceeds ``threshold`` [N] (the push of 10 N)."""
    pushed = trial.wrench[:, 0] > threshold
    assert pushed.any(), "the run was never pushed"
    return int(np.argmax(pushed))


#: What the push's timing inside a tick may add to the track [m]: the simulator applies it at its next
#: 2 ms cycle, anywhere in the loop's period before the tick MuJoCo applies it at, so up to a period's
#: more impulse: F·dt/D = 10 N · 8 ms / 100 N·s/m (MG's damping) = 0.8 mm. Measured: MG 0.92-0.97 mm,
#: the assistive controller 0.38-0.54 mm (the defaults' trial, pushed by the simulated operator in the
#: simulator's own time, keeps the 1 mm without it).
PUSH_TIMING = 10.0 * 0.008 / 100.0


def _mujoco_same_push(trial, config: DriveConfig, push_at: int):
    """The MuJoCo run of the push ``trial`` felt, at the tick it felt it. The test hands the push to the
    simulator's process through its stdin (read by a thread at normal priority): on a busy machine it
    lands a tick or more late, and each tick is 0.8 mm of MG's 0.1 m/s on the track; what is compared
    is the loop through the protocol, not when the test's message arrived."""
    mj = _mujoco(config, push_at=push_at)
    shift = _onset(trial) - _onset(mj)
    assert abs(shift) <= 25, shift  # the push reached the simulator within 0.2 s
    if shift:
        mj = _mujoco(config, push_at=push_at + shift)
        assert _onset(mj) == _onset(trial)
    return mj


#: The defaults' trial through the simulator against the same trial in MuJoCo: the largest distance of
#: the two tool tracks [m]. Measured 0.39, 0.46, 0.83 mm (3 runs alone, none flagged, this machine's load 8-12),
#: 1.30 mm once among the other realtime tests at load 10 (unflagged): the issue's 1 mm is reached
#: alone, the bound keeps 1.5 mm for a shared machine. What remains is the protocol's, a real UR's too:
#: the state read is up to one controller cycle (2 ms) old, a speedJ takes effect at the next cycle and
#: ramps at its 1.4 rad/s² (these in a MuJoCo run: 0.1 mm); each world's sensor noise is its own draw
#: (0.1-0.3 mm between two MuJoCo runs' seeds); the loaded machine's jitter (the package a tick reads
#: sometimes a cycle older, the simulator's skipped packages). It was 2.7-5.5 mm while the loop took a
#: fresh initPeriod each period (22 µs long each: the hand and the arm, in real time, ran ahead of the
#: ticks; docs/robots.md; 2.5 mm when tried again, failing this bound), 0.9-1.0 mm while the hand
#: started before the watchdog's round trip and a cycle after the state the loop reads.
TRACK_GAP = 1.5e-3


def test_only_a_deadline_miss_just_before_explains_an_acceleration_limit():
    from types import SimpleNamespace

    D, A, C = int(Fault.DEADLINE_MISS), int(Fault.JOINT_ACCELERATION_LIMIT), int(Fault.DECELERATING)
    ticks = lambda *f: SimpleNamespace(fault=np.array([0, 0, 0, *f]))  # noqa: E731 (the first 3 are left out)
    assert _unexplained(ticks(0, D | C, 0, A, C)) == 0  # the stall, the layer slowing, the next command limited
    assert _unexplained(ticks(A, 0, D, 0)) == A  # limited before any stall
    assert _unexplained(ticks(D, *[0] * STALL_AFTERMATH, A)) == A  # 26 ticks after it
    assert _unexplained(ticks(D, *[0] * (STALL_AFTERMATH - 1), A)) == 0
    assert _unexplained(ticks(D, int(Fault.NONFINITE_STATE))) == int(Fault.NONFINITE_STATE)


def _machine_stall(trial) -> bool:
    """A run this machine disturbed: a late tick flagged, the stream held up past the link timeout, or the loop's
    own period over the controller's watchdog (two busy loops beside the test on 2026-12-04: "link_lost" at tick
    62, the robot's data arriving 102 ms late; the watchdog's stop at tick 1927, a period of 0.102 s)."""
    message = trial.meta.extra.get("stop_message") or ""
    return bool(_flags(trial) & MACHINE_STALL) or (
        trial.meta.extra["ended"] in ("world_error", "link_lost")
        and ("no new data" in message or "arrive" in message or "period lasted" in message)
    )


def _first_stall(trial) -> int | None:
    """The first tick (after the first 3, :func:`_flags`) a stall of this machine flagged, or None."""
    late = np.flatnonzero(np.asarray(trial.fault[3:]) & MACHINE_STALL)
    return int(late[0]) + 3 if late.size else None


def _detour_passed(trial) -> int:
    """The tick the tool is back on its line after the bump: within 3 mm across of where it started, after its
    farthest point (the defaults' MuJoCo run: the bump's low at tick 819, back at 1067 of 2115)."""
    y = trial.pose[:, 1] - trial.pose[0, 1]
    low = int(np.argmin(y))
    back = np.flatnonzero(np.abs(y[low:]) < 3e-3)
    return low + int(back[0]) if back.size else trial.n_samples


@pytest.mark.alone
def test_drives_defaults_complete_a_trial_on_the_track_of_the_mujoco_world(tmp_path):
    from typer.testing import CliRunner

    from coassist.cli import app
    from coassist.data import read_trial

    mj = drive(DriveConfig(world="mujoco"))  # the same defaults: the simulated operator at MuJoCo's handle
    passed = _detour_passed(mj)
    compared = None  # the ticks whose track was compared: all (an unflagged run) or those before a late stall
    best = None  # (stall, trial, result, status) of the stalled run that ended at the target latest-stalled
    reached = None  # (trial, result, status) of the last stalled run that ended at the target
    off_track = None  # (trial, result, status) of the last run no stall disturbed whose track left MuJoCo's
    for attempt in range(4):  # a stall of this machine decelerates the loop: from it on the track is not the same
        with simulator() as sim:
            out = tmp_path / f"trial-{attempt}.parquet"
            with realtime_priority():
                result = CliRunner().invoke(
                    app, ["drive", "--world", "ur", "--host", sim.host, "--yes", "--no-plot", "--out", str(out)]
                )
            status = sim.status()
        assert result.exit_code == 0, result.output
        trial = read_trial(out)
        # again after a stall before the tool was back on its line past the bump, or a track off by more than
        # the bound: measured once 2.63 mm unflagged in ./dev test's realtime phase at this shared machine's
        # heaviest load; the old schedule is 2.5 mm and more in every run: it fails all four, and the test. A stall
        # after it (2 of 3 runs of ./dev test on 2026-12-04: ticks 1246-1839) leaves the whole detour to compare
        # up to it: one run instead of up to four (~20 s each)
        stall = _first_stall(trial)
        if not _machine_stall(trial):
            if _flags(trial) or _track_gap(trial, mj) < TRACK_GAP:
                compared = None if _flags(trial) else trial.n_samples
                break
            off_track = (trial, result, status)
        if stall is not None and trial.meta.extra["ended"] == "target":
            reached = (trial, result, status)
            if _track_gap(_ticks(trial, stall), mj) < TRACK_GAP:
                if stall > passed:
                    compared = stall
                    break
                if best is None or stall > best[0]:
                    best = (stall, trial, result, status)
    else:
        # no run was kept. A run no stall disturbed whose track left MuJoCo's is compared whole, and fails below
        # (before, such runs passed uncompared). Else every run stalled before the bump's return (two busy loops
        # beside the test on 2026-12-04: stalls at ticks 57, 689 and 113, the last run then stopped by the watchdog
        # at 1927): the run that reached the target with the latest stall, its track compared up to it, if that is
        # past the push's first ticks (the tool 10 cm along by tick 600, the push from tick ~300), where a force of
        # the wrong sign or frame leaves the track; else the last run that reached the target, uncompared; else
        # the last run (which fails below: a run of the wrong sign or frame ends off the target)
        if off_track is not None:
            trial, result, status = off_track
            compared = trial.n_samples
        elif best is not None and best[0] >= EARLY_STALL:
            compared, trial, result, status = best
        elif reached is not None:
            trial, result, status = reached
    assert trial.meta.extra["ended"] == mj.meta.extra["ended"] == "target", result.output
    assert status["out_of_limits"] == 0 and status["events"] == {"stopScript": 1}
    # the simulator's hand pushed the tool round the obstacle (the thesis' bump), as MuJoCo's did
    assert np.abs(trial.wrench[:, :2]).max() > 5.0 and trial.pose[:, 1].min() < trial.pose[0, 1] - 0.03
    flags = _flags(trial)
    assert not _unexplained(trial), fault_names(flags)
    if not flags:
        assert abs(trial.n_samples - mj.n_samples) <= 2
    if compared is not None:
        # against nobody at the handle the gap is the bump, 54 mm; a force read in the wrong frame or sign,
        # or a command of the wrong sign, ends the run off the target (tried), and leaves the track within
        # the push's first ticks, long before the bump
        assert compared >= EARLY_STALL  # the whole run, up to a stall past the bump, or (all stalled) past 600
        assert _track_gap(_ticks(trial, compared), mj) < TRACK_GAP


#: [ticks] the least of the defaults' run a stalled run's track is compared over, when every attempt stalled
#: before the bump's return: MuJoCo's run has the tool 0.1 m along by then (the push from tick ~300 on).
EARLY_STALL = 600


def _ticks(trial, n: int):
    """The trial's first ``n`` ticks' poses, as :func:`_track_gap` reads them."""
    from types import SimpleNamespace

    return SimpleNamespace(pose=trial.pose[:n], n_samples=min(n, trial.n_samples))


def test_the_track_before_a_late_stall_is_what_the_defaults_test_compares():
    """The helpers the defaults test leans on, on hand-made runs: the first stall after the first 3 ticks, the
    tick the tool is back on its line past the bump, and a comparison cut at the stall."""
    from types import SimpleNamespace

    D, C = int(Fault.DEADLINE_MISS), int(Fault.DECELERATING)
    assert _first_stall(SimpleNamespace(fault=np.array([D, D, 0, 0, 0, C | D, 0]))) == 5
    assert _first_stall(SimpleNamespace(fault=np.array([D, 0, 0, 0, int(Fault.JOINT_ACCELERATION_LIMIT)]))) is None
    y = np.concatenate([np.zeros(10), -np.linspace(0, 0.05, 20), -np.linspace(0.05, 0, 20), np.zeros(10)])
    run = SimpleNamespace(pose=np.column_stack([np.linspace(0, 0.5, y.size), y]), n_samples=y.size)
    assert _detour_passed(run) == 29 + 19  # the low at 29, back within 3 mm at 29 + 19 (0.05·(1 − 18/19) ≈ 2.6 mm)
    drift = np.zeros_like(run.pose)
    drift[55:, 1] = 0.01  # the track 10 mm off across from tick 55 on (a stall's aftermath)
    off = SimpleNamespace(pose=run.pose + drift, n_samples=y.size)
    assert _track_gap(off, run) == pytest.approx(0.01) and _track_gap(_ticks(off, 55), run) == 0.0


@pytest.mark.alone
def test_mg_with_a_push_settles_at_f_over_d_on_the_mujoco_track():
    config = DriveConfig(world="ur", controller="manual", time_limit=3.0)
    trial, seen, kin, status = _run(config, push_at=40, sensor=QUIET)
    mj = _mujoco_same_push(trial, DriveConfig(controller="manual", time_limit=3.0), push_at=40)
    assert trial.meta.extra["ended"] == "time_limit", trial.meta.extra["stop_message"]
    assert status["out_of_limits"] == 0
    # initPeriod / waitPeriod keep the period (the first one: the watchdog's round trip before it): within 1 % on a run
    # this machine kept on time; within 5 % where it made the loop late (CI on 2026-12-07, alone, after every retry:
    # medians of 7.80 ms, and late ticks every few dozen), which a loop that does not pace (periods of a tick's work)
    # or paces twice (16 ms) still fails by far
    periods = np.array(status["loop_periods"])
    late = bool((trial.fault & int(Fault.DEADLINE_MISS)).any())
    assert np.median(periods) == pytest.approx(config.dt, rel=0.05 if late else 0.01)
    if status["granted"] and not _flags(trial):  # a run the machine kept on time (else its misses are flagged)
        assert np.percentile(periods, 99) < 1.25 * config.dt
    settled = slice(150, 375)  # M/D = 0.1 s after the push at tick 40
    speed = trial.velocity[settled, 0].mean()
    if not _flags(trial):
        assert speed == pytest.approx((10.0 - 0.2) / 100.0, rel=0.02)  # the 0.2 N deadband
    else:
        # deadline misses this machine made (quiet machine, 3 of 4 runs on 2026-12-03 at cd60587 and later:
        # DEADLINE_MISS and DECELERATING, 0.072-0.095 m/s): the safety layer slows the arm, it never speeds it up
        assert 0.0 < speed <= (10.0 - 0.2) / 100.0 * 1.02, fault_names(_flags(trial))
    _every_command_inside_the_limits(seen, kin, config.dt)
    if not _flags(trial):
        assert _track_gap(trial, mj) < 1e-3 + PUSH_TIMING


@pytest.mark.alone
def test_the_assistive_controller_through_the_simulator_on_the_mujoco_track():
    config = DriveConfig(world="ur", controller="cooperative", time_limit=3.0)
    trial, seen, kin, status = _run(config, push_at=40, sensor=QUIET)
    mj = _mujoco_same_push(trial, DriveConfig(controller="cooperative", time_limit=3.0), push_at=40)
    assert trial.meta.extra["ended"] == "time_limit", trial.meta.extra["stop_message"]
    assert status["out_of_limits"] == 0
    flags = _flags(trial)
    assert not _unexplained(trial), fault_names(flags)
    _every_command_inside_the_limits(seen, kin, config.dt)
    if not flags:
        assert _track_gap(trial, mj) < 1e-3 + PUSH_TIMING


def _every_command_inside_the_limits(seen, kin, dt) -> None:
    limits, prev, bad = SafetyLimits(), np.zeros(6), []
    for k, (qd, q, pose) in enumerate(seen):
        bad += [f"tick {k}: {b}" for b in within_limits(qd, prev, kin.forward_and_jacobian(q)[2], pose, limits, dt)]
        prev = qd
    assert bad == []


# ------------------------------------------------------------------ faults


FAULTS = {
    # name: (what the test does at tick 60, ended, words of the message, ticks after the fault it may take:
    # a link is lost after link_timeout (0.1 s, 13 ticks) without data, a jittery one once a quarter of
    # the last second's samples came late)
    # (the safety stops: seen within a tick or two; 6 where the machine stalls the loop: CI at ff0cb5a saw a protective
    # stop 5 ticks on, two at a time with the other realtime tests; a stop not seen runs on until speedJ is refused)
    "protective stop": (lambda sim: sim.protective_stop(), "robot_stop", "Protective stop", 6),
    "emergency stop": (lambda sim: sim.emergency_stop(), "robot_stop", "Emergency stop", 6),
    "program stopped on the pendant": (lambda sim: sim.stop_program(), "world_error", "teach pendant", 3),
    "coassist hangs 0.5 s (watchdog)": (lambda sim: time.sleep(0.5), "world_error", "watchdog", 2),
    "dropped connection": (lambda sim: sim.drop_connections(1.0), "link_lost", "lost", 2),
    "stream stops": (lambda sim: sim.stall(), "link_lost", "no new data", 16),
    "stream 0.2 s late": (lambda sim: sim.set_stream_delay(0.2), "link_lost", "no new data", 16),
    "stream jitters 60 ms": (lambda sim: sim.set_stream_delay(0.0, 0.06), "link_lost", "irregularly", 250),
}


@pytest.mark.parametrize("name", list(FAULTS))
def test_each_fault_ends_in_a_controlled_stop_with_the_trial_kept_and_what_to_do(name):
    inject, ended, words, within = FAULTS[name]
    for _ in range(3):  # a run that ended before the fault was injected: a stall of this machine, again
        with simulator() as sim:

            def on_tick(k, state, out, sim=sim):
                if k == 0:  # the hand pushes from the run's start (drive zeroes the sensor before it, hands off)
                    sim.push([10.0, 0.0, 0.0])
                if k == 60:
                    inject(sim)

            with realtime_priority():  # ur-rtde's receive threads, started here, inherit it
                world = URRTDEWorld(sim.host, frequency=125.0)
                try:
                    trial = drive(
                        DriveConfig(world="ur", controller="manual", time_limit=4.0), world=world, on_tick=on_tick
                    )
                except RobotLinkError as exc:  # the stream stalled while the sensor was zeroed (CI at load 3.5)
                    if "no new data" not in str(exc):
                        raise
                    world.close()
                    trial = None
                    continue
            t = time.monotonic()
            world.close()  # on any link, dead or alive: never raises, never hangs
            closed_in = time.monotonic() - t
            status = sim.status()
        if trial.n_samples > 60:
            break
    assert trial is not None, "the stream stalled before every run of three"
    extra = trial.meta.extra
    assert extra["ended"] == ended, extra.get("stop_message")
    message = extra["stop_message"]
    assert words in message and "rerun" in message and "\n" not in message
    assert 61 <= trial.n_samples <= 61 + within  # the run before it kept; it ended as soon as it was seen
    assert not status["moving"] and max(abs(v) for v in status["qd"]) < 1e-3  # the arm at rest
    assert closed_in < 5.0 and status["out_of_limits"] == 0


@pytest.mark.alone
def test_the_watchdog_stops_the_arm_within_its_timeout_when_coassist_hangs():
    with simulator() as sim, realtime_priority():
        world = URRTDEWorld(sim.host, frequency=125.0, watchdog_hz=10.0)
        world.read()
        for _ in range(50):  # moving at 0.3 rad/s
            world.read()
            world.apply(Command(qd=[0.3, 0, 0, 0, 0, 0]))
        time.sleep(0.4)  # the loop hangs: nothing reaches the controller
        status = sim.status()
        with pytest.raises(URProgramStopped, match="watchdog"):
            world.apply(Command(qd=[0.3, 0, 0, 0, 0, 0]))
        world.close()
    # fired once the register had been silent for the timeout (0.1 s) and at most a cycle more
    assert 0.1 <= status["watchdog_silence"] <= 0.1 + 0.004
    # and the arm was at rest 0.3 / 10 rad/s² = 30 ms later (within the timeout again)
    assert status["watchdog_rest_after"] <= 0.04 and not status["moving"]


def test_connecting_names_what_is_wrong_remote_control_and_old_software():
    with simulator() as sim:  # a 127.x.y.z address: ur-rtde checks remote control (it skips 127.0.0.1)
        sim.set_remote_control(False)
        with pytest.raises(RobotLinkError, match="not in remote control: switch it to Remote Control"):
            URRTDEWorld(sim.host)
    with simulator(version=(3, 3, 0, 0), series="cb3") as sim:  # before the output registers (3.4)
        with pytest.raises(RobotLinkError, match=r"runs URSoftware 3\.3\.0\.0.*needs PolyScope 3\.4 or 5\.0"):
            URRTDEWorld(sim.host)


def test_close_after_a_protective_stop():
    with simulator() as sim:
        world = URRTDEWorld(sim.host, frequency=125.0)
        world.read()
        sim.protective_stop()
        time.sleep(0.05)
        state = world.read()
        assert state.protective_stop and "Protective stop" in world.stop_detail
        t = time.monotonic()
        world.close()
        assert time.monotonic() - t < 3.0  # speedStop / stopScript answer at once (the program stopped)
