"""The ``coassist ros2`` node's configuration: :class:`Ros2Config` (names, frames, QoS, link rules).

Apart from :mod:`coassist.robot.ros2_world` so that what needs only the names (the UR joints'
order, the link limits: ``coassist drive``, the Foxglove view, the tests) imports no rclpy; the
world re-exports every name here. What each field does to the node is said in
:mod:`coassist.robot.ros2_world`'s docstring.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from coassist.robot.ros2_node import ROS_NAME, ROS_TOPIC, resolve_topic

__all__ = ["MAX_STALE_AFTER", "MAX_TCP_OFFSET", "UR_JOINT_NAMES", "Ros2Config"]

#: The UR arms' joint names (ur_description), in kinematic order.
UR_JOINT_NAMES = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
#: [s] the longest ``stale_after``: the stop on a lost link. At the 0.25 m/s tool speed a silent
#: driver lets the tool go at most 125 mm before the arm stops; beyond it the stop is no stop.
MAX_STALE_AFTER = 0.5
#: [m] the farthest a TCP may lie from the flange: a hand-guided tool, not a typo of mm for m.
MAX_TCP_OFFSET = 0.5


@dataclass(frozen=True)
class Ros2Config:
    """The node's names, frames, QoS and link rules (every field validated; errors name ``Ros2Config.<field>``).

    node_name, namespace : the node (``coassist`` in ``/``).
    wrench_topic, joint_state_topic, command_topic : the robot side (module docstring).
    tool_pose_topic, prediction_topic, alpha_topic, hand_force_topic, diagnostics_topic :
        the monitor topics ("" leaves one out).
    base_frame : ``frame_id`` of the published poses (the UR driver's ``base``).
    wrench_frame : ``frame_id`` of a wrench in the sensor frame, whose axes are the
        flange's (the UR driver's ``tool0``). A wrench stamped in ``base_frame`` is
        rotated from there instead; any other frame is refused and stops the run.
    joint_names : the UR5's 6 joints from the base to the tool: the order of ``q`` and of the command (the
        joint states are matched by name); the UR's own names out of that order are refused.
    wrench_in_base : kept for scripts that set it: each wrench message's ``frame_id`` now
        says whether it is in the base frame or the sensor's (module docstring).
    sensor_reliable : subscribe to the sensor topics reliable (default best effort).
    command_depth : history depth of the command publisher.
    rate_hz : control rate [Hz].  stale_after : [s] input age that stops the arm, at most
        :data:`MAX_STALE_AFTER`; a command computed from state older than it is not sent
        (zeros go out instead).
    connect_timeout : [s] wait for the first messages.  monitor_rate_hz : monitor topics' rate.
    prediction_seconds : [s] how much of the prediction ``~/prediction`` carries.
    prediction_stride : ``~/prediction`` carries every stride-th row of it, and the last.
    lockstep : wait for fresh state each tick (simulated robots).  pace : wait for the period's end.
    stamps_on_this_clock : the driver stamps on a clock kept with this computer's (the same computer,
        or chrony/NTP): a message stamped more than ``stale_after`` before this node's clock is then
        refused as old (a recording replayed, a bridge that buffers, a driver's clock behind). False
        for a robot on a clock of its own (a simulator's time): its stamps are only ordered. In
        lockstep the robot's clock is the simulator's, and stamps are never compared with this one.
    domain_id : ROS_DOMAIN_ID (None: the environment's).
    tcp_offset : TCP pose in the flange frame ``[x, y, z, rx, ry, rz]``, at most
        :data:`MAX_TCP_OFFSET` from the flange.
    payload : ``(mass [kg], (cx, cy, cz) [m])`` of the tool below the sensor, for the
        wrench pipeline's gravity compensation (0: the driver compensates already).
    """

    node_name: str = "coassist"
    namespace: str = ""
    wrench_topic: str = "/force_torque_sensor_broadcaster/wrench"
    joint_state_topic: str = "/joint_states"
    command_topic: str = "/forward_velocity_controller/commands"
    tool_pose_topic: str = "~/tool_pose"
    prediction_topic: str = "~/prediction"
    alpha_topic: str = "~/alpha"
    hand_force_topic: str = "~/hand_force"
    diagnostics_topic: str = "/diagnostics"
    base_frame: str = "base"
    wrench_frame: str = "tool0"
    joint_names: tuple[str, ...] = UR_JOINT_NAMES
    wrench_in_base: bool = False
    sensor_reliable: bool = False
    command_depth: int = 1
    rate_hz: float = 125.0
    stale_after: float = 0.1
    connect_timeout: float = 5.0
    monitor_rate_hz: float = 25.0
    prediction_seconds: float = 0.4
    prediction_stride: int = 5
    lockstep: bool = False
    pace: bool = True
    stamps_on_this_clock: bool = True
    domain_id: int | None = None
    tcp_offset: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    payload: tuple[float, tuple[float, float, float]] = (0.0, (0.0, 0.0, 0.0))

    def __post_init__(self) -> None:
        def bad(name: str, what: str) -> ValueError:
            return ValueError(f"Ros2Config.{name} must be {what}, got {getattr(self, name)!r}")

        if not isinstance(self.node_name, str) or not ROS_NAME.match(self.node_name):
            raise bad("node_name", "a ROS name (letters, digits, _; a letter first)")
        if not isinstance(self.namespace, str) or (self.namespace and not ROS_TOPIC.match(self.namespace)):
            raise bad("namespace", "'' or a ROS namespace such as /cell_1")
        for name in ("wrench_topic", "joint_state_topic", "command_topic"):
            v = getattr(self, name)
            if not isinstance(v, str) or not ROS_TOPIC.match(v):
                raise bad(name, "a ROS topic name such as /joint_states")
        for name in ("tool_pose_topic", "prediction_topic", "alpha_topic", "hand_force_topic", "diagnostics_topic"):
            v = getattr(self, name)
            if not isinstance(v, str) or (v and not ROS_TOPIC.match(v)):
                raise bad(name, "'' (off) or a ROS topic name such as ~/tool_pose")
        for name in ("base_frame", "wrench_frame"):
            v = getattr(self, name)
            if not isinstance(v, str) or not v.strip():
                raise bad(name, "a frame id")
        if self.base_frame == self.wrench_frame:
            raise bad("wrench_frame", f"the sensor's frame, not the base frame {self.base_frame!r}")
        names = tuple(self.joint_names) if isinstance(self.joint_names, (list, tuple)) else None
        if not names or len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
            raise bad("joint_names", "distinct joint names")
        if len(names) != len(UR_JOINT_NAMES):
            raise bad("joint_names", f"{len(UR_JOINT_NAMES)} names, one per joint of the UR5 (got {len(names)})")
        known = [next((k for k, ur in enumerate(UR_JOINT_NAMES) if n.endswith(ur)), -1) for n in names]
        if sorted(known) == list(range(len(UR_JOINT_NAMES))) and known != sorted(known):
            # the UR's own joints (a description's prefix allowed) out of order: q read in that order would be
            # taken for the kinematic one, the forward kinematics wrong and the arm pushed against the person
            raise bad(
                "joint_names",
                "the UR's joints from the base to the tool (shoulder_pan … wrist_3: the order of q and of the "
                f"commands; the joint states are matched by name), got {', '.join(names)}",
            )
        object.__setattr__(self, "joint_names", names)
        for name in ("wrench_in_base", "sensor_reliable", "lockstep", "pace", "stamps_on_this_clock"):
            if not isinstance(getattr(self, name), bool):
                raise bad(name, "True or False")
        for name in ("command_depth", "prediction_stride"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise bad(name, "an int >= 1")
        for name in ("rate_hz", "stale_after", "connect_timeout", "monitor_rate_hz", "prediction_seconds"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise bad(name, "a finite number > 0")
        if self.stale_after > MAX_STALE_AFTER:
            raise bad(
                "stale_after", f"at most {MAX_STALE_AFTER:g} s (the stop on a lost link; longer is no stop at all)"
            )
        if self.domain_id is not None and (
            isinstance(self.domain_id, bool) or not isinstance(self.domain_id, int) or not 0 <= self.domain_id <= 232
        ):
            raise bad("domain_id", "None or an int in 0 … 232")
        off = np.asarray(self.tcp_offset, dtype=float) if _numbers(self.tcp_offset) else None
        if off is None or off.shape != (6,) or not np.isfinite(off).all():
            raise bad("tcp_offset", "6 finite numbers [x, y, z, rx, ry, rz]")
        if float(np.linalg.norm(off[:3])) > MAX_TCP_OFFSET:
            raise bad("tcp_offset", f"a TCP within {MAX_TCP_OFFSET:g} m of the flange (x, y, z in metres)")
        object.__setattr__(self, "tcp_offset", tuple(float(v) for v in off))
        try:
            mass_in, com_in = self.payload
            mass = float(mass_in)
            com = tuple(float(c) for c in com_in)
        except (TypeError, ValueError):
            raise bad("payload", "(mass, (cx, cy, cz))") from None
        if not math.isfinite(mass) or mass < 0 or len(com) != 3 or not all(math.isfinite(c) for c in com):
            raise bad("payload", "(mass >= 0 [kg], 3 finite numbers [m])")
        object.__setattr__(self, "payload", (mass, com))
        self._check_topics()

    def _check_topics(self) -> None:
        """No two roles on one topic (as the middleware resolves the names): an input on the node's
        own command or monitor topic, or two inputs on one topic, is refused before anything starts."""
        roles = [name for name in _TOPIC_FIELDS if getattr(self, name)]
        seen: dict[str, str] = {}
        for name in roles:
            full = resolve_topic(getattr(self, name), self.node_name, self.namespace)
            if full in seen:
                raise ValueError(
                    f"Ros2Config.{name} {getattr(self, name)!r} is {full}, the topic of "
                    f"Ros2Config.{seen[full]} too: give each its own topic"
                )
            seen[full] = name

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz


#: The topic fields, inputs first (an error names the later of two that clash).
_TOPIC_FIELDS = (
    "wrench_topic",
    "joint_state_topic",
    "command_topic",
    "tool_pose_topic",
    "prediction_topic",
    "alpha_topic",
    "hand_force_topic",
    "diagnostics_topic",
)


def _numbers(value: Any) -> bool:
    try:
        np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return True
