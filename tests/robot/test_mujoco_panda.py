"""The MuJoCo Panda (``--world mujoco --robot panda``): a redundant arm under the same tick.

MG renders its admittance on 7 joints, the null space holds the posture (the self-motion
decays as e^(−k t) with the tool still), every command stays inside the joint limits, the
assistive controller saves force on the Panda as on the UR5, and ``--robot`` is checked
against the world.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the Panda kinematics need the robot extra: pip install 'coassist[robot]'")

from typer.testing import CliRunner  # noqa: E402

from coassist.cli import app  # noqa: E402
from coassist.interfaces import Fault  # noqa: E402
from coassist.metrics import f_rms  # noqa: E402
from coassist.robot.arm_mjcf import urdf_joint_limits  # noqa: E402
from coassist.robot.arms import NullSpacePosture, arm_kinematics, get_arm  # noqa: E402
from coassist.robot.drive import DriveConfig, drive  # noqa: E402
from coassist.robot.mujoco_world import FTSensorModel, MujocoArmWorld  # noqa: E402
from coassist.runtime.operators import ScriptedForce  # noqa: E402
from coassist.runtime.safety_limits import SafetyLimits  # noqa: E402

D = 100.0  # the preset's damping [N·s/m]
DEADBAND = 0.2  # the wrench pipeline's force deadband [N] (WrenchConfig default)
DT = 0.008
PUSH_X = ScriptedForce.constant((10.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def _inside_joint_limits(trial) -> None:
    # the safety layer's limits (π/2 rad/s, 8 rad/s²) below the Panda's own (2.175 / 2.61 rad/s), but for the
    # acceleration: every joint held to the Panda's smallest (joint 2's 7.5 rad/s²; the default 8 let it take 7.84)
    lim = SafetyLimits()
    qd = trial.joint_velocity
    assert np.abs(qd).max() <= lim.joint_velocity + 1e-12
    assert min(get_arm("panda").joint_acceleration_limit) == 7.5
    assert np.abs(np.diff(np.vstack([np.zeros(7), qd]), axis=0)).max() <= 7.5 * DT + 1e-12
    assert (np.abs(qd) <= urdf_joint_limits("panda")[2]).all()
    # and the joints inside their range (the null-space scaling keeps 0.05 rad)
    rng = arm_kinematics("panda").joint_position_limit
    assert (trial.joints > rng[:, 0] + 0.05 - 1e-9).all() and (trial.joints < rng[:, 1] - 0.05 + 1e-9).all()


@pytest.fixture(scope="module")
def mg_push():
    return drive(DriveConfig(robot="panda", controller="manual", time_limit=2.0), operator=PUSH_X)


def test_the_model_is_the_panda_with_its_limits():
    world = MujocoArmWorld("handle", robot="panda")
    m = world.model
    assert (m.nq, m.nu, world.n_joints) == (7, 7, 7)
    np.testing.assert_array_equal(m.actuator_forcerange[:, 1], [87, 87, 87, 87, 12, 12, 12])  # datasheet [N·m]
    np.testing.assert_array_equal(world.velocity_limits, get_arm("panda").joint_velocity_limit)
    # MuJoCo's TCP and pinocchio's (two engines reading the URDF; the FK itself is checked
    # against Franka's DH table in test_arms.py) agree at the start and at random joints
    kin = world.kinematics()
    assert isinstance(kin, NullSpacePosture)
    state = world.read()
    p, _ = kin.forward(state.q)
    np.testing.assert_allclose(p, state.tool_pose[:3], atol=1e-9)
    np.testing.assert_allclose(kin.kinematics.pose(state.q)[3:], state.tool_pose[3:], atol=1e-9)
    np.testing.assert_allclose(kin.kinematics.jacobian(state.q), world.tcp_jacobian(), atol=1e-9)
    world.close()


def test_mg_with_a_constant_push_settles_at_f_over_d(mg_push):
    # M a + D v = F − deadband: 9.8 N / 100 N·s/m = 0.098 m/s (time constant M/D = 0.1 s, so
    # settled long before the last 0.5 s); 1 %: the sensor's 0.05 N noise averages out over 60 ticks
    assert mg_push.meta.extra["ended"] == "time_limit" and mg_push.meta.origin == "mujoco"
    assert mg_push.meta.extra["robot"] == "panda"
    assert mg_push.velocity[-60:, 0].mean() == pytest.approx((10.0 - DEADBAND) / D, rel=0.01)
    assert np.abs(mg_push.velocity[-60:, 1]).max() < 2e-3
    assert mg_push.fault.max() == 0  # nothing intervened
    assert mg_push.joints.shape == (250, 7)
    _inside_joint_limits(mg_push)


def test_the_null_space_pulls_the_posture_back_with_the_tool_still():
    # The posture target moved 0.1 rad along the null space at the start: with no hand force the
    # tool must not move while the joints follow q̇ = (I − J⁺J) k (q₀ − q), an error decaying as
    # e^(−k t) (k = 1/s). 10 % of the error: the null direction turns as the arm moves and the
    # joint servo lags 20 ms.
    class Offset(MujocoArmWorld):
        delta = np.zeros(7)

        def kinematics(self):
            k = super().kinematics()
            return NullSpacePosture(k.kinematics, self.q_start + self.delta, gain=self.posture_gain)

    zero = ScriptedForce.constant((0.0,) * 6)
    config = DriveConfig(robot="panda", controller="manual", time_limit=3.0)
    quiet = FTSensorModel(noise_force=0.0, noise_torque=0.0)
    # (0.25, 0, 0.4): the linear task's start moved to the Panda (drive.move_tasks)
    world = Offset("handle", robot="panda", operator=zero, start=(0.25, 0.0, 0.4), sensor=quiet)
    J = world.kinematics().kinematics.jacobian(world.q_start)
    delta = 0.1 * np.linalg.svd(J)[2][-1]  # the unit null vector of the 6 × 7 Jacobian
    world.delta = delta
    trial = drive(config, world=world, operator=zero)
    world.close()
    t = np.arange(trial.n_samples) * DT
    err = np.linalg.norm(trial.joints[0] + delta - trial.joints, axis=1)
    late = t > 0.3  # after the acceleration limit's ramp
    np.testing.assert_allclose(err[late], 0.1 * np.exp(-t[late]), rtol=0.1)
    assert np.abs(trial.pose - trial.pose[0]).max() < 1e-5  # the tool stays put (x-y [m])
    seen = Fault(int(np.bitwise_or.reduce(trial.fault)))
    assert seen & ~Fault.JOINT_ACCELERATION_LIMIT == Fault.NONE, repr(seen)  # only the start's ramp
    _inside_joint_limits(trial)


def test_the_assistive_controller_saves_force_on_the_panda():
    # the simulated operator (user 0) on the linear task moved to the Panda's reach; measured:
    # 1.01 N (assistive, oracle intent) against MG's 4.02 N (seed 1)
    force = {}
    for ctrl, intent in (("cooperative", "oracle"), ("manual", "nominal")):
        tr = drive(DriveConfig(robot="panda", controller=ctrl, intent=intent, seed=1))
        assert tr.meta.extra["ended"] == "target" and tr.fault.max() == 0
        _inside_joint_limits(tr)
        force[ctrl] = f_rms(tr.effort_h)
    assert force["cooperative"] < 0.7 * force["manual"], force


@pytest.mark.parametrize(
    ("world", "robot", "known"),
    [
        ("ur", "panda", "('ur5',)"),
        ("mujoco", "kuka", "('ur5', 'panda')"),
        ("franka", "ur5", "('panda', 'fr3')"),
    ],
)
def test_robot_is_checked_against_the_world(world, robot, known):
    with pytest.raises(ValueError) as info:
        DriveConfig(world=world, robot=robot)
    assert str(info.value) == f"DriveConfig.robot must be one of {known} with world {world!r}, got {robot!r}"
    result = CliRunner().invoke(app, ["drive", "--world", world, "--robot", robot], terminal_width=80)
    assert result.exit_code == 2 and "Traceback" not in result.output
    lines = [ln for ln in result.output.splitlines() if ln.startswith("error:")]
    assert lines == [f"error: --robot must be one of {known} with world {world!r}, got {robot!r}"]


def test_the_world_default_robots():
    assert DriveConfig().robot == "ur5" and DriveConfig(world="franka").robot == "panda"


def test_a_panda_run_is_written_as_mcap_with_its_seven_joints(tmp_path):
    pytest.importorskip("rosbags", reason="MCAP needs the bags extra")
    from coassist.data import read_trial
    from coassist.data.bags import load_bag_trial

    out = tmp_path / "p.parquet"
    result = CliRunner().invoke(
        app,
        [
            "drive",
            "--robot",
            "panda",
            "--controller",
            "manual",
            "--time-limit",
            "0.5",
            "--out",
            str(out),
            "--mcap",
            "--no-plot",
        ],
    )
    assert result.exit_code == 0, result.output
    trial, back = read_trial(out), load_bag_trial(tmp_path / "p.mcap")
    assert trial.joints.shape[1] == 7
    assert back.pose.tobytes() == trial.pose.tobytes()


def test_the_trial_records_the_task_where_the_run_put_it(mg_push):
    """The tasks are laid out for the UR5 and moved to the Panda: its trial recorded the UR5's start, target and box
    (the figure drew the box 0.6 m off the path; σ and the overshoot read NaN for a run that reached its target; a
    review, 2026-12-07). They are recorded in the run's frame: the plan starts at the start, and the target and the
    box lie from it as the UR5's layout of the task has them."""
    from coassist.scenario.tasks import task_for_seed

    extra, plan = mg_push.meta.extra, mg_push.reference
    np.testing.assert_allclose(extra["start"], plan[0, :2], atol=1e-9)
    ur5 = task_for_seed("linear", 0)
    for name, there in (("target", extra["target"]), ("obstacle", extra["obstacle"]["center"])):
        here = ur5.target if name == "target" else ur5.obstacle.center
        np.testing.assert_allclose(np.asarray(there) - extra["start"], np.asarray(here) - ur5.start, atol=1e-9)


def test_a_tool_the_arm_cannot_hold_is_refused_naming_the_joint():
    # the Panda's 12 N·m wrist under the 8 kg board: it fell from the first tick, and the sensor read the fall as
    # pushes of up to 169 N (a review); the heavy block it holds (0.95 × at its start), the UR5 the board (0.82 ×)
    with pytest.raises(ValueError, match=r"the panda cannot hold the board: at its start its joint \d needs .* N·m"):
        MujocoArmWorld("board", robot="panda")
    for robot, tool in (("panda", "heavy"), ("ur5", "board")):
        MujocoArmWorld(tool, robot=robot).close()
