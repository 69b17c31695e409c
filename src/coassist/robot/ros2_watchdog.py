"""A command watchdog for ros2_control's forward velocity controller: ``coassist ros2-watchdog``.

ros2_control's ``forward_command_controller`` (the UR driver's ``forward_velocity_controller``,
``velocity_controllers/JointGroupVelocityController``) writes the last command it received
to the hardware on every cycle, for ever: it has no timeout. If the process that sends
the commands hangs, crashes or loses the network, the arm keeps moving at the last
velocity (a 0.5 s hang of ``coassist ros2`` moved the tool 48 mm). UR's RTDE has its
watchdog and franky holds a motion 50 ms; this node is the equivalent for ROS 2.

Run it on the robot's computer, beside the controller (so a lost network between the two
computers stops the arm too), and point ``coassist ros2 --command-topic`` at its input::

    coassist ros2-watchdog --input /coassist/joint_velocity_command \\
        --output /forward_velocity_controller/commands --joints 6 --timeout 0.05
    coassist ros2 --command-topic /coassist/joint_velocity_command ...

It forwards every command of ``n_joints`` finite numbers as it arrives and, checking
every ``period``, sends zeros whenever none came for ``timeout`` seconds (and keeps sending
them, one per period, until commands return): the arm stops within
``timeout + period`` plus the controller's own ramp. A malformed command (wrong length,
NaN) is not forwarded; zeros go out instead. Commands go out reliable, depth 1 (what the
forward controllers subscribe with). What it cannot do: stop the arm if it dies itself —
launch it with the controller (``respawn``), and keep the emergency stop within reach.
Needs the ``ros2`` extra.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Any

from coassist.robot.ros2_node import ROS_NAME, ROS_TOPIC, Ros2Node, install_hint, resolve_topic

__all__ = ["CommandWatchdog", "WatchdogConfig"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class WatchdogConfig:
    """The watchdog's topics and timing (validated; errors name ``WatchdogConfig.<field>``).

    input_topic : where ``coassist ros2`` sends its commands (``--command-topic``).
    output_topic : the controller's command topic.
    n_joints : joints per command.  timeout : [s] silence after which zeros go out, ≤ 0.5.
    period : [s] how often the silence is checked (and zeros repeated), ≤ timeout.
    node_name : the node's name.  domain_id : ROS_DOMAIN_ID (None: the environment's).
    """

    input_topic: str = "/coassist/joint_velocity_command"
    output_topic: str = "/forward_velocity_controller/commands"
    n_joints: int = 6
    timeout: float = 0.05
    period: float = 0.008
    node_name: str = "coassist_watchdog"
    domain_id: int | None = None

    def __post_init__(self) -> None:
        def bad(name: str, what: str) -> ValueError:
            return ValueError(f"WatchdogConfig.{name} must be {what}, got {getattr(self, name)!r}")

        for name in ("input_topic", "output_topic"):
            v = getattr(self, name)
            if not isinstance(v, str) or not ROS_TOPIC.match(v):
                raise bad(name, "a ROS topic name such as /forward_velocity_controller/commands")
        if not isinstance(self.node_name, str) or not ROS_NAME.match(self.node_name):
            raise bad("node_name", "a ROS name (letters, digits, _; a letter first)")
        if resolve_topic(self.input_topic, self.node_name) == resolve_topic(self.output_topic, self.node_name):
            raise bad("output_topic", f"another topic than the input ({self.input_topic})")
        if isinstance(self.n_joints, bool) or not isinstance(self.n_joints, int) or not 1 <= self.n_joints <= 12:
            raise bad("n_joints", "an int in 1 … 12")
        for name, top in (("timeout", 0.5), ("period", 0.5)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not 0 < v <= top:
                raise bad(name, f"a number of seconds in (0, {top:g}]")
        if self.period > self.timeout:
            raise bad("period", f"at most the timeout ({self.timeout:g} s)")
        if self.domain_id is not None and (
            isinstance(self.domain_id, bool) or not isinstance(self.domain_id, int) or not 0 <= self.domain_id <= 232
        ):
            raise bad("domain_id", "None or an int in 0 … 232")


class CommandWatchdog:
    """The relay with a timeout (module docstring), spun by a thread of its own until :meth:`close`.

    Attributes: forwarded (commands passed on), zeros_sent (zero commands sent on silence or a
    malformed command), malformed (commands not forwarded), timeouts (silences that began).
    """

    def __init__(self, config: WatchdogConfig | None = None) -> None:
        self.config = config = config or WatchdogConfig()
        if not isinstance(config, WatchdogConfig):
            raise ValueError(f"config must be a WatchdogConfig, got {type(config).__name__}")
        try:
            from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
            from std_msgs.msg import Float64MultiArray
        except ImportError as exc:
            raise ImportError(f"{install_hint('ros2-watchdog')} ({exc})") from exc
        self.forwarded = self.zeros_sent = self.malformed = self.timeouts = 0
        self._msg = Float64MultiArray
        self._lock = threading.Lock()
        self._last = -math.inf  # monotonic time of the last good command
        self._quiet = True  # zeros are what the controller holds
        self._ros = Ros2Node(
            config.node_name,
            domain_id=config.domain_id,
            owner="CommandWatchdog",
            command="ros2-watchdog",
            thread_name="coassist-ros2-watchdog",
        )
        self.node = self._ros.node
        try:
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE)
            self._pub = self.node.create_publisher(Float64MultiArray, config.output_topic, qos)
            self.node.create_subscription(Float64MultiArray, config.input_topic, self._on_command, qos)
            self.node.create_timer(config.period, self._check)
            self._ros.spin()
        except BaseException:
            self.close()
            raise

    def _send(self, values: list[float]) -> None:
        msg = self._msg()
        msg.data = values
        self._pub.publish(msg)

    def _on_command(self, msg: Any) -> None:
        values = [float(v) for v in msg.data]
        ok = len(values) == self.config.n_joints and all(math.isfinite(v) for v in values)
        with self._lock:
            if not ok:
                self.malformed += 1
                self.zeros_sent += 1
                self._last = -math.inf  # the silence starts now: zeros until a good command
                self._quiet = True
                self._send([0.0] * self.config.n_joints)
                return
            self._last = time.monotonic()
            self._quiet = False
            self.forwarded += 1
            self._send(values)

    def _check(self) -> None:
        with self._lock:
            if time.monotonic() - self._last <= self.config.timeout:
                return
            if not self._quiet:
                self.timeouts += 1
                log.warning(
                    "CommandWatchdog: no command on %s for %g s: zero velocities sent",
                    self.config.input_topic,
                    self.config.timeout,
                )
            self._quiet = True
            if self.forwarded:  # nothing to stop before the first command
                self.zeros_sent += 1
                self._send([0.0] * self.config.n_joints)

    def close(self) -> None:
        """Stop the thread, then send zeros and shut the node down; never raises. The spin thread
        stops first: a command it forwarded after the zeros would be held by the robot's controller."""
        self._ros.stop_spinning()
        try:
            if getattr(self, "_pub", None) is not None and self.forwarded:
                with self._lock:
                    self._send([0.0] * self.config.n_joints)
        except Exception:  # noqa: BLE001 - close must finish
            pass
        self._ros.shutdown()

    def __enter__(self) -> CommandWatchdog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
