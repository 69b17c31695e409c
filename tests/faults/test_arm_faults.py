"""The fault table of the UR (``test_runtime_faults.CASES``) on the 7-joint Panda.

Every case runs on the MuJoCo Panda (``MujocoArmWorld(robot="panda")``, the null-space
posture in the tick), and the cases that concern what the robot link delivers (the
wrench faults, the missed deadlines, a hand letting go at speed) run again on
:class:`~coassist.robot.franka_world.FrankaWorld`: the real franky client against
franky-sim on loopback (the predictor cases do not touch the world; the singular-pose
case pushes for 5 s of wall time — both stay on MuJoCo to keep the suite fast; franky-sim
runs are cut to 1.6 s). The
check is the UR's: the loop does not crash, the fault is flagged, the run stops where the
case says, and no joint velocity command sent is outside a limit
(:func:`coassist.runtime.safety_limits.within_limits` with the Jacobian and pose the layer saw).

Run as a script for the table of cases: ``python tests/faults/test_arm_faults.py``.
"""

from __future__ import annotations

import importlib.util
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the Panda kinematics need the robot extra: pip install 'coassist[robot]'")

from coassist.interfaces import Fault  # noqa: E402
from coassist.robot.drive import ZERO_READINGS, DriveConfig, drive  # noqa: E402
from coassist.robot.mujoco_world import MujocoArmWorld  # noqa: E402
from coassist.runtime.safety_limits import SafetyLimits, within_limits  # noqa: E402

TESTS = Path(__file__).resolve().parents[1]


def _load(path: Path):
    """A sibling test module by path (the suite runs with --import-mode=importlib: no package)."""
    name = f"_coassist_tests_{path.stem}"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


table = _load(TESTS / "faults" / "test_runtime_faults.py")
DT = table.DT
#: The cases run on franky-sim too (module docstring).
ON_FRANKY = (
    "NaN wrench (10 ticks)",
    "±inf wrench (10 ticks)",
    "5 kN spike (1 tick)",
    "frozen sensor",
    "50 consecutive deadline misses",
    "hand lets go at full speed",
)
START = (0.25, 0.0, 0.4)  # the linear task's start moved to the Panda (robot.drive.move_tasks)


def _limits(start) -> SafetyLimits:
    # the UR table's box relative to its start (-0.1, -0.615, 0.2): 0.5-0.8 m each way in x-y,
    # so that the arm pushed along −y stretches out before it meets the face
    s = np.asarray(start, dtype=float)
    return SafetyLimits(workspace_lower=tuple(s + (-0.5, -1.0, -0.2)), workspace_upper=tuple(s + (0.6, 0.5, 0.3)))


class FaultyArm(table.FaultyWorld):
    """The UR table's FaultyWorld around any MuJoCo arm (its joints and kinematics)."""

    def __init__(self, inner, inject=None, overrun_ticks=range(0)) -> None:
        super().__init__(inner, inject, overrun_ticks)
        self.n_joints = inner.n_joints

    def kinematics(self):
        return self.inner.kinematics()


def _violations(trial, kin, poses, limits) -> list[str]:
    out = []
    qd, q = trial.joint_velocity, trial.joints
    stopped_at = trial.n_samples - 1 if trial.meta.extra["ended"] == "safety_stop" else None
    for k in range(trial.n_samples):
        if k == stopped_at:
            continue  # a stop is not a velocity command: the world brakes with its own stop
        J = kin.forward_and_jacobian(q[k])[2]
        prev = qd[k - 1] if k else np.zeros(q.shape[1])
        out.extend(f"tick {k}: {b}" for b in within_limits(qd[k], prev, J, poses[k], limits, DT))
    return out


def _check(case, trial, violations) -> None:
    assert violations == []
    seen = Fault(int(np.bitwise_or.reduce(trial.fault)))
    assert seen & case.expect == case.expect, f"expected {case.expect!r}, saw {seen!r}"
    assert (trial.meta.extra["ended"] == "safety_stop") == case.stops, trial.meta.extra["ended"]


def run_mujoco(case):
    """One case on the MuJoCo Panda; returns (trial, violations)."""
    limits = _limits(START)
    config = DriveConfig(robot="panda", controller="manual", task="linear", time_limit=case.time_limit, limits=limits)
    inner = MujocoArmWorld("handle", robot="panda", control_dt=DT, operator=case.operator, start=START)
    world = FaultyArm(inner, case.inject, case.overrun)
    source = None if case.predictor is None else case.predictor(50)
    try:
        trial = drive(config, operator=case.operator, world=world, intent_source=source)
        violations = _violations(trial, inner.kinematics(), world.poses, limits)
    finally:
        world.close()
    return trial, violations


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
@pytest.mark.parametrize("case", table.CASES, ids=[c.name for c in table.CASES])
def test_mujoco_panda(case):
    trial, violations = run_mujoco(case)
    assert trial.joint_velocity.shape[1] == 7
    _check(case, trial, violations)


# ---------------------------------------------------------------------------- franky-sim


class ScriptedSensor:
    """An F/T sensor on franky-sim's hand: the case's scripted hand force, applied to the simulated
    hand body at the same time (zero at the readings drive zeroes the pipeline on, its first ZERO_READINGS)."""

    #: Reading noise [N, N·m], seeded: a real sensor's noise moves some channel every sample, so the
    #: pipeline's frozen-sensor check (on for measured sensors) only trips on the frozen case.
    NOISE = 0.05

    def __init__(self, server, operator) -> None:
        self.server, self.operator, self.n, self.sent = server, operator, 0, np.zeros(3)
        self.rng = np.random.default_rng(0)

    def read(self):
        self.n += 1
        k = self.n - ZERO_READINGS - 2  # the loop's tick (read 1: the test's own, for the limits; then drive's)
        w = np.zeros(6) if k < 0 else np.asarray(self.operator.force(k * DT, None, None), dtype=float)
        if (w[:3] != self.sent).any():
            self.server.push(w[:3])  # the hand pushes the clean force; the sensor reads it with noise
            self.sent = w[:3].copy()
        return w + self.rng.normal(0.0, self.NOISE, 6), np.eye(3), self.n


class FaultyFranka(table.FaultInjector):
    """FrankaWorld with the case's fault injected into what the tick reads (and the loop's clock);
    the robot's clock still paces the loop."""

    def __init__(self, inner, inject=None, overrun_ticks=range(0)) -> None:
        super().__init__(inner, inject, overrun_ticks)
        self.tcp_offset_pose = inner.tcp_offset_pose

    stop_detail = property(lambda self: self.inner.stop_detail)

    def kinematics(self):
        return self.inner.kinematics()


@pytest.fixture(scope="module")
def franky_sim():
    pytest.importorskip("franky", reason="the Franka world needs franky: pip install 'coassist[franka]'")
    pytest.importorskip("franky_sim", reason="the tests need franky-sim: pip install 'coassist[franka]'")
    return _load(TESTS / "robot" / "test_franka_world.py")


def run_franky(case, franky_sim):
    """One case on FrankaWorld against franky-sim (``franky_sim``: test_franka_world's module);
    returns (trial, violations)."""
    from coassist.robot.franka_world import FrankaWorld

    server = franky_sim.SimServer()
    try:
        inner = FrankaWorld(  # franky-sim is an FR3; the cases are not about the link (its timeout: test_franka_world)
            server.host,
            arm="fr3",
            ft_sensor=ScriptedSensor(server, case.operator),
            link_timeout=franky_sim.LINK_TIMEOUT,
        )
        limits = _limits(inner.read().tool_pose[:3])
        world = FaultyFranka(inner, case.inject, case.overrun)
        config = DriveConfig(
            world="franka", robot="fr3", controller="manual", task="linear", time_limit=case.time_limit, limits=limits
        )
        try:
            trial = drive(config, world=world)
            violations = _violations(trial, inner.kinematics(), world.poses, limits)
        finally:
            world.close()
    finally:
        server.close()
    return trial, violations


@pytest.mark.realtime  # franky-sim's loop: run alone (tests/robot/test_franka_world.py)
@pytest.mark.parametrize("case", [c for c in table.CASES if c.name in ON_FRANKY], ids=list(ON_FRANKY))
def test_franka_through_franky_sim(case, franky_sim):
    # 1.6 s: every one of these faults starts by tick 150 (1.2 s) and is flagged within a tick
    case = replace(case, time_limit=min(case.time_limit, 1.6))
    trial, violations = run_franky(case, franky_sim)
    assert trial.meta.origin == "franka" and trial.joint_velocity.shape[1] == 7
    _check(case, trial, violations)


if __name__ == "__main__":
    franky = _load(TESTS / "robot" / "test_franka_world.py")
    print("| case | world | flags raised | ended | commands | outside a limit |")
    print("|---|---|---|---|---|---|")
    for case in table.CASES:
        runs = [("MuJoCo Panda", run_mujoco(case))]
        if case.name in ON_FRANKY:
            runs.append(("franky-sim", run_franky(replace(case, time_limit=min(case.time_limit, 1.6)), franky)))
        for where, (trial, violations) in runs:
            seen = Fault(int(np.bitwise_or.reduce(trial.fault)))
            names = ", ".join(f.name for f in Fault if f and f & seen)
            print(
                f"| {case.name} | {where} | {names} | {trial.meta.extra['ended']} | {trial.n_samples} | "
                f"{len(violations)} |"
            )
