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
stamp is newer: a late message (stamped before the newest) never does, and a stamp of 0 — a
driver that does not stamp — is refused, as is a stamp more than :data:`MAX_STAMP_LEAD` ahead
of this node's clock (a wrong stamp, or a driver's computer whose clock is ahead: accepted,
it would make every correct message after it a late one), and one more than ``stale_after``
behind it (``stamps_on_this_clock``, the default but in lockstep: a recording replayed with
``ros2 bag play``, a bridge that buffers, or a driver whose clock is behind; its stamps would
advance and look fresh, and the loop would close on old states). The same stamp again with the same
values is a repeat (a driver republishing its last sample): no news, and not a sign of life
either (below); with other values (two publishers, or a driver that does not advance its
stamp) it is refused, on either topic, and the message first stamped so is kept. A joint
state that names a joint twice, lacks one of ``joint_names``, or
has not one position and one velocity per name is refused, as is any message with a
non-finite value. Joint states that jump — a joint farther from the newest state than
:data:`MAX_JOINT_SPEED` moves it between their stamps (at most ``stale_after`` more than
between their arrivals), plus :data:`JOINT_JUMP_TOLERANCE` — come from two sources (a second
node publishing another pose on the topic): the robot's state is unknown, so the run stops
(or does not start) with one line naming the topic and the joint, as for a wrench in an
unknown frame. Joint states whose stamps advance while their positions stay the same, bit for
bit, for longer than ``stale_after`` while the commands sent since would have turned a joint
more than :data:`FROZEN_MOTION`, are a driver republishing a frozen state (or an arm that no
longer follows): read as a lost link (judged on a new stamp: the same message read again is a
gap, which ``stale_after`` bounds as before), which stops the arm — on a frozen pose the loop's position terms never close, and the
workspace limit, checked on that pose, never trips. Refused messages are counted (``rejected_messages``) and never reach
the tick; if nothing valid follows, the topic goes stale and the arm stops, with the
reason in the message (``"12 message(s) on /joint_states arrived but were refused: a
joint state needs one position and one velocity per name …"``, not "no message"). At connect, a
topic whose every message was refused for :data:`REFUSED_AT_CONNECT` (1 s) says so then, not at
``connect_timeout``.

Link rules, those of :class:`~coassist.robot.ur_rtde_world.URRTDEWorld`: a wrench or a
joint state older than ``stale_after`` [s] (at most :data:`MAX_STALE_AFTER`) — wall clock since
its stamp last advanced: a driver that hangs and republishes its last sample is a lost link,
as a silent one is —, nothing at all within ``connect_timeout`` of start (or
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
the simulator. Such a robot repeats its state while it waits for a command, so in lockstep a
repeat is a sign of life (the read after a command waits for a newer stamp all the same).

ROS isolation: ``domain_id`` (default ``$ROS_DOMAIN_ID``, else 0) and, where the
environment sets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, loopback only. The node
lives in its own rclpy context, spun by one executor thread. Needs the ``ros2`` extra.

The configuration is :mod:`coassist.robot.ros2_config`'s (no rclpy needed to import it), the
monitor topics :mod:`coassist.robot.ros2_monitor`'s; :class:`Ros2Config`, :data:`UR_JOINT_NAMES`,
:data:`MAX_STALE_AFTER` and :data:`MAX_TCP_OFFSET` are importable from here as before.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from coassist.errors import CoassistError
from coassist.robot.ros2_config import MAX_STALE_AFTER, MAX_TCP_OFFSET, UR_JOINT_NAMES, Ros2Config
from coassist.robot.ros2_monitor import Ros2Monitor
from coassist.robot.ros2_node import Ros2Node, install_hint, stamp_ns
from coassist.robot.worlds import WorldRequest
from coassist.runtime.loop import alpha_reader
from coassist.runtime.world import Command, RobotLinkError, RobotState
from coassist.spatial import rotation_matrix, rotation_vector

__all__ = [
    "JOINT_JUMP_TOLERANCE",
    "MAX_JOINT_SPEED",
    "MAX_STAMP_LEAD",
    "MAX_STALE_AFTER",
    "MAX_TCP_OFFSET",
    "UR_JOINT_NAMES",
    "Ros2Config",
    "Ros2InputError",
    "Ros2World",
    "build_world",
]

log = logging.getLogger(__name__)

#: [rad/s] the fastest a UR5 joint turns (180 °/s): joint states farther apart than this allows
#: between their stamps come from two sources (module docstring).
MAX_JOINT_SPEED = math.pi
#: [rad] what two joint states of one arm may differ by beyond MAX_JOINT_SPEED · Δt: a driver's
#: stamp a few ms off its sample at full speed (π rad/s × 3 ms); encoders resolve 1e-5 rad.
JOINT_JUMP_TOLERANCE = 0.01
#: [s] at connect, a topic whose every message was refused for this long (none accepted) ends the wait at
#: once, saying why, instead of after ``connect_timeout``: a driver that sends malformed messages sends
#: nothing else (a wrong name list, no velocities, no stamps), so waiting longer tells the user nothing more.
#: A second leaves room for a driver whose first messages are unstamped while it starts.
REFUSED_AT_CONNECT = 1.0
#: [s] how far a header stamp may be ahead of this node's clock. A driver stamps a sample before
#: it is sent, so on one computer a stamp is never ahead; between two, NTP or chrony keep the clocks
#: within milliseconds. Further ahead, the stamp is wrong (or the clocks are not synchronised), and
#: accepted it would make every correct message after it late, for as long as it is ahead: below
#: ``stale_after``'s default (0.1 s), one such message cannot stop the run.
MAX_STAMP_LEAD = 0.05
#: [rad] how far the commands sent since the joint state last changed may have turned the fastest joint
#: before a state that does not change (bit for bit) while its stamps advance is taken as frozen (module
#: docstring). An arm that follows moves its encoders (1e-5 rad) within a few ms of a command; from rest at
#: 8 rad/s² (the safety layer's acceleration limit at 125 Hz) 0.02 rad is 70 ms of commands, some 10 mm at the
#: tool: room for the arm's and the driver's delay, little motion of an arm that is not where it is read.
FROZEN_MOTION = 0.02


class Ros2InputError(CoassistError, ValueError):
    """What arrives on an input topic cannot be used (a wrench in an unknown frame, joint states that
    are all refused): one line naming the topic and what is wrong; the run stops, or does not start."""


class Ros2World:
    """A robot behind ROS 2 topics, driven by joint velocity (module docstring).

    Parameters
    ----------
    config : :class:`Ros2Config`.
    alpha : the game's α to publish on ``~/alpha`` (None: not published) until :meth:`follow_episode`
        is told the run, whose controller's α it then publishes, tick by tick.

    Attributes
    ----------
    dt, command_space, n_joints, realtime : the World protocol (``realtime`` = ``config.pace``).
    tcp_offset_pose : the TCP in the flange frame (the drive builds its kinematics from it).
    last_overrun : [s] how far the last period ran over ``dt`` (0.0 on time).
    rejected_messages : dropped inputs (non-finite, missing joints, late or unstamped, stamped ahead of
        this node's clock, the newest stamp again with other values; a repeat is not counted).
    repeated_messages : messages that repeated the newest one (same stamp, same values).
    base_frame : the robot's base frame (``config.base_frame``): the frame of every pose it reports.
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
            from geometry_msgs.msg import WrenchStamped
            from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
            from sensor_msgs.msg import JointState
            from std_msgs.msg import Float64MultiArray
        except ImportError as exc:
            raise ImportError(f"{install_hint('ros2')} ({exc})") from exc
        from coassist.robot.kinematics import UR5Kinematics

        self.dt = config.dt
        self.n_joints = len(config.joint_names)
        self.realtime = config.pace
        self.tcp_offset_pose = np.asarray(config.tcp_offset, dtype=float)
        self.base_frame = config.base_frame
        self.alpha = None if alpha is None else float(alpha)
        self._alpha_of: Any = None  # the followed run's controller's α now (follow_episode), else self.alpha
        self._plan: np.ndarray | None = None  # the followed run's plan (x, y) where its intent source is the plan
        self._horizon = 0
        self.last_overrun = 0.0
        self.rejected_messages = 0
        self.rejected_commands = 0
        self._kin = UR5Kinematics(tcp_offset=self.tcp_offset_pose)
        self._R_offset = rotation_matrix(self.tcp_offset_pose[3:])
        self._msg = {"Float64MultiArray": Float64MultiArray}
        self._cond = threading.Condition()
        # receive time: when the stamp last advanced (what a message's age is counted from, module docstring)
        self._js: tuple[int, np.ndarray, np.ndarray, float] | None = None  # stamp ns, q, qd, receive time
        self._wr: tuple[int, np.ndarray, float, bool] | None = None  # stamp ns, wrench, receive time, in base
        # topic -> (repeats of its newest message since its stamp last advanced, when the last came [monotonic s])
        self._repeats: dict[str, tuple[int, float]] = {}
        self.repeated_messages = 0
        # topic -> (messages refused since its last good one, why, when the first of them came [monotonic s])
        self._refused: dict[str, tuple[int, str, float]] = {}
        self._input_error: str | None = None  # an input that cannot be used at all (a wrench's unknown frame)
        self._state_rx = math.inf  # receive time of the older input read() used (the command's state)
        self.stale_commands = 0
        self._wrench_seq = 0
        self._used_js = -1
        self._used_wr = -1
        self._await_fresh = False  # lockstep: a command went out, so the next read waits for its state
        self._last_q: np.ndarray | None = None  # the positions the last read gave, and
        self._commanded = 0.0  # [rad] the fastest joint's commanded motion since they last changed (FROZEN_MOTION)
        self._q_changed_at = math.inf  # when they last changed (time.monotonic)
        self._t0_ns: int | None = None
        self._last_t = -math.inf
        self._period_start: float | None = None
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
            self._monitor = Ros2Monitor(self.node, config)
            self._pubs = self._monitor.publishers  # topic name → publisher (the tests wait on their subscribers)
            self._ros.spin()
            self._wait_first()
        except BaseException:
            self.close()
            raise

    # -- ROS side -----------------------------------------------------------------

    def _reject(self, topic: str, why: str) -> None:
        """Drop a message on ``topic``, remembering why: a topic that goes silent for it says so."""
        self.rejected_messages += 1
        n, _, since = self._refused.get(topic, (0, "", time.monotonic()))
        self._refused[topic] = (n + 1, why, since)
        if self.rejected_messages == 1 or self.rejected_messages % 1000 == 0:
            log.warning(
                "Ros2World: dropped a message on %s: %s (%d dropped so far)", topic, why, self.rejected_messages
            )

    def _why_silent(self, topic: str) -> str:
        """What was wrong with the messages of ``topic`` since its last good one ("" if none came)."""
        n, why, _ = self._refused.get(topic, (0, "", 0.0))
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
        stamp = stamp_ns(msg.header.stamp)
        now = time.monotonic()
        with self._cond:
            last = self._js
            fresh = self._fresh(topic, stamp, None if last is None else last[0])
            if fresh is None:
                return
            if last is not None and not fresh:  # the newest stamp again: a repeat, or refused (not a jump of 0 s)
                self._same_stamp(topic, np.array_equal(q, last[1]) and np.array_equal(qd, last[2]), now)
                return
            if last is not None and self._input_error is None:
                jump = self._jump(last, stamp, q, now)
                if jump:
                    self._input_error = jump
                    self._cond.notify_all()
                    return
            self._refused.pop(topic, None)
            self._repeats.pop(topic, None)
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

    def _fresh(self, topic: str, stamp: int, newest: int | None) -> bool | None:
        """Whether a message stamped ``stamp`` is newer than the newest one (stamped ``newest``): True,
        False for the same stamp (the caller compares the values), None when it is refused (module
        docstring): a stamp of 0 (a driver that does not stamp), one older than the newest (a late
        message), one more than MAX_STAMP_LEAD ahead of this node's clock, or (``stamps_on_this_clock``, not in
        lockstep) one more than ``stale_after`` behind it."""
        if stamp <= 0:
            self._reject(
                topic,
                "header stamp 0: the driver does not stamp its messages, and coassist orders and "
                "ages them by their stamp",
            )
            return None
        if newest is not None and stamp < newest:
            self._reject(topic, f"a late message, stamped {(newest - stamp) * 1e-9:.3f} s before the newest")
            return None
        lead = (stamp - self.node.get_clock().now().nanoseconds) * 1e-9
        if lead > MAX_STAMP_LEAD:
            self._reject(
                topic,
                f"stamped {lead:.3f} s ahead of this node's clock (at most {MAX_STAMP_LEAD:g} s): a wrong stamp, or "
                "the driver's computer's clock is ahead of this one's (synchronise them: chrony, NTP)",
            )
            return None
        c = self.config
        news = newest is None or stamp > newest  # the newest stamp again is a repeat, old or not (the caller's)
        if news and c.stamps_on_this_clock and not c.lockstep and -lead > c.stale_after:
            self._reject(
                topic,
                f"stamped {-lead:.3f} s before this node's clock (more than stale_after, {c.stale_after:g} s): an old "
                "message — a recording replayed, a bridge that buffers, or the driver's computer's clock behind this "
                "one's (synchronise them: chrony, NTP); a robot on a clock of its own (a simulator's time): "
                "stamps_on_this_clock=False (coassist ros2 --robot-clock)",
            )
            return None
        return news

    def _same_stamp(self, topic: str, same_values: bool, now: float) -> None:
        """A message stamped as the newest one of ``topic``: a repeat when its values are the same (no
        news; in lockstep a sign of life), refused when they differ (module docstring)."""
        if not same_values:
            self._reject(
                topic,
                "a message with the newest message's stamp and other values (two publishers on the topic, or a "
                "driver that does not advance its stamps); the first one is kept",
            )
            return
        self.repeated_messages += 1
        n, _ = self._repeats.get(topic, (0, now))
        self._repeats[topic] = (n + 1, now)
        self._cond.notify_all()

    def _why_stale(self, topic: str) -> str:
        """Why ``topic`` brought nothing newer: its refused messages, its repeats ("" if neither)."""
        why = [self._why_silent(topic)]
        n, _ = self._repeats.get(topic, (0, 0.0))
        if n:
            why.append(
                f"{n} message(s) on {topic} repeated the newest one, stamp unchanged (a driver that hangs and "
                "republishes its last sample)"
            )
        return "; ".join(w for w in why if w)

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
        stamp = stamp_ns(msg.header.stamp)
        in_base = frame == c.base_frame
        now = time.monotonic()
        with self._cond:
            last = self._wr
            fresh = self._fresh(topic, stamp, None if last is None else last[0])
            if fresh is None:
                return
            if last is not None and not fresh:  # the newest stamp again
                self._same_stamp(topic, in_base == last[3] and np.array_equal(w, last[1]), now)
                return
            self._refused.pop(topic, None)
            self._repeats.pop(topic, None)
            self._wrench_seq += 1
            self._wr = (stamp, w, now, in_base)
            self._cond.notify_all()

    def _wait_first(self) -> None:
        c = self.config
        deadline = time.monotonic() + c.connect_timeout
        with self._cond:
            while self._js is None or self._wr is None:
                if self._input_error is not None:
                    raise Ros2InputError(self._input_error)
                now = time.monotonic()
                hopeless = [
                    self._why_silent(t)
                    for t, v in ((c.joint_state_topic, self._js), (c.wrench_topic, self._wr))
                    if v is None and t in self._refused and now - self._refused[t][2] >= REFUSED_AT_CONNECT
                ]
                if hopeless:  # only refused messages for a second: say what is wrong now
                    raise Ros2InputError("; ".join(hopeless) + " (nothing was moved)")
                left = deadline - now
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
                        why = self._why_stale(stale)
                        raise RobotLinkError(
                            f"no new message on {stale} for {c.stale_after:g} s (lockstep): the robot stopped "
                            "answering; the arm is stopped" + (f" ({why})" if why else "")
                        )
                    self._cond.wait(left)
            js_stamp, q, qd, js_rx = self._js
            wr_stamp, w, wr_rx, wr_in_base = self._wr
            seq = self._wrench_seq
            if c.lockstep:  # a robot waiting for its command repeats its state: a sign of life there
                js_rx = max(js_rx, self._repeats.get(c.joint_state_topic, (0, js_rx))[1])
                wr_rx = max(wr_rx, self._repeats.get(c.wrench_topic, (0, wr_rx))[1])
        now = time.monotonic()
        for topic, rx in ((c.joint_state_topic, js_rx), (c.wrench_topic, wr_rx)):
            if now - rx > c.stale_after:
                why = self._why_stale(topic)
                raise RobotLinkError(
                    f"no new message on {topic} for {now - rx:.3f} s (stale_after {c.stale_after:g} s)"
                    + (f": {why}" if why else "")
                    + "; the arm is stopped. Check the driver and the network, then rerun."
                )
        if self._last_q is None or not np.array_equal(q, self._last_q):
            self._last_q, self._commanded, self._q_changed_at = q, 0.0, now
        elif js_stamp > self._used_js and self._commanded > FROZEN_MOTION and now - self._q_changed_at > c.stale_after:
            # judged on a new stamp only (the same message read again is a gap, which stale_after bounds), and only
            # after stale_after without a change (a message or two lost on a fast arm is no frozen state)
            topic = c.joint_state_topic
            raise RobotLinkError(
                f"the joint states on {topic} advance their stamps but not their positions: in the "
                f"{now - self._q_changed_at:.3f} s since they last changed (stale_after {c.stale_after:g} s) the "
                f"commands would have turned a joint {self._commanded:.3f} rad (more than {FROZEN_MOTION:g}): a driver republishing a frozen state, or an arm that does not follow its "
                "commands (a protective stop?); the arm is stopped"
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
        if qd is not None:
            self._commanded += float(np.max(np.abs(qd))) * self.dt
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

    def follow_episode(self, episode: Any) -> None:
        """Publish what ``episode`` (:class:`~coassist.runtime.episode.Episode`) does: its controller's α
        each tick (an arbitration's online one; none for IMP and MG), and where its intent source is the
        plan, the plan's next rows as ``~/prediction`` (what its MCAP and the live view show)."""
        tick = episode.tick
        self._alpha_of = alpha_reader(tick.controller) or (lambda: None)
        self._plan = np.asarray(episode.plan, dtype=float)[:, :2] if tick.intent.nominal else None
        self._horizon = int(tick.Hs)

    def publish_monitor(self, k: int, state: RobotState, out: Any) -> None:
        """The loop's ``on_tick``: the monitor topics (:meth:`~coassist.robot.ros2_monitor.Ros2Monitor.publish`)."""
        if self._closed:
            return
        alpha = self.alpha if self._alpha_of is None else self._alpha_of()
        prediction = out.prediction
        if prediction is None and self._plan is not None:
            prediction = self._plan[k + 1 : k + 1 + self._horizon]
        self._monitor.publish(k, state, out, alpha, prediction)


def build_world(request: WorldRequest) -> Ros2World:
    """The ``ros2`` world of :data:`coassist.robot.worlds.WORLDS` with ros2_control's default topics at the
    run's rate (``coassist ros2`` builds it from its options instead and hands it to the drive)."""
    return Ros2World(Ros2Config(rate_hz=float(request.rate_hz)))
