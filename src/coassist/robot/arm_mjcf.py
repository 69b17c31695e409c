"""The MuJoCo model of an arm of the registry with its force/torque sensor and the carried object.

What the MuJoCo worlds of every arm share (:class:`coassist.robot.mujoco_world.MujocoArmWorld`):
the model is the arm's URDF of the installed ``example-robot-data`` package
(:data:`coassist.robot.arms.ARMS`: its path, flange frame and base frame), with its DAE
visuals dropped (the STL collision meshes are kept as visuals) and the links of
``ArmDescription.mujoco_drop`` left out (ROS frames, a gripper: the tool is mounted on
the flange). Nothing is downloaded.

Frames. The MuJoCo world frame is the arm controller's *base* frame: the root body is
turned by π about z where ``ArmDescription.base_signs`` says so (the UR5). Below the
flange (``tip_frame``, z out of the flange)::

    flange ── site ft_sensor (at the flange, the flange's axes; sensors ft_force, ft_torque)
      └── body tool (welded): the object and its mount, one rigid body
            ├── site handle  where the hand grasps (the operator's wrench acts here)
            └── site tcp     the tool centre point (tool_pose)

The tools, in the flange frame (the worlds start with the tool straight down and tool
x = base x, so tool y = −base y and the objects' base-frame offsets of
:mod:`coassist.scenario.objects` enter with y flipped):

- ``handle``: a 3D-printed cylinder handle, MOUNT_MASS kg, 0.12 m long; hand and TCP
  at its middle (0, 0, 0.06).
- ``board``: a vacuum cup (MOUNT_MASS kg, 0.05 m) holding the plywood board below it,
  the board's centre at the object's ``center_offset`` from the cup, the hand at its
  ``grasp_offset``. The TCP is the cup (0, 0, 0.05).
- ``heavy``: a mounting plate (MOUNT_MASS kg) and the steel block held at its centre;
  hand and TCP at the block's centre.

Joint motors: one torque motor per arm joint (``ctrl`` [N·m]), clipped to the URDF's
``effort`` limits (:func:`urdf_joint_limits`); the world closes a computed-torque servo
around them every physics step (:mod:`coassist.robot.ur5_mjcf` gives the law). The
model stores ``servo_time_constant`` as a numeric. Collisions are off (contype =
conaffinity = 0 on every geom): free-space pHRI.
"""

from __future__ import annotations

import importlib.metadata
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np

from coassist._checks import check_positive_scalar
from coassist.robot.arms import get_arm
from coassist.robot.kinematics import robot_data_path
from coassist.scenario.objects import get_object

__all__ = [
    "MOUNT_MASS",
    "TOOLS",
    "ToolGeometry",
    "arm_joint_names",
    "build_arm_model",
    "build_arm_spec",
    "tool_geometry",
    "urdf_joint_limits",
]

#: Mass of each tool's mount (handle body, vacuum cup, mounting plate) [kg].
MOUNT_MASS = 0.3
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
    """One tool in the flange frame [m, kg] (module docstring).

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
    """The geometry of ``tool`` (one of :data:`TOOLS`), masses from :mod:`coassist.scenario.objects`."""
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


def _urdf_path(robot: str) -> Path:
    arm = get_arm(robot)
    return robot_data_path(arm.urdf, f"the {arm.name} model")


@lru_cache(maxsize=8)
def _patched_urdf(robot: str) -> str:
    path = _urdf_path(robot)
    share = Path(importlib.metadata.distribution("example-robot-data").locate_file(_SHARE_REL))
    text = path.read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    text = re.sub(r"<gazebo.*?</gazebo>", "", text, flags=re.S)
    text = text.replace("package://", str(share) + "/")
    # Keep the fixed links (the flange) as bodies: the sensor needs the flange frame.
    text = re.sub(
        r"<robot([^>]*)>",
        r'<robot\1><mujoco><compiler fusestatic="false" discardvisual="false" strippath="false"/></mujoco>',
        text,
        count=1,
    )
    return text


@lru_cache(maxsize=8)
def urdf_joint_limits(robot: str) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """(names, effort (n,) [N·m], velocity (n,) [rad/s]) of the arm's revolute joints, from its URDF.

    The joints in URDF order, the ``locked`` ones (a gripper's fingers) left out; the
    count must be the arm's ``n_joints``. The arrays are read-only (cached).
    """
    arm = get_arm(robot)
    names, effort, velocity = [], [], []
    for joint in ET.parse(_urdf_path(robot)).getroot().iter("joint"):
        if joint.get("type") not in ("revolute", "continuous") or joint.get("name") in arm.locked:
            continue
        limit = joint.find("limit")
        if limit is None:
            raise ValueError(f"the {robot} URDF's joint {joint.get('name')!r} has no <limit>")
        names.append(joint.get("name"))
        effort.append(float(limit.get("effort")))
        velocity.append(float(limit.get("velocity")))
    if len(names) != arm.n_joints:
        raise ValueError(f"the {robot} URDF has {len(names)} arm joints, the registry says {arm.n_joints}")
    e, v = np.array(effort), np.array(velocity)
    e.flags.writeable = v.flags.writeable = False
    return tuple(names), e, v


def arm_joint_names(robot: str) -> tuple[str, ...]:
    """The arm's joint names in the MuJoCo model's order (the URDF's)."""
    return urdf_joint_limits(robot)[0]


def _as_point(value, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be 3 finite numbers [m], got {value!r}")
    return arr


def build_arm_spec(
    robot: str,
    tool: str = "handle",
    *,
    physics_dt: float = 0.002,
    servo_time_constant: float = 0.02,
    tcp_offset=None,
    gravity: bool = True,
) -> mujoco.MjSpec:
    """The :class:`mujoco.MjSpec` of the registered arm ``robot`` with sensor, ``tool`` and motors.

    servo_time_constant : [s] the lag of the joint velocity behind the command; stored
    in the model as the numeric ``servo_time_constant`` (the world applies it).
    tcp_offset : (3,) the TCP in the flange frame [m]; None: the tool's default.
    gravity : False sets gravity to zero.
    """
    arm = get_arm(robot)
    geometry = tool_geometry(tool)
    physics_dt = check_positive_scalar(physics_dt, "physics_dt")
    servo_time_constant = check_positive_scalar(servo_time_constant, "servo_time_constant")
    tcp = np.asarray(geometry.tcp) if tcp_offset is None else _as_point(tcp_offset, "tcp_offset")
    joint_names, torque_limits, _ = urdf_joint_limits(robot)

    spec = mujoco.MjSpec.from_string(_patched_urdf(robot))
    spec.modelname = f"{robot}_{tool}"
    spec.option.timestep = physics_dt
    spec.option.gravity = [0.0, 0.0, -9.81 if gravity else 0.0]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for name in arm.mujoco_drop:
        body = spec.body(name)
        if body is not None:
            spec.delete(body)
    if arm.base_signs[0] < 0.0:
        root = spec.worldbody.first_body()
        root.quat = [0.0, 0.0, 0.0, 1.0]  # π about z: world frame = the controller's base frame
    for geom in spec.geoms:
        geom.contype = 0
        geom.conaffinity = 0
        geom.rgba = [0.7, 0.72, 0.75, 1.0]

    flange = spec.body(arm.tip_frame)
    flange.add_site(name="ft_sensor", pos=[0.0, 0.0, 0.0], size=[0.01, 0.0, 0.0], rgba=[1.0, 0.3, 0.0, 1.0])
    body = flange.add_body(name="tool")
    for part in geometry.parts:
        kind = mujoco.mjtGeom.mjGEOM_CYLINDER if part.kind == "cylinder" else mujoco.mjtGeom.mjGEOM_BOX
        size = list(part.size) + [0.0] * (3 - len(part.size))
        body.add_geom(
            name=part.name,
            type=kind,
            size=size,
            pos=list(part.pos),
            mass=part.mass,
            contype=0,
            conaffinity=0,
            rgba=list(part.rgba),
        )
    body.add_site(name="handle", pos=list(geometry.handle), size=[0.015, 0.0, 0.0], rgba=[0.1, 0.8, 0.1, 1.0])
    body.add_site(name="tcp", pos=list(tcp), size=[0.008, 0.0, 0.0], rgba=[0.1, 0.1, 0.9, 1.0])

    spec.add_sensor(
        name="ft_force",
        type=mujoco.mjtSensor.mjSENS_FORCE,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname="ft_sensor",
    )
    spec.add_sensor(
        name="ft_torque",
        type=mujoco.mjtSensor.mjSENS_TORQUE,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname="ft_sensor",
    )

    spec.add_numeric(name="servo_time_constant", data=[servo_time_constant])

    for i, name in enumerate(joint_names):
        spec.add_actuator(
            name=f"servo_{i}",
            target=name,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            gaintype=mujoco.mjtGain.mjGAIN_FIXED,
            gainprm=[1.0] + [0.0] * 9,
            biastype=mujoco.mjtBias.mjBIAS_NONE,
            ctrllimited=mujoco.mjtLimited.mjLIMITED_FALSE,
            forcelimited=mujoco.mjtLimited.mjLIMITED_TRUE,
            forcerange=[-torque_limits[i], torque_limits[i]],
        )
    return spec


def build_arm_model(
    robot: str,
    tool: str = "handle",
    *,
    physics_dt: float = 0.002,
    servo_time_constant: float = 0.02,
    tcp_offset=None,
    gravity: bool = True,
) -> mujoco.MjModel:
    """The compiled MuJoCo model of ``robot`` carrying ``tool`` (module docstring); its joints are
    the arm's (checked: a URDF joint the model keeps beyond them would be simulated but never driven)."""
    spec = build_arm_spec(
        robot,
        tool,
        physics_dt=physics_dt,
        servo_time_constant=servo_time_constant,
        tcp_offset=tcp_offset,
        gravity=gravity,
    )
    model = spec.compile()
    n = get_arm(robot).n_joints
    if model.nq != n or model.nv != n:
        raise ValueError(
            f"the MuJoCo {robot} model has {model.nv} joints, the registry says {n} "
            "(leave the extra links out with ArmDescription.mujoco_drop)"
        )
    return model
