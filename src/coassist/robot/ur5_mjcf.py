"""The MuJoCo model of the UR5 with its force/torque sensor and the carried object.

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
the objects' base-frame offsets of :mod:`coassist.sim.objects` enter with y flipped):

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

import importlib.metadata
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np

from coassist._checks import check_positive_scalar
from coassist.robot.kinematics import ur5_urdf_path  # one place knows where the URDF is installed
from coassist.sim.objects import get_object

__all__ = [
    "JOINT_NAMES",
    "MOUNT_MASS",
    "Q_SEED",
    "TOOLS",
    "TORQUE_LIMITS",
    "VELOCITY_LIMITS",
    "ToolGeometry",
    "build_ur5_model",
    "build_ur5_spec",
    "tool_geometry",
    "ur5_mjcf_xml",
    "ur5_urdf_path",
]

JOINT_NAMES = (
    "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint",
)
#: UR5 joint torque limits [N·m].
TORQUE_LIMITS = np.array([150.0, 150.0, 150.0, 28.0, 28.0, 28.0])
#: UR5 joint speed limits of the URDF [rad/s].
VELOCITY_LIMITS = np.array([3.15, 3.15, 3.15, 3.2, 3.2, 3.2])
#: Mass of each tool's mount (handle body, vacuum cup, mounting plate) [kg].
MOUNT_MASS = 0.3
#: The seed of the start pose's IK: elbow up, wrist down, tool down, the handle's TCP at
#: the middle of the tasks' workspace ((0.15, −0.615, 0.2) m).
Q_SEED = np.array([-1.1583, -1.9627, -1.5428, -1.2068, 1.5708, -2.7291])
TOOLS = ("handle", "board", "heavy")

_SHARE_REL = "cmeel.prefix/share"


@dataclass(frozen=True)
class _Part:
    name: str
    kind: str  # "cylinder" (axis along tool z) or "box"
    size: tuple[float, ...]  # MuJoCo half-sizes: cylinder (radius, half-length), box (3 half-sizes)
    pos: tuple[float, float, float]
    mass: float
    rgba: tuple[float, float, float, float]


@dataclass(frozen=True)
class ToolGeometry:
    """One tool in the tool0 frame [m, kg] (module docstring).

    parts : the rigid pieces (mount first). handle : the hand point. tcp : the default
    TCP. mass : their total mass.
    """

    name: str
    parts: tuple[_Part, ...]
    handle: tuple[float, float, float]
    tcp: tuple[float, float, float]

    @property
    def mass(self) -> float:
        return float(sum(p.mass for p in self.parts))


def tool_geometry(tool: str) -> ToolGeometry:
    """The geometry of ``tool`` (one of :data:`TOOLS`), masses from :mod:`coassist.sim.objects`."""
    if tool not in TOOLS:
        raise ValueError(f"tool must be one of {TOOLS}, got {tool!r}")
    obj = get_object(tool)
    grey, wood, steel = (0.2, 0.2, 0.2, 1.0), (0.76, 0.6, 0.42, 1.0), (0.55, 0.57, 0.6, 1.0)
    if tool == "handle":
        # The handle preset has no object mass: the handle itself is the mount.
        parts = (_Part("handle", "cylinder", (0.02, 0.06), (0.0, 0.0, 0.06), MOUNT_MASS + obj.mass, grey),)
        point = (0.0, 0.0, 0.06)
        return ToolGeometry(tool, parts, point, point)
    if tool == "board":
        a, b = obj.size
        thick = 0.02
        cup_len = 0.05
        z = cup_len + thick / 2
        cx, cy = obj.center_offset
        gx, gy = obj.grasp_offset
        parts = (
            _Part("cup", "cylinder", (0.04, cup_len / 2), (0.0, 0.0, cup_len / 2), MOUNT_MASS, grey),
            _Part("board", "box", (a / 2, b / 2, thick / 2), (cx, -cy, z), obj.mass, wood),
        )
        return ToolGeometry(tool, parts, (gx, -gy, z), (0.0, 0.0, cup_len))
    # heavy: the steel block 18 × 15.5 × 5 cm held at its centre.
    a, b = obj.size
    h = 0.05
    plate = 0.01
    z = plate + h / 2
    parts = (
        _Part("plate", "cylinder", (0.04, plate / 2), (0.0, 0.0, plate / 2), MOUNT_MASS, grey),
        _Part("block", "box", (a / 2, b / 2, h / 2), (0.0, 0.0, z), obj.mass, steel),
    )
    return ToolGeometry(tool, parts, (0.0, 0.0, z), (0.0, 0.0, z))


@lru_cache(maxsize=1)
def _patched_urdf() -> str:
    path = ur5_urdf_path()
    share = Path(importlib.metadata.distribution("example-robot-data").locate_file(_SHARE_REL))
    text = path.read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    text = re.sub(r"<gazebo.*?</gazebo>", "", text, flags=re.S)
    text = text.replace("package://", str(share) + "/")
    # Keep the fixed links (tool0) as bodies: the sensor needs the flange frame.
    text = re.sub(
        r"<robot([^>]*)>",
        r'<robot\1><mujoco><compiler fusestatic="false" discardvisual="false" strippath="false"/></mujoco>',
        text,
        count=1,
    )
    return text


def _as_point(value, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be 3 finite numbers [m], got {value!r}")
    return arr


def build_ur5_spec(
    tool: str = "handle",
    *,
    physics_dt: float = 0.002,
    servo_time_constant: float = 0.02,
    tcp_offset=None,
    gravity: bool = True,
) -> mujoco.MjSpec:
    """The :class:`mujoco.MjSpec` of the UR5 with sensor, ``tool`` and servos (module docstring).

    servo_time_constant : [s] the lag of the joint velocity behind the command; stored
    in the model as the numeric ``servo_time_constant`` (the world applies it).
    tcp_offset : (3,) the TCP in the tool0 frame [m]; None: the tool's default.
    gravity : False sets gravity to zero.
    """
    geometry = tool_geometry(tool)
    physics_dt = check_positive_scalar(physics_dt, "physics_dt")
    servo_time_constant = check_positive_scalar(servo_time_constant, "servo_time_constant")
    tcp = np.asarray(geometry.tcp) if tcp_offset is None else _as_point(tcp_offset, "tcp_offset")

    spec = mujoco.MjSpec.from_string(_patched_urdf())
    spec.modelname = f"ur5_{tool}"
    spec.option.timestep = physics_dt
    spec.option.gravity = [0.0, 0.0, -9.81 if gravity else 0.0]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    # The URDF's ROS "base" link (an identity-mass frame) is not needed.
    base = spec.body("base")
    if base is not None:
        spec.delete(base)
    root = spec.body("base_link")
    root.quat = [0.0, 0.0, 0.0, 1.0]  # π about z: world frame = the UR controller's base frame
    for geom in spec.geoms:
        geom.contype = 0
        geom.conaffinity = 0
        geom.rgba = [0.7, 0.72, 0.75, 1.0]

    tool0 = spec.body("tool0")
    tool0.add_site(name="ft_sensor", pos=[0.0, 0.0, 0.0], size=[0.01, 0.0, 0.0], rgba=[1.0, 0.3, 0.0, 1.0])
    body = tool0.add_body(name="tool")
    for part in geometry.parts:
        kind = mujoco.mjtGeom.mjGEOM_CYLINDER if part.kind == "cylinder" else mujoco.mjtGeom.mjGEOM_BOX
        size = list(part.size) + [0.0] * (3 - len(part.size))
        body.add_geom(
            name=part.name, type=kind, size=size, pos=list(part.pos), mass=part.mass,
            contype=0, conaffinity=0, rgba=list(part.rgba),
        )
    body.add_site(name="handle", pos=list(geometry.handle), size=[0.015, 0.0, 0.0], rgba=[0.1, 0.8, 0.1, 1.0])
    body.add_site(name="tcp", pos=list(tcp), size=[0.008, 0.0, 0.0], rgba=[0.1, 0.1, 0.9, 1.0])

    spec.add_sensor(
        name="ft_force", type=mujoco.mjtSensor.mjSENS_FORCE, objtype=mujoco.mjtObj.mjOBJ_SITE, objname="ft_sensor",
    )
    spec.add_sensor(
        name="ft_torque", type=mujoco.mjtSensor.mjSENS_TORQUE, objtype=mujoco.mjtObj.mjOBJ_SITE, objname="ft_sensor",
    )

    spec.add_numeric(name="servo_time_constant", data=[servo_time_constant])

    for i, name in enumerate(JOINT_NAMES):
        spec.add_actuator(
            name=f"servo_{i}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT,
            gaintype=mujoco.mjtGain.mjGAIN_FIXED, gainprm=[1.0] + [0.0] * 9,
            biastype=mujoco.mjtBias.mjBIAS_NONE,
            ctrllimited=mujoco.mjtLimited.mjLIMITED_FALSE,
            forcelimited=mujoco.mjtLimited.mjLIMITED_TRUE, forcerange=[-TORQUE_LIMITS[i], TORQUE_LIMITS[i]],
        )
    return spec


def ur5_mjcf_xml(tool: str = "handle", **kwargs) -> str:
    """The MJCF text of :func:`build_ur5_model` (for inspection; mesh paths are absolute)."""
    spec = build_ur5_spec(tool, **kwargs)
    spec.compile()
    return spec.to_xml()


def build_ur5_model(
    tool: str = "handle",
    *,
    physics_dt: float = 0.002,
    servo_time_constant: float = 0.02,
    tcp_offset=None,
    gravity: bool = True,
) -> mujoco.MjModel:
    """The compiled MuJoCo model of the UR5 carrying ``tool`` (module docstring).

    The joint motors take torques; the world
    (:class:`coassist.robot.mujoco_world.MujocoUR5World`) closes the servo loop each
    physics step with the model's ``servo_time_constant`` numeric.
    """
    spec = build_ur5_spec(
        tool, physics_dt=physics_dt, servo_time_constant=servo_time_constant, tcp_offset=tcp_offset, gravity=gravity,
    )
    return spec.compile()
