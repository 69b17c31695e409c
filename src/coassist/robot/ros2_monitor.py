"""The monitor topics of ``coassist ros2``'s node: what the loop did, published on every monitor tick.

=====================  =================================  =========================================
topic (default)        type                               what
=====================  =================================  =========================================
``~/tool_pose``        geometry_msgs/PoseStamped          the TCP pose, ``base_frame``
``~/prediction``       nav_msgs/Path                      the next ``prediction_seconds`` of the intent
``~/alpha``            std_msgs/Float64                   the game's α
``~/hand_force``       geometry_msgs/WrenchStamped        the hand wrench the tick used
``/diagnostics``       diagnostic_msgs/DiagnosticArray    the tick's fault flags
=====================  =================================  =========================================

:class:`~coassist.robot.ros2_world.Ros2World` builds one :class:`Ros2Monitor` on its node and calls
:meth:`Ros2Monitor.publish` from the loop's ``on_tick`` (on the control thread: its cost is in
:mod:`coassist.robot.ros2_world`'s docstring). A topic set to "" in the
:class:`~coassist.robot.ros2_config.Ros2Config` has no publisher. Needs the ``ros2`` extra.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from coassist.interfaces import fault_names
from coassist.robot.ros2_config import Ros2Config
from coassist.robot.ros2_node import install_hint, stamp_ns
from coassist.runtime.world import RobotState
from coassist.spatial import quaternion_from_rotation_vector

__all__ = ["MONITOR_TOPICS", "Ros2Monitor"]

#: The monitor topics, by the name of their Ros2Config field (``<name>_topic``).
MONITOR_TOPICS = ("tool_pose", "prediction", "alpha", "hand_force", "diagnostics")


class Ros2Monitor:
    """The monitor publishers of one node (module docstring).

    Parameters
    ----------
    node : the rclpy node they publish from.
    config : its :class:`~coassist.robot.ros2_config.Ros2Config` (the topics, ``base_frame``, the rates,
        ``prediction_seconds`` and ``prediction_stride``).

    Attributes
    ----------
    publishers : topic name (of :data:`MONITOR_TOPICS`) → its publisher, for the topics not left out.
    every : a monitor tick every ``every``-th control tick: ``round(rate_hz / monitor_rate_hz)``, at least 1.
    """

    def __init__(self, node: Any, config: Ros2Config) -> None:
        try:
            from diagnostic_msgs.msg import DiagnosticArray
            from geometry_msgs.msg import PoseStamped, WrenchStamped
            from nav_msgs.msg import Path
            from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
            from std_msgs.msg import Float64
        except ImportError as exc:
            raise ImportError(f"{install_hint('ros2')} ({exc})") from exc
        self.config = config
        self.node = node
        self._dt = config.dt
        self.every = max(1, round(config.rate_hz / config.monitor_rate_hz))
        self._msg = {
            "PoseStamped": PoseStamped,
            "WrenchStamped": WrenchStamped,
            "Path": Path,
            "Float64": Float64,
            "DiagnosticArray": DiagnosticArray,
        }
        kinds = {
            "tool_pose": PoseStamped,
            "prediction": Path,
            "alpha": Float64,
            "hand_force": WrenchStamped,
            "diagnostics": DiagnosticArray,
        }
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.publishers = {
            name: node.create_publisher(kinds[name], getattr(config, f"{name}_topic"), qos)
            for name in MONITOR_TOPICS
            if getattr(config, f"{name}_topic")
        }

    def publish(
        self, k: int, state: RobotState, out: Any, alpha: float | None, prediction: np.ndarray | None = None
    ) -> None:
        """Tick ``k``'s tool pose, prediction, α, hand force and fault flags at ``monitor_rate_hz``
        (every ``round(rate_hz / monitor_rate_hz)``-th tick, from tick 0).

        ``out`` is the tick's :class:`~coassist.runtime.tick.TickOutput`; ``alpha`` the game's α (None: not
        published); ``prediction`` (H, ≥2) the rows to publish (None: ``out.prediction``; the nominal plan's
        rows are the caller's, as the tick gives none). Faults go out on every tick that has one (and at the monitor rate otherwise), so none
        is missed.
        """
        due = k % self.every == 0
        flags = int(out.fault)
        if not due and not flags:
            return
        stamp = self.node.get_clock().now().to_msg()
        if "diagnostics" in self.publishers:
            self.publishers["diagnostics"].publish(self._diagnostics(stamp, flags))
        if not due:
            return
        frame = self.config.base_frame
        pose = np.asarray(state.tool_pose, dtype=float)
        if "tool_pose" in self.publishers:
            self.publishers["tool_pose"].publish(self._pose_stamped(stamp, frame, pose))
        if "hand_force" in self.publishers:
            m = self._msg["WrenchStamped"]()
            m.header.stamp, m.header.frame_id = stamp, frame
            w = np.zeros(6)
            w[: len(out.wrench)] = out.wrench
            m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = (float(v) for v in w[:3])
            m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z = (float(v) for v in w[3:])
            self.publishers["hand_force"].publish(m)
        if "alpha" in self.publishers and alpha is not None:
            self.publishers["alpha"].publish(self._msg["Float64"](data=alpha))
        if prediction is None:
            prediction = out.prediction
        if "prediction" in self.publishers and prediction is not None and len(prediction):
            # Every stride-th row of the first prediction_seconds, and the last: a path to draw,
            # built in well under a millisecond (all 50 rows cost ~1 ms of the tick).
            n = max(1, min(len(prediction), round(self.config.prediction_seconds / self._dt)))
            rows = sorted(set(range(self.config.prediction_stride - 1, n, self.config.prediction_stride)) | {n - 1})
            path = self._msg["Path"]()
            path.header.stamp, path.header.frame_id = stamp, frame
            qx, qy, qz, qw = quaternion_from_rotation_vector(pose[3:6])  # the tool's orientation, held
            t0 = stamp_ns(stamp)
            d = prediction.shape[1]
            poses = []
            for i in rows:
                ps = self._msg["PoseStamped"]()
                ns = t0 + round((i + 1) * self._dt * 1e9)
                ps.header.stamp.sec, ps.header.stamp.nanosec, ps.header.frame_id = (
                    ns // 1_000_000_000,
                    ns % 1_000_000_000,
                    frame,
                )
                xyz = pose[:3].copy()
                xyz[: min(d, 3)] = prediction[i, : min(d, 3)]
                pp = ps.pose
                pp.position.x, pp.position.y, pp.position.z = float(xyz[0]), float(xyz[1]), float(xyz[2])
                pp.orientation.x, pp.orientation.y, pp.orientation.z, pp.orientation.w = qx, qy, qz, qw
                poses.append(ps)
            path.poses = poses
            self.publishers["prediction"].publish(path)

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
