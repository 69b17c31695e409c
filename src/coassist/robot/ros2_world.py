"""A ROS 2 robot as a :class:`~coassist.runtime.world.World`: ``coassist ros2``.

The control loop runs as a ROS 2 node (rclpy) through the same
:class:`~coassist.runtime.tick.ControlTick` and safety layer as every other world
(:func:`coassist.robot.drive.drive` builds the run). The node talks to the robot the way
ros2_control does:

================================================  =================================  =========================================
topic (default)                                   type                               role
================================================  =================================  =========================================
``/force_torque_sensor_broadcaster/wrench``       geometry_msgs/WrenchStamped        in: the F/T reading, sensor frame
``/joint_states``                                 sensor_msgs/JointState             in: joint positions and velocities
``/forward_velocity_controller/commands``         std_msgs/Float64MultiArray         out: joint velocities [rad/s], one per
                                                                                     joint in ``joint_names`` order
``~/tool_pose``                                   geometry_msgs/PoseStamped          monitor: TCP pose, ``base_frame``
``~/prediction``                                  nav_msgs/Path                      monitor: the next 0.4 s of the intent
``~/alpha``                                       std_msgs/Float64                   monitor: the game's α
``~/hand_force``                                  geometry_msgs/WrenchStamped        monitor: the hand wrench the tick used
``/diagnostics``                                  diagnostic_msgs/DiagnosticArray    monitor: the tick's fault flags
================================================  =================================  =========================================

(the UR driver's names; ``~`` is the node's namespace, ``/coassist/…`` by default).
Every name, the frames and the QoS are fields of :class:`Ros2Config`. The sensor topics
are read with the sensor-data QoS (best effort, depth 5: a late sample is worth less than
a fresh one, and a best-effort subscriber matches a reliable publisher); commands go out
reliable, depth 1 (what ros2_control's forward controllers subscribe with).

State. ``q`` and ``q̇`` come from the newest joint state (reordered by ``joint_names``,
the UR5's six joints); the TCP pose and twist from the UR5 kinematics (``tcp_offset``),
``t`` from the joint state's header stamp. The wrench's ``frame_id`` says its frame: the
sensor's (``wrench_frame``, default ``tool0`` as the UR driver publishes it: the flange's
axes) or the base's (``base_frame``: rotated into the sensor frame with the flange's
orientation from the kinematics, so the bias and the payload stay where they are
constant; ``wrench_in_base`` used to declare it). A wrench in any other frame cannot be rotated
into the base frame: :meth:`Ros2World.read` raises :class:`Ros2InputError` naming the
topic and the frame, and the run stops (at connect: it does not start). ``wrench_seq``
counts wrench messages with a newer header stamp.

Trust in the inputs. A message replaces the newest one of its topic only when its header
stamp is newer: a late message (stamped before the newest) never does, the same stamp
again is no news (a sign of life only), and a stamp of 0 — a driver that does not stamp
— is refused. A joint state that names a joint twice, lacks one of ``joint_names``, or
has not one position and one velocity per name is refused, as is any message with a
non-finite value. Joint states that jump — a joint farther from the newest state than
:data:`MAX_JOINT_SPEED` moves it between their stamps (at most ``stale_after`` more than
between their arrivals), plus :data:`JOINT_JUMP_TOLERANCE` — come from two sources (a second
node publishing another pose on the topic): the robot's state is unknown, so the run stops
(or does not start) with one line naming the topic and the joint, as for a wrench in an
unknown frame. Refused messages are counted (``rejected_messages``) and never reach
the tick; if nothing valid follows, the topic goes stale and the arm stops, with the
reason in the message (``"12 message(s) on /joint_states arrived but were refused: a
joint state needs one position and one velocity per name …"``, not "no message").

Link rules, those of :class:`~coassist.robot.ur_rtde_world.URRTDEWorld`: a wrench or a
joint state older than ``stale_after`` [s] (wall clock since the last accepted message;
at most :data:`MAX_STALE_AFTER`), nothing at all within ``connect_timeout`` of start (or
no subscriber to the commands), makes :meth:`Ros2World.read` raise
:class:`~coassist.runtime.world.RobotLinkError`; the loop stops the run and
:meth:`Ros2World.stop` sends zero velocities. A command that is not ``n_joints`` finite
numbers is replaced by zeros, and so is one computed from state older than
``stale_after`` when it is sent (the loop stalled between read and apply; counted in
``stale_commands``; the next tick is flagged DEADLINE_MISS). ``apply`` waits for the end
of the period (``pace``), like RTDE's ``waitPeriod``, and reports overruns in
``last_overrun`` (the loop flags DEADLINE_MISS).

The robot side must stop on its own when the commands stop: ros2_control's forward
velocity controller holds the last command for ever (a 0.5 s hang of this process moved
the tool 48 mm; a dead process would not stop it). Run :mod:`coassist.robot.ros2_watchdog`
(``coassist ros2-watchdog``) on the robot's computer between this node and the
controller: it forwards the commands and sends zeros once none came for its
``timeout``.

Cost. The monitor topics are built and published in the loop's ``on_tick``, on the
control thread: measured on this project's 2-core machine, 0.8 ms median and 1.7 ms p99
on a monitor tick (every 5th at 125 Hz; rclpy message building and one DDS write per
topic), 0.3 µs on the others; ``read`` (UR5 kinematics) 16 µs. Lower
``monitor_rate_hz``, or leave topics out (``""``), where the period is tight.

Lockstep (``lockstep=True``) is for simulated robots that step once per command:
:meth:`read` after an :meth:`apply` then waits (at most ``stale_after``) for a joint state
and a wrench stamped later than the last ones it used, so a run is as deterministic as
the simulator.

ROS isolation: ``domain_id`` (default ``$ROS_DOMAIN_ID``, else 0) and, where the
environment sets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, loopback only. The node
lives in its own rclpy context, spun by one executor thread. Needs the ``ros2`` extra.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from coassist.errors import CoassistError
from coassist.interfaces import fault_names
from coassist.robot.ros2_node import ROS_NAME, ROS_TOPIC, Ros2Node, install_hint, resolve_topic
from coassist.robot.worlds import WorldRequest
from coassist.runtime.world import Command, RobotLinkError, RobotState
from coassist.spatial import quaternion_from_rotation_vector, rotation_matrix, rotation_vector

__all__ = [
    "JOINT_JUMP_TOLERANCE",
    "MAX_JOINT_SPEED",
    "MAX_STALE_AFTER",
    "MAX_TCP_OFFSET",
    "UR_JOINT_NAMES",
    "Ros2Config",
    "Ros2InputError",
    "Ros2World",
    "build_world",
]

log = logging.getLogger(__name__)

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
#: [rad/s] the fastest a UR5 joint turns (180 °/s): joint states farther apart than this allows
#: between their stamps come from two sources (module docstring).
MAX_JOINT_SPEED = math.pi
#: [rad] what two joint states of one arm may differ by beyond MAX_JOINT_SPEED · Δt: a driver's
#: stamp a few ms off its sample at full speed (π rad/s × 3 ms); encoders resolve 1e-5 rad.
JOINT_JUMP_TOLERANCE = 0.01


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
    joint_names : the order of ``q`` and of the command: the UR5's 6 joints.
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
        object.__setattr__(self, "joint_names", names)
        for name in ("wrench_in_base", "sensor_reliable", "lockstep", "pace"):
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
            mass, com = self.payload
            mass = float(mass)
            com = tuple(float(c) for c in com)
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


def _stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class Ros2InputError(CoassistError, ValueError):
    """What arrives on an input topic cannot be used (a wrench in an unknown frame, joint states that
    are all refused): one line naming the topic and what is wrong; the run stops, or does not start."""


class Ros2World:
    """A robot behind ROS 2 topics, driven by joint velocity (module docstring).

    Parameters
    ----------
    config : :class:`Ros2Config`.
    alpha : the game's α to publish on ``~/alpha`` (None: not published).

    Attributes
    ----------
    dt, command_space, n_joints, realtime : the World protocol (``realtime`` = ``config.pace``).
    tcp_offset_pose : the TCP in the flange frame (the drive builds its kinematics from it).
    last_overrun : [s] how far the last period ran over ``dt`` (0.0 on time).
    rejected_messages : dropped inputs (non-finite, missing joints).
    rejected_commands : commands replaced by zeros (not n_joints finite numbers).
    stale_commands : commands replaced by zeros because their state was older than
        ``stale_after`` when they were sent.
    """

    command_space = "joint_velocity"
    noise_free_sensor = False  # a real sensor behind the topic: the frozen-sensor check stays on

    def __init__(self, config: Ros2Config | None = None, *, alpha: float | None = None) -> None:
        self.config = config = config or Ros2Config()
        if not isinstance(config, Ros2Config):
            raise ValueError(f"config must be a Ros2Config, got {type(config).__name__}")
        try:
            from diagnostic_msgs.msg import DiagnosticArray
            from geometry_msgs.msg import PoseStamped, WrenchStamped
            from nav_msgs.msg import Path
            from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
            from sensor_msgs.msg import JointState
            from std_msgs.msg import Float64, Float64MultiArray
        except ImportError as exc:
            raise ImportError(f"{install_hint('ros2')} ({exc})") from exc
        from coassist.robot.kinematics import UR5Kinematics

        self.dt = config.dt
        self.n_joints = len(config.joint_names)
        self.realtime = config.pace
        self.tcp_offset_pose = np.asarray(config.tcp_offset, dtype=float)
        self.alpha = None if alpha is None else float(alpha)
        self.last_overrun = 0.0
        self.rejected_messages = 0
        self.rejected_commands = 0
        self._kin = UR5Kinematics(tcp_offset=self.tcp_offset_pose)
        self._R_offset = rotation_matrix(self.tcp_offset_pose[3:])
        self._msg = {
            "PoseStamped": PoseStamped,
            "WrenchStamped": WrenchStamped,
            "Path": Path,
            "Float64": Float64,
            "Float64MultiArray": Float64MultiArray,
            "DiagnosticArray": DiagnosticArray,
        }
        self._cond = threading.Condition()
        self._js: tuple[int, np.ndarray, np.ndarray, float] | None = None  # stamp ns, q, qd, receive time
        self._wr: tuple[int, np.ndarray, float, bool] | None = None  # stamp ns, wrench, receive time, in base
        self._refused: dict[str, tuple[int, str]] = {}  # topic -> (refused since its last good message, why)
        self._input_error: str | None = None  # an input that cannot be used at all (a wrench's unknown frame)
        self._state_rx = math.inf  # receive time of the older input read() used (the command's state)
        self.stale_commands = 0
        self._wrench_seq = 0
        self._used_js = -1
        self._used_wr = -1
        self._await_fresh = False  # lockstep: a command went out, so the next read waits for its state
        self._t0_ns: int | None = None
        self._last_t = -math.inf
        self._period_start: float | None = None
        self._monitor_every = max(1, round(config.rate_hz / config.monitor_rate_hz))
        self._closed = False
        self._stopped_sent = False

        self._ros = Ros2Node(
            config.node_name,
            namespace=config.namespace or None,
            domain_id=config.domain_id,
            owner="Ros2World",
            command="ros2",
            thread_name="coassist-ros2",
        )
        self.node = self._ros.node
        try:
            sensor_qos = (
                QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5, reliability=ReliabilityPolicy.RELIABLE)
                if config.sensor_reliable
                else qos_profile_sensor_data
            )
            self.node.create_subscription(JointState, config.joint_state_topic, self._on_joint_state, sensor_qos)
            self.node.create_subscription(WrenchStamped, config.wrench_topic, self._on_wrench, sensor_qos)
            cmd_qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=config.command_depth, reliability=ReliabilityPolicy.RELIABLE
            )
            self._cmd_pub = self.node.create_publisher(Float64MultiArray, config.command_topic, cmd_qos)
            mon_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE)
            self._pubs = {
                name: self.node.create_publisher(kind, getattr(config, f"{name}_topic"), mon_qos)
                for name, kind in (
                    ("tool_pose", PoseStamped),
                    ("prediction", Path),
                    ("alpha", Float64),
                    ("hand_force", WrenchStamped),
                    ("diagnostics", DiagnosticArray),
                )
                if getattr(config, f"{name}_topic")
            }
            self._ros.spin()
            self._wait_first()
        except BaseException:
            self.close()
            raise

    # -- ROS side -----------------------------------------------------------------

    def _reject(self, topic: str, why: str) -> None:
        """Drop a message on ``topic``, remembering why: a topic that goes silent for it says so."""
        self.rejected_messages += 1
        n = self._refused.get(topic, (0, ""))[0] + 1
        self._refused[topic] = (n, why)
        if self.rejected_messages == 1 or self.rejected_messages % 1000 == 0:
            log.warning(
                "Ros2World: dropped a message on %s: %s (%d dropped so far)", topic, why, self.rejected_messages
            )

    def _why_silent(self, topic: str) -> str:
        """What was wrong with the messages of ``topic`` since its last good one ("" if none came)."""
        n, why = self._refused.get(topic, (0, ""))
        return f"{n} message(s) on {topic} arrived but were refused: {why}" if n else ""

    def _on_joint_state(self, msg: Any) -> None:
        topic = self.config.joint_state_topic
        names = list(msg.name)
        if len(set(names)) != len(names):
            twice = sorted({n for n in names if names.count(n) > 1})
            self._reject(topic, f"a joint state names {', '.join(twice)} more than once")
            return
        try:
            idx = [names.index(n) for n in self.config.joint_names]
        except ValueError:
            missing = [n for n in self.config.joint_names if n not in names]
            self._reject(topic, f"a joint state without {', '.join(missing)} (--joint-names)")
            return
        pos = np.asarray(msg.position, dtype=float)
        vel = np.asarray(msg.velocity, dtype=float)
        if pos.shape != (len(names),) or vel.shape != (len(names),):
            self._reject(
                topic,
                f"a joint state needs one position and one velocity per name ({len(names)} names, "
                f"{pos.size} positions, {vel.size} velocities)",
            )
            return
        q, qd = pos[idx], vel[idx]
        if not (np.isfinite(q).all() and np.isfinite(qd).all()):
            self._reject(topic, "a joint state with a non-finite value")
            return
        stamp = _stamp_ns(msg.header.stamp)
        now = time.monotonic()
        with self._cond:
            if not self._fresh(topic, stamp, None if self._js is None else self._js[0]):
                return
            if self._js is not None and self._input_error is None:
                jump = self._jump(self._js, stamp, q, now)
                if jump:
                    self._input_error = jump
                    self._cond.notify_all()
                    return
            self._refused.pop(topic, None)
            self._js = (stamp, q, qd, now)
            self._cond.notify_all()

    def _jump(self, last: tuple[int, np.ndarray, np.ndarray, float], stamp: int, q: np.ndarray, now: float) -> str:
        """Why a joint state (stamp ns, q, arrival) cannot follow ``last`` (the newest) of the same arm, or "".

        A joint may move MAX_JOINT_SPEED · Δt + JOINT_JUMP_TOLERANCE, Δt the time between the two
        stamps, or between their arrivals plus stale_after where that is shorter (a publisher on
        another clock)."""
        last_stamp, last_q, _, last_rx = last
        span = min((stamp - last_stamp) * 1e-9, max(now - last_rx, 0.0) + self.config.stale_after)
        moved = np.abs(q - last_q)
        i = int(np.argmax(moved))
        if not moved[i] > MAX_JOINT_SPEED * span + JOINT_JUMP_TOLERANCE:
            return ""
        topic = self.config.joint_state_topic
        return (
            f"the joint states on {topic} jump: {self.config.joint_names[i]} moved {moved[i]:.3f} rad in "
            f"{span:.3f} s, more than the arm can ({MAX_JOINT_SPEED:.2f} rad/s): two sources publish on {topic} "
            "(another node, a second driver?); stop the other one, then rerun"
        )

    def _fresh(self, topic: str, stamp: int, newest: int | None) -> bool:
        """Whether a message stamped ``stamp`` replaces the newest one (stamped ``newest``): a stamp of 0
        (a driver that does not stamp) or older than the newest (a late message) is refused; the same
        stamp again (a driver repeating its last sample) is no news, but counts as a sign of life."""
        if stamp <= 0:
            self._reject(
                topic,
                "header stamp 0: the driver does not stamp its messages, and coassist orders and "
                "ages them by their stamp",
            )
            return False
        if newest is not None and stamp < newest:
            self._reject(topic, f"a late message, stamped {(newest - stamp) * 1e-9:.3f} s before the newest")
            return False
        return True

    def _on_wrench(self, msg: Any) -> None:
        c = self.config
        topic = c.wrench_topic
        frame = msg.header.frame_id
        if frame not in (c.wrench_frame, c.base_frame):
            with self._cond:
                if self._input_error is None:
                    self._input_error = (
                        f"the wrench on {topic} is in frame {frame!r}, not the sensor's ({c.wrench_frame!r}, "
                        f"--wrench-frame) or the base ({c.base_frame!r}, --base-frame): coassist cannot rotate it "
                        "into the base frame; publish it in one of these, or name the sensor's frame"
                    )
                self._cond.notify_all()
            return
        f, tq = msg.wrench.force, msg.wrench.torque
        w = np.array([f.x, f.y, f.z, tq.x, tq.y, tq.z], dtype=float)
        if not np.isfinite(w).all():
            self._reject(topic, "a wrench with a non-finite value")
            return
        stamp = _stamp_ns(msg.header.stamp)
        with self._cond:
            newest = None if self._wr is None else self._wr[0]
            if not self._fresh(topic, stamp, newest):
                return
            self._refused.pop(topic, None)
            if newest is None or stamp > newest:
                self._wrench_seq += 1
                self._wr = (stamp, w, time.monotonic(), frame == c.base_frame)
            else:  # the same sample again: alive, no news
                self._wr = (*self._wr[:2], time.monotonic(), self._wr[3])
            self._cond.notify_all()

    def _wait_first(self) -> None:
        c = self.config
        deadline = time.monotonic() + c.connect_timeout
        with self._cond:
            while self._js is None or self._wr is None:
                if self._input_error is not None:
                    raise Ros2InputError(self._input_error)
                left = deadline - time.monotonic()
                if left <= 0:
                    missing = [t for t, v in ((c.joint_state_topic, self._js), (c.wrench_topic, self._wr)) if v is None]
                    refused = [self._why_silent(t) for t in missing if self._why_silent(t)]
                    if refused:  # messages come, and something is wrong with them: say what
                        raise Ros2InputError("; ".join(refused) + " (nothing was moved)")
                    raise RobotLinkError(
                        f"no message on {' and '.join(missing)} within {c.connect_timeout:g} s: is the robot "
                        "driver running, on the same ROS_DOMAIN_ID, with these topic names?"
                    )
                self._cond.wait(min(left, 0.05))
        # A command sent before the controller's subscription is matched would be lost.
        while self._cmd_pub.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                raise RobotLinkError(
                    f"nothing subscribes to {c.command_topic} within {c.connect_timeout:g} s: "
                    "is the forward velocity controller loaded and active?"
                )
            time.sleep(0.005)

    # -- World -----------------------------------------------------------------------

    def read(self) -> RobotState:
        """The latest joint state and wrench (module docstring); RobotLinkError when stale."""
        if self._closed:
            raise RobotLinkError("read() on a closed Ros2World; build a new one")
        c = self.config
        with self._cond:
            if self._input_error is not None:
                raise Ros2InputError(self._input_error)
            if c.lockstep and self._await_fresh:
                deadline = time.monotonic() + c.stale_after
                while not (self._js[0] > self._used_js and self._wr[0] >= self._js[0] and self._wr[0] > self._used_wr):
                    if self._input_error is not None:
                        raise Ros2InputError(self._input_error)
                    left = deadline - time.monotonic()
                    if left <= 0:
                        stale = c.joint_state_topic if self._js[0] <= self._used_js else c.wrench_topic
                        why = self._why_silent(stale)
                        raise RobotLinkError(
                            f"no new message on {stale} for {c.stale_after:g} s (lockstep): the robot stopped "
                            "answering; the arm is stopped" + (f" ({why})" if why else "")
                        )
                    self._cond.wait(left)
            js_stamp, q, qd, js_rx = self._js
            wr_stamp, w, wr_rx, wr_in_base = self._wr
            seq = self._wrench_seq
        now = time.monotonic()
        for topic, rx in ((c.joint_state_topic, js_rx), (c.wrench_topic, wr_rx)):
            if now - rx > c.stale_after:
                why = self._why_silent(topic)
                raise RobotLinkError(
                    f"no new message on {topic} for {now - rx:.3f} s (stale_after {c.stale_after:g} s)"
                    + (f": {why}" if why else "")
                    + "; the arm is stopped. Check the driver and the network, then rerun."
                )
        self._state_rx = min(js_rx, wr_rx)
        self._used_js, self._used_wr = js_stamp, wr_stamp
        self._await_fresh = False
        if self._period_start is None:
            self._period_start = time.perf_counter()
        if self._t0_ns is None:
            self._t0_ns = js_stamp
        t = (js_stamp - self._t0_ns) * 1e-9
        t = t if t > self._last_t else self._last_t + 1e-6
        self._last_t = t
        p, R, J = self._kin.forward_and_jacobian(q)
        pose = np.concatenate([p, rotation_vector(R)])
        twist = J @ qd
        R_sensor = R @ self._R_offset.T  # the flange's orientation: the sensor frame's axes in the base frame
        if wr_in_base:  # stamped in the base frame: into the sensor frame, where the bias and the payload live
            w = np.concatenate([R_sensor.T @ w[:3], R_sensor.T @ w[3:]])
        return RobotState(
            t=t,
            q=q.copy(),
            qd=qd.copy(),
            tool_pose=pose,
            tool_twist=twist,
            wrench=w.copy(),
            sensor_rotation=R_sensor,
            wrench_seq=seq,
        )

    def _publish_command(self, qd: Sequence[float]) -> None:
        msg = self._msg["Float64MultiArray"]()
        msg.data = [float(v) for v in qd]
        self._cmd_pub.publish(msg)

    def apply(self, command: Command) -> None:
        """Publish the joint velocity (zeros on stop or a bad command), then wait for the period's end."""
        if self._closed:
            raise RobotLinkError("apply() on a closed Ros2World; build a new one")
        qd = None
        if not command.stop and command.qd is not None:
            try:
                arr = np.asarray(command.qd, dtype=float)
            except (TypeError, ValueError):
                arr = None
            if arr is not None and arr.shape == (self.n_joints,) and np.isfinite(arr).all():
                qd = arr
            else:
                self.rejected_commands += 1
                if self.rejected_commands == 1 or self.rejected_commands % 1000 == 0:
                    log.warning("Ros2World: command %r is not %d finite values; sent zeros", command.qd, self.n_joints)
        # never a command computed from stale state: the loop stalled between read() and here
        state_age = time.monotonic() - self._state_rx
        stale = qd is not None and state_age > self.config.stale_after
        if stale:
            self.stale_commands += 1
            qd = None
            log.warning("Ros2World: a command computed from state %.3f s old was not sent (zeros instead)", state_age)
        self._publish_command(np.zeros(self.n_joints) if qd is None else qd)
        self._await_fresh = True
        if self.config.pace:
            start = self._period_start if self._period_start is not None else time.perf_counter()
            end = start + self.dt
            now = time.perf_counter()
            if end > now:
                time.sleep(end - now)
                self.last_overrun = 0.0
            else:
                self.last_overrun = now - end if now - end > 0.1 * self.dt else 0.0
            self._period_start = max(end, time.perf_counter() - self.dt)
        else:
            self._period_start = time.perf_counter()
            self.last_overrun = 0.0
        if stale:  # the loop flags the next tick DEADLINE_MISS: the safety layer ramps from the measured q̇
            self.last_overrun = max(self.last_overrun, state_age)

    def stop(self) -> None:
        """Send zero joint velocities; safe to call twice; a no-op after :meth:`close`."""
        if self._closed or not hasattr(self, "_cmd_pub"):
            return
        self._publish_command(np.zeros(self.n_joints))

    def close(self) -> None:
        """Stop, then shut the node and its context down; never raises."""
        if self._closed:
            return
        try:
            self.stop()
        except Exception as exc:  # noqa: BLE001 - close must finish
            log.warning("Ros2World.close: stop failed: %s", exc)
        self._closed = True
        self._ros.close()

    def __enter__(self) -> Ros2World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def tool_mass_and_com(self) -> tuple[float, np.ndarray]:
        """The payload below the sensor (``Ros2Config.payload``) for the wrench pipeline."""
        mass, com = self.config.payload
        return mass, np.asarray(com, dtype=float)

    def kinematics(self):
        """The UR5's kinematics with this node's TCP (``Ros2Config.tcp_offset``)."""
        from coassist.robot.kinematics import UR5Kinematics

        return UR5Kinematics(tcp_offset=self.tcp_offset_pose)

    # -- monitor ---------------------------------------------------------------------

    def publish_monitor(self, k: int, state: RobotState, out: Any) -> None:
        """The loop's ``on_tick``: tool pose, prediction, α, hand force and fault flags at ``monitor_rate_hz``
        (every ``round(rate_hz / monitor_rate_hz)``-th tick, from tick 0).

        ``out`` is the tick's :class:`~coassist.runtime.tick.TickOutput`. Faults go out on
        every tick that has one (and at the monitor rate otherwise), so none is missed.
        """
        if self._closed:
            return
        due = k % self._monitor_every == 0
        flags = int(out.fault)
        if not due and not flags:
            return
        stamp = self.node.get_clock().now().to_msg()
        if "diagnostics" in self._pubs:
            self._pubs["diagnostics"].publish(self._diagnostics(stamp, flags))
        if not due:
            return
        frame = self.config.base_frame
        pose = np.asarray(state.tool_pose, dtype=float)
        if "tool_pose" in self._pubs:
            self._pubs["tool_pose"].publish(self._pose_stamped(stamp, frame, pose))
        if "hand_force" in self._pubs:
            m = self._msg["WrenchStamped"]()
            m.header.stamp, m.header.frame_id = stamp, frame
            w = np.zeros(6)
            w[: len(out.wrench)] = out.wrench
            m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = (float(v) for v in w[:3])
            m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z = (float(v) for v in w[3:])
            self._pubs["hand_force"].publish(m)
        if "alpha" in self._pubs and self.alpha is not None:
            self._pubs["alpha"].publish(self._msg["Float64"](data=self.alpha))
        if "prediction" in self._pubs and out.prediction is not None:
            # Every stride-th row of the first prediction_seconds, and the last: a path to draw,
            # built in well under a millisecond (all 50 rows cost ~1 ms of the tick).
            n = max(1, min(len(out.prediction), round(self.config.prediction_seconds / self.dt)))
            rows = sorted(set(range(self.config.prediction_stride - 1, n, self.config.prediction_stride)) | {n - 1})
            path = self._msg["Path"]()
            path.header.stamp, path.header.frame_id = stamp, frame
            qx, qy, qz, qw = quaternion_from_rotation_vector(pose[3:6])  # the tool's orientation, held
            t0 = _stamp_ns(stamp)
            d = out.prediction.shape[1]
            poses = []
            for i in rows:
                ps = self._msg["PoseStamped"]()
                ns = t0 + round((i + 1) * self.dt * 1e9)
                ps.header.stamp.sec, ps.header.stamp.nanosec, ps.header.frame_id = (
                    ns // 1_000_000_000,
                    ns % 1_000_000_000,
                    frame,
                )
                xyz = pose[:3].copy()
                xyz[: min(d, 3)] = out.prediction[i, : min(d, 3)]
                pp = ps.pose
                pp.position.x, pp.position.y, pp.position.z = float(xyz[0]), float(xyz[1]), float(xyz[2])
                pp.orientation.x, pp.orientation.y, pp.orientation.z, pp.orientation.w = qx, qy, qz, qw
                poses.append(ps)
            path.poses = poses
            self._pubs["prediction"].publish(path)

    def _pose_stamped(self, stamp: Any, frame: str, pose: np.ndarray) -> Any:
        m = self._msg["PoseStamped"]()
        m.header.stamp, m.header.frame_id = stamp, frame
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in pose[:3])
        qx, qy, qz, qw = quaternion_from_rotation_vector(pose[3:6])
        m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = qx, qy, qz, qw
        return m

    def _diagnostics(self, stamp: Any, flags: int) -> Any:
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

        from coassist.data.trial_mcap import FAULT_STATUS_NAME, fault_level

        names = fault_names(flags)
        status = DiagnosticStatus(
            level=bytes([fault_level(flags)]),
            name=FAULT_STATUS_NAME,
            message=", ".join(names) or "ok",
            hardware_id=self.config.node_name,
        )
        status.values = [KeyValue(key="flags", value=str(flags))] + [KeyValue(key=n, value="1") for n in names]
        arr = self._msg["DiagnosticArray"]()
        arr.header.stamp, arr.status = stamp, [status]
        return arr


def build_world(request: WorldRequest) -> Ros2World:
    """The ``ros2`` world of :data:`coassist.robot.worlds.WORLDS` with ros2_control's default topics at the
    run's rate (``coassist ros2`` builds it from its options instead and hands it to the drive)."""
    return Ros2World(Ros2Config(rate_hz=float(request.rate_hz)))
