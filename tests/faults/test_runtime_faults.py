"""Fault injection on the MuJoCo UR5: no bad input gets past the safety layer.

Each case runs the whole loop (``coassist.robot.drive``) with a fault injected between
the world and the tick, and checks: the loop does not crash, every joint velocity
command sent is inside every limit (:func:`coassist.runtime.safety_limits.within_limits`,
with the Jacobian and pose the layer saw), and the fault is flagged in the log.

Run as a script for the table of cases: ``python tests/faults/test_runtime_faults.py``.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")

from coassist.interfaces import Fault  # noqa: E402
from coassist.robot.drive import DriveConfig, drive  # noqa: E402
from coassist.robot.mujoco_world import MujocoUR5World  # noqa: E402
from coassist.runtime.operators import ScriptedForce  # noqa: E402
from coassist.runtime.safety_limits import SafetyLimits, within_limits  # noqa: E402

DT = 0.008
LIMITS = SafetyLimits(workspace_lower=(-0.6, -1.1, 0.0), workspace_upper=(0.7, -0.1, 0.5))
PUSH = ScriptedForce.constant((15.0, 0.0, 0.0, 0.0, 0.0, 0.0))


class FaultInjector:
    """Any joint-velocity world with a fault injected into what the tick reads (and the loop's clock).
    ``realtime`` is off: a loaded test machine's own late ticks would add deadline misses that are
    not the case's fault."""

    command_space, realtime = "joint_velocity", False

    def __init__(self, inner, inject=None, overrun_ticks=range(0)) -> None:
        self.inner, self.inject, self.overrun_ticks = inner, inject, overrun_ticks
        self.dt, self.n_joints = inner.dt, inner.n_joints
        self.k = 0
        self.poses: dict[int, np.ndarray] = {}  # tick → the pose the tick read (drive's first read is overwritten)
        self.last_overrun = 0.0

    def read(self):
        state = self.inner.read()
        if self.inject is not None:
            self.inject(self.k, state)
        self.poses[self.k] = np.array(state.tool_pose, dtype=float)
        return state

    def apply(self, command):
        self.last_overrun = 0.004 if self.k in self.overrun_ticks else 0.0
        self.inner.apply(command)
        self.k += 1

    def stop(self):
        self.inner.stop()

    def close(self):
        self.inner.close()

    # the drive's ArmWorld: the inner arm's kinematics; no payload removed and the frozen-sensor
    # check on (the wrapper hides the inner world's sensor), unless a subclass says otherwise
    noise_free_sensor = False

    def kinematics(self):
        return self.inner.kinematics()

    def tool_mass_and_com(self):
        return 0.0, np.zeros(3)


class FaultyWorld(FaultInjector):
    """The MuJoCo UR5 world with a fault injected (the MuJoCo parts drive reads passed through)."""

    def __init__(self, inner: MujocoUR5World, inject=None, overrun_ticks=range(0)) -> None:
        super().__init__(inner, inject, overrun_ticks)

    operator = property(lambda self: self.inner.operator, lambda self, v: setattr(self.inner, "operator", v))
    model = property(lambda self: self.inner.model)
    data = property(lambda self: self.inner.data)

    def hand_pose(self):
        return self.inner.hand_pose()

    def tool_mass_and_com(self):
        return self.inner.tool_mass_and_com()

    @property
    def hand_wrench(self):
        return self.inner.hand_wrench


class FakeRealtimePredictor:
    """The RealtimePredictor's contract with a real worker thread that can hang or emit NaN."""

    def __init__(self, horizon: int, hang=range(0), nan=range(0)) -> None:
        self.horizon, self.history, self.errors, self.model_id = horizon, 10, 0, "fake"
        self.hang, self.nan = hang, nan
        self._k = -1
        self._latest: tuple[int, np.ndarray] | None = None
        self._lock = threading.Lock()

    def reset(self, context=None) -> None:
        self._k = -1
        self._latest = None

    def tick(self, sample, nominal):
        self._k += 1
        k = self._k
        if k >= self.history and k not in self.hang:  # the worker finished this tick's window
            if k in self.nan:
                self.errors += 1  # a NaN prediction is counted and dropped, as the real one does
            else:
                with self._lock:
                    self._latest = (k, np.array(nominal, dtype=float))
        latest = self._latest
        age = -1 if latest is None else k - latest[0]
        if not 0 <= age <= 10:
            return np.array(nominal, dtype=float), Fault.PREDICTION_FALLBACK, -1
        pos = latest[1]
        pos = np.concatenate([pos[age:], np.repeat(pos[-1:], age, axis=0)]) if age else pos.copy()
        return pos, Fault.PREDICTION_STALE if age else Fault.NONE, age


def _real_predictor(runner, history: int = 10):
    """The real RealtimePredictor (worker thread, plausibility checks, health) on a stand-in network."""
    from types import SimpleNamespace

    from coassist.intent.realtime import RealtimeConfig, RealtimePredictor

    def make(H):
        model = SimpleNamespace(horizon=H, history=history, n_dof=2, dt=DT)
        return RealtimePredictor(model, RealtimeConfig(threaded=True), runner=lambda w: runner(w, H))

    return make


def _absurd(window, H):
    return np.full((H, 2), 1e6)  # finite, a kilometre away: must never be used


def _dies(window, H):
    raise SystemExit  # ends the worker thread: the predictor must report itself dead


def _set(rows, fn):
    def inject(k, state):
        if k in rows:
            fn(k, state)

    return inject


def _frozen(start):
    held = {}

    def inject(k, state):
        if k == start:
            held["w"], held["seq"] = state.wrench.copy(), state.wrench_seq
        if k >= start:
            state.wrench = held["w"].copy()
            state.wrench_seq = held["seq"]

    return inject


def _frozen_live(start):
    """A stuck sensor whose messages still arrive: bit-identical values, a counter that moves."""
    held = {}

    def inject(k, state):
        if k == start:
            held["w"] = state.wrench.copy()
        if k >= start:
            state.wrench = held["w"].copy()

    return inject


def _nan_field(name):
    def fn(k, s):
        getattr(s, name)[:] = np.nan

    return fn


def _none_state(k, s):
    s.tool_pose = s.tool_twist = s.q = None


def _pose_jump(k, s):
    s.tool_pose = s.tool_pose + np.array([1.0, 0, 0, 0, 0, 0])  # the reported TCP 1 m away in x; the joints disagree


def _joint_glitch(k, s):
    q = np.array(s.q, dtype=float)  # a finite glitch (a second publisher, say): the tool pose disagrees
    q[0] += 0.3  # (any arm: six joints or seven)
    s.q = q


@dataclass
class Case:
    name: str
    expect: Fault  # flags that must appear
    inject: object = None
    operator: object = field(default_factory=lambda: PUSH)
    overrun: range = range(0)
    predictor: object = None
    start: tuple[float, float, float] | None = None
    time_limit: float = 2.0
    stops: bool = False  # the case must end in a safety stop


def _nan(k, s):
    s.wrench[:] = np.nan


def _inf(k, s):
    s.wrench[0] = np.inf if k % 2 else -np.inf


def _spike(k, s):
    s.wrench[0] = 5000.0


#: Robot-state glitches: flagged, held, logged; the trial is still written (test below).
GLITCH_TICKS = range(100, 110)
GLITCHES = [
    Case(
        "NaN tool pose (10 ticks)",
        Fault.NONFINITE_STATE | Fault.DECELERATING,
        _set(GLITCH_TICKS, _nan_field("tool_pose")),
    ),
    Case("NaN joints (10 ticks)", Fault.NONFINITE_STATE | Fault.DECELERATING, _set(GLITCH_TICKS, _nan_field("q"))),
    Case(
        "NaN tool twist (10 ticks)",
        Fault.NONFINITE_STATE | Fault.DECELERATING,
        _set(GLITCH_TICKS, _nan_field("tool_twist")),
    ),
    Case("state None (1 tick)", Fault.NONFINITE_STATE | Fault.DECELERATING, _set(GLITCH_TICKS[:1], _none_state)),
]

CASES = [
    Case("NaN wrench (10 ticks)", Fault.NONFINITE_WRENCH | Fault.DECELERATING, _set(range(100, 110), _nan)),
    Case("±inf wrench (10 ticks)", Fault.NONFINITE_WRENCH | Fault.DECELERATING, _set(range(100, 110), _inf)),
    Case("5 kN spike (1 tick)", Fault.WRENCH_SPIKE | Fault.DECELERATING, _set(range(150, 151), _spike)),
    Case("frozen sensor", Fault.SENSOR_STALE | Fault.DECELERATING | Fault.STOPPED, _frozen(100), stops=True),
    Case(
        "predictor hangs 1 s",
        Fault.PREDICTOR_STALLED | Fault.DECELERATING | Fault.STOPPED,
        predictor=lambda H: FakeRealtimePredictor(H, hang=range(100, 225)),
        stops=True,
    ),
    Case(
        "predictor returns NaN (5 ticks)",
        Fault.PREDICTOR_STALLED | Fault.DECELERATING,
        predictor=lambda H: FakeRealtimePredictor(H, nan=range(100, 105)),
    ),
    Case(
        "predictor returns 1e6 m (finite, absurd)",
        Fault.PREDICTOR_STALLED | Fault.DECELERATING | Fault.STOPPED,
        predictor=_real_predictor(_absurd),
        stops=True,
    ),
    Case(
        "predictor worker thread dies",
        Fault.PREDICTOR_STALLED | Fault.DECELERATING | Fault.STOPPED,
        predictor=_real_predictor(_dies),
        stops=True,
    ),
    Case(
        "pushed into a singular pose (arm stretched)",
        Fault.TOOL_SPEED_LIMIT | Fault.SINGULARITY,
        operator=ScriptedForce.constant((0.0, -40.0, 0.0, 0.0, 0.0, 0.0)),
        time_limit=5.0,
    ),
    Case(
        "hand lets go at full speed",
        Fault.TOOL_SPEED_LIMIT,
        operator=ScriptedForce.steps([(0.0, (40.0, 0, 0, 0, 0, 0)), (1.2, (0, 0, 0, 0, 0, 0))]),
    ),
    Case(
        "50 consecutive deadline misses",
        Fault.DEADLINE_MISS | Fault.DECELERATING | Fault.STOPPED,
        overrun=range(100, 150),
        stops=True,
    ),
    Case(
        "frozen sensor, live counter (hand lets go at 0.8 s)",
        Fault.SENSOR_STALE | Fault.DECELERATING | Fault.STOPPED,
        _frozen_live(50),
        operator=ScriptedForce.steps([(0.0, (15.0, 0, 0, 0, 0, 0)), (0.8, (0, 0, 0, 0, 0, 0))]),
        stops=True,
    ),
    Case(
        "reported pose jumps +1 m in x (20 ticks)",
        Fault.STATE_MISMATCH | Fault.DECELERATING,
        _set(range(100, 120), _pose_jump),
    ),
    Case(
        "joint 1 reads +0.3 rad, the pose true (10 ticks)",
        Fault.STATE_MISMATCH | Fault.DECELERATING,
        _set(range(100, 110), _joint_glitch),
    ),
    *GLITCHES,
]


def run_case(case: Case):
    """Run one case; returns (trial, violations, world)."""
    config = DriveConfig(controller="manual", task="linear", time_limit=case.time_limit, limits=LIMITS)
    kwargs = {} if case.start is None else {"start": case.start}
    inner = MujocoUR5World("handle", control_dt=DT, operator=case.operator, **kwargs)
    world = FaultyWorld(inner, case.inject, case.overrun)
    source = None if case.predictor is None else case.predictor(50)
    try:
        trial = drive(config, operator=case.operator, world=world, intent_source=source)
        kin = inner.kinematics()
        violations = []
        qd, q = trial.joint_velocity, trial.joints
        stopped_at = trial.n_samples - 1 if trial.meta.extra["ended"] == "safety_stop" else None
        for k in range(trial.n_samples):
            if k == stopped_at:
                continue  # a stop is not a velocity command: the world brakes with its own stop
            J = kin.jacobian(q[k])
            prev = qd[k - 1] if k else np.zeros(6)
            bad = within_limits(qd[k], prev, J, world.poses[k], LIMITS, DT)
            violations.extend(f"tick {k}: {b}" for b in bad)
            # the acceleration limit by hand, whatever the state said (within_limits allows no exception to it)
            step = float(np.max(np.abs(qd[k] - prev)))
            if step > LIMITS.joint_acceleration * DT + 1e-9:
                violations.append(f"tick {k}: a joint step of {step:.4g} rad/s")
    finally:
        world.close()
    return trial, violations


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_fault_is_flagged_and_no_command_leaves_the_limits(case):
    trial, violations = run_case(case)  # the loop must not raise
    assert violations == []
    seen = Fault(int(np.bitwise_or.reduce(trial.fault)))
    assert seen & case.expect == case.expect, f"expected {case.expect!r}, saw {seen!r}"
    assert (trial.meta.extra["ended"] == "safety_stop") == case.stops, trial.meta.extra["ended"]


@pytest.mark.parametrize("case", GLITCHES, ids=[c.name for c in GLITCHES])
def test_a_state_glitch_is_held_and_the_file_says_which_ticks(case, tmp_path):
    """drive() returns the trial, it is written and read back, and its fault column flags
    NONFINITE_STATE on exactly the glitch's ticks; a bad pose or joint row holds the last good one."""
    from coassist.data import read_trial, write_trial

    trial, _ = run_case(case)
    back = read_trial(write_trial(trial, tmp_path / "t.parquet"))
    rows = list(GLITCH_TICKS[:1] if case.name.startswith("state None") else GLITCH_TICKS)
    assert np.flatnonzero(back.fault & int(Fault.NONFINITE_STATE)).tolist() == rows
    if "pose" in case.name or "None" in case.name:
        for k in rows:
            np.testing.assert_array_equal(back.pose[k], back.pose[rows[0] - 1])
    if "joints" in case.name or "None" in case.name:
        for k in rows:
            np.testing.assert_array_equal(back.joints[k], back.joints[rows[0] - 1])


if __name__ == "__main__":
    print("| case | flags raised | ended | commands | outside a limit |")
    print("|---|---|---|---|---|")
    for case in CASES:
        trial, violations = run_case(case)
        seen = Fault(int(np.bitwise_or.reduce(trial.fault)))
        names = ", ".join(f.name for f in Fault if f and f & seen)
        print(f"| {case.name} | {names} | {trial.meta.extra['ended']} | {trial.n_samples} | {len(violations)} |")
