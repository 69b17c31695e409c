"""The arm registry's data: one :class:`ArmDescription` per arm family, by name in :data:`ARMS`.

What differs between arms is data: where the URDF is (``example-robot-data``), the
flange frame, the joints to lock (a gripper's fingers), the base frame of the arm's
controller relative to the URDF root, the joint speed limits and a home pose. This module
holds only that data (nothing of the robot package below it), so the kinematics
(:mod:`coassist.robot.kinematics`) and the arms' shared machinery (:mod:`coassist.robot.arms`,
which re-exports these names) both build on it without importing each other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ARMS", "FRANKY_JOINT_ACCELERATION", "ArmDescription", "get_arm"]


@dataclass(frozen=True)
class ArmDescription:
    """One arm family.

    name : the registry key (``--robot``).
    urdf : path components under example-robot-data's ``robots/``.
    tip_frame : the flange frame in the URDF (the TCP offset is relative to it).
    n_joints : joints commanded.  locked : URDF joints fixed at 0 (fingers).
    base_signs : diagonal of the controller's base frame relative to the URDF root
        (a rotation about z by 0 or π).
    joint_velocity_limit : (n,) [rad/s] (datasheet).  joint_position_limit : (n, 2)
        [rad]; None: the URDF's.
    home : (n,) a comfortable start posture [rad] (the MuJoCo worlds' IK seed).
    mujoco_drop : URDF links left out of the MuJoCo model, with their subtrees (ROS
        frames, a gripper: the tools are mounted on the flange; :mod:`coassist.robot.arm_mjcf`).
    tool_speed_limit : [m/s] the arm's own largest TCP speed (the datasheet's; a safety
        limit above it is refused: it would limit nothing).
    joint_acceleration_limit : (n,) [rad/s²] the datasheet's joint accelerations; None where the
        maker publishes none (the UR's speedJ takes up to 40 rad/s²: the UR world checks it). The safety
        layer's one acceleration bound (‖q̇ − q̇⁻‖∞ ≤ a dt) is then at most the smallest of them, and a
        ``SafetyLimits.joint_acceleration`` above the largest is refused (it would limit no joint).
    task_centre : (3,) [m] where the MuJoCo worlds put the tasks, in the base frame: the
        centre of their x-y area and the height of their plane (the tasks are laid out
        for the UR5: (0.15, −0.615) at 0.2 m; an arm with another reach moves them).
    """

    name: str
    urdf: tuple[str, ...]
    tip_frame: str
    n_joints: int
    joint_velocity_limit: tuple[float, ...]
    home: tuple[float, ...]
    locked: tuple[str, ...] = ()
    base_signs: tuple[float, float, float] = (1.0, 1.0, 1.0)
    joint_position_limit: tuple[tuple[float, float], ...] | None = None
    mujoco_drop: tuple[str, ...] = ()
    task_centre: tuple[float, float, float] = (0.15, -0.615, 0.20)
    tool_speed_limit: float = 1.0
    joint_acceleration_limit: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        n = self.n_joints
        if not isinstance(n, int) or n < 6:
            raise ValueError(f"ArmDescription.n_joints must be an int >= 6, got {n!r}")
        for name in ("joint_velocity_limit", "home"):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != (n,) or not np.isfinite(v).all():
                raise ValueError(f"ArmDescription.{name} must be {n} finite numbers, got {getattr(self, name)!r}")
        if self.joint_acceleration_limit is not None:
            a = np.asarray(self.joint_acceleration_limit, dtype=float)
            if a.shape != (n,) or not (np.isfinite(a).all() and (a > 0.0).all()):
                raise ValueError(
                    f"ArmDescription.joint_acceleration_limit must be {n} finite numbers > 0 [rad/s²] or None, got "
                    f"{self.joint_acceleration_limit!r}"
                )
        if not (isinstance(self.tool_speed_limit, float) and 0.0 < self.tool_speed_limit < 10.0):
            raise ValueError(
                f"ArmDescription.tool_speed_limit must be a speed in (0, 10) m/s, got {self.tool_speed_limit!r}"
            )
        c = np.asarray(self.task_centre, dtype=float)
        if c.shape != (3,) or not np.isfinite(c).all():
            raise ValueError(f"ArmDescription.task_centre must be 3 finite numbers [m], got {self.task_centre!r}")
        if any(abs(s) != 1.0 for s in self.base_signs) or self.base_signs[2] != 1.0:
            raise ValueError(f"ArmDescription.base_signs must be (1, 1, 1) or (-1, -1, 1), got {self.base_signs!r}")


#: [rad/s²] What franky's own motion generator holds a Franka arm's joints to (its ``Robot.joint_acceleration_limit``,
#: libfranka's Panda figures, which franky 2.0 reports for franky-sim's FR3 too): through franky a joint is held to the
#: smaller of this and its arm's own (:func:`coassist.robot.drive.arm_limits`), or franky smooths what the layer sent.
FRANKY_JOINT_ACCELERATION = (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)

ARMS: dict[str, ArmDescription] = {
    # UR5 (CB3): UR's base frame is the URDF base_link turned by π about z (kinematics.py).
    "ur5": ArmDescription(
        name="ur5",
        urdf=("ur_description", "urdf", "ur5_robot.urdf"),
        tip_frame="tool0",
        n_joints=6,
        joint_velocity_limit=(np.pi,) * 6,
        home=(-1.1583, -1.9627, -1.5428, -1.2068, 1.5708, -2.7291),
        base_signs=(-1.0, -1.0, 1.0),
        joint_position_limit=((-2.0 * np.pi, 2.0 * np.pi),) * 6,
        mujoco_drop=("base",),  # the ROS "base" frame: the world frame is it already
        tool_speed_limit=1.0,  # UR5 datasheet: typical TCP speed 1 m/s
    ),
    # Franka Emika Panda: libfranka's base frame (O) is the URDF's panda_link0; the flange
    # (F) is panda_link8. Speed limits: Franka's datasheet (the URDF's velocity=).
    # Position limits: the URDF's (the datasheet's).
    "panda": ArmDescription(
        name="panda",
        urdf=("panda_description", "urdf", "panda.urdf"),
        tip_frame="panda_link8",
        n_joints=7,
        joint_velocity_limit=(2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61),
        home=(0.0, -0.785398, 0.0, -2.356194, 0.0, 1.570796, 0.785398),
        locked=("panda_finger_joint1", "panda_finger_joint2"),
        mujoco_drop=("panda_hand",),
        task_centre=(0.5, 0.0, 0.4),  # every task point reachable tool-down, > 0.2 rad from a limit
        tool_speed_limit=1.7,  # libfranka's Cartesian translation limit (franky: translation_velocity_limit.max)
        # libfranka's joint-space limits for the Panda (Franka's control parameters; franky.Robot's
        # joint_acceleration_limit): joint 2 the lowest
        joint_acceleration_limit=(15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0),
    ),
    # Franka Research 3: the Panda's kinematics (the same DH table and flange; franky-sim's
    # FR3 matches the Panda model to 1e-4 m, tests/robot/test_franka_world.py) with its own
    # joint limits: position and speed from the FR3 URDF of Franka's franka_description, as
    # shipped in the installed franky-sim 1.0.4 (franky_sim/assets/fr3.urdf, <limit lower=
    # upper= velocity=>; checked against that file in tests/robot/test_arms.py). Narrower
    # than the Panda's on joint 4 (upper −0.1169) and shifted on joint 6 ([0.4398, 4.6216]).
    # No MuJoCo model of its own (the MuJoCo worlds drive the Panda).
    "fr3": ArmDescription(
        name="fr3",
        urdf=("panda_description", "urdf", "panda.urdf"),
        tip_frame="panda_link8",
        n_joints=7,
        joint_velocity_limit=(2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26),
        home=(0.0, -0.785398, 0.0, -2.356194, 0.0, 1.570796, 0.785398),
        locked=("panda_finger_joint1", "panda_finger_joint2"),
        joint_position_limit=(
            (-2.9007, 2.9007),
            (-1.8361, 1.8361),
            (-2.9007, 2.9007),
            (-3.077, -0.1169),
            (-2.8763, 2.8763),
            (0.4398, 4.6216),
            (-3.0508, 3.0508),
        ),
        tool_speed_limit=1.7,  # what franky reports for franky-sim's FR3 (translation_velocity_limit.max)
        # Franka's FCI documentation, "Limits for Franka Research 3 (FR3)" (joint-space table, a necessary condition:
        # a command beyond it aborts the motion): 10 rad/s² on every joint (jerk 5000 rad/s³). franky-sim's FR3
        # reports the Panda's (15, 7.5, 10, 12.5, 15, 20, 20), which a real FR3 would refuse on joints 1 and 4–7
        joint_acceleration_limit=(10.0,) * 7,
    ),
}


def get_arm(name: str) -> ArmDescription:
    """The registered arm ``name``; ValueError naming the known ones otherwise."""
    try:
        return ARMS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown robot {name!r}; known: {', '.join(sorted(ARMS))}") from None
