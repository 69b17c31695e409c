"""The MuJoCo model of the UR5 with its force/torque sensor and the carried object.

The UR5 entry of :mod:`coassist.robot.arm_mjcf` (which builds every arm of the registry
the same way, and holds the tools: ``build_arm_model("ur5", tool)``); this module keeps
the UR5's names and constants.

Source: example-robot-data's ``ur5_robot.urdf`` (the installed ``example-robot-data``
package; its DAE visuals are dropped, the STL collision meshes are kept as visuals).
Nothing is downloaded; the meshes are read from the installed package.

Frames. The MuJoCo world frame is the UR controller's *base* frame (x forward, z up;
:mod:`coassist.runtime.world`), which is the URDF's ``base_link`` turned by π about z:
the robot's root body is rotated by π about z. At q = 0 the flange (``tool0``) then sits
at (a2 + a3, −(d4 + d6), d1 − d5) = (−0.81725, −0.19145, −0.00549) m of the DH table.

Below the flange (``tool0``, z out of the flange)::

    tool0 ── site ft_sensor (at the flange, tool0's axes; sensors ft_force, ft_torque)
      └── body tool (welded): the object and its mount, one rigid body
            ├── site handle  where the hand grasps (the operator's wrench acts here)
            └── site tcp     the tool centre point (tool_pose)

The force and torque sensors measure the interaction between the subtree below the
sensor (tool0 + tool) and the wrist. The tools, in the tool0 frame (the world chooses
a start pose with the tool straight down and tool x = base x, so tool y = −base y and
the objects' base-frame offsets of :mod:`coassist.scenario.objects` enter with y flipped):

- ``handle``: a 3D-printed cylinder handle, MOUNT_MASS kg, 0.12 m long; hand and TCP
  at its middle (0, 0, 0.06).
- ``board``: a vacuum cup (MOUNT_MASS kg, 0.05 m) holding the plywood board below it,
  the board's centre at the object's ``center_offset`` from the cup, the hand at its
  ``grasp_offset`` (0.61 m from the cup, the board's near edge). The TCP is the cup
  (0, 0, 0.05): the task paths are the robot's tip paths, as in the point-mass world;
  the rubber cup's torsion (the point-mass world's yaw mode) is not modelled — the
  board is rigid here.
- ``heavy``: a mounting plate (MOUNT_MASS kg) and the steel block held at its centre;
  hand and TCP at the block's centre.

Joint servos (a UR's ``speedJ``): each joint has a torque motor (``ctrl`` is the joint
torque [N·m]) clipped to the UR5 torque limits (150, 150, 150, 28, 28, 28 N·m).
:class:`coassist.robot.mujoco_world.MujocoUR5World` computes the torque every physics
step (computed torque, the UR controller's own dynamic model)::

    τ = M(q) [a_ref + 2ω (v_ref − q̇) + ω² (q_ref − q)] + c(q, q̇)

where the reference joint velocity v_ref follows the command through a first-order lag
of ``servo_time_constant`` (a_ref its derivative, q_ref its integral) and c is gravity
and Coriolis (``qfrc_bias``, the gravity compensation a UR does internally). The joint
velocity follows the command with that lag, and every joint-space mode of the error is
critically damped at ω (``servo_bandwidth``): stiff against the hand, as the real geared
arm, without back-driving. The model stores ``servo_time_constant`` as a numeric.

Loads: at the default start the board's weight takes 23 of wrist 1's 28 N·m (its COM
is 0.2 m off the cup), so brisk wrist motions with the board saturate wrist 1 and the
arm lags its command, as a real UR5 would (or stop). The URDF's wrist inertias are
large (0.11–0.22 kg·m² for 1.2 kg links); the computed-torque servo hides them.

Collisions are off (contype = conaffinity = 0 on every geom): free-space pHRI.
"""

from __future__ import annotations

import numpy as np

from coassist.robot.arm_mjcf import (
    MOUNT_MASS,
    TOOLS,
    ToolGeometry,
    tool_geometry,
    urdf_joint_limits,
)
from coassist.robot.arms import get_arm
from coassist.robot.kinematics import ur5_urdf_path  # one place knows where the URDF is installed

__all__ = [
    "MOUNT_MASS",
    "Q_SEED",
    "TOOLS",
    "TORQUE_LIMITS",
    "ToolGeometry",
    "tool_geometry",
    "ur5_urdf_path",
]

#: UR5 joint torque limits [N·m] (the URDF's ``effort``, what the model's motors clip to; the
#: arm registry reads the URDF the same way).
TORQUE_LIMITS = np.array(urdf_joint_limits("ur5")[1])
#: The seed of the start pose's IK: elbow up, wrist down, tool down, the handle's TCP at
#: the middle of the tasks' workspace ((0.15, −0.615, 0.2) m): the registry's UR5 home.
Q_SEED = np.array(get_arm("ur5").home)
