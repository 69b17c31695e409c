"""Write a trial as an MCAP file of standard ROS 2 messages (Foxglove, ``ros2 bag``, coassist).

One MCAP file per trial, ROS 2 ``cdr`` messages with their ``ros2msg`` schemas embedded
(written with rosbags), so Foxglove Studio and ``ros2 bag play`` open it without the
message packages. Every message of tick k carries the header stamp
``start_ns + round(t_k · 1e9)`` and is logged at that time; ``frame_id`` (default
``"base"``, the UR driver's base frame) is the frame of every pose.

=================================  =====================================  ====================================
topic                              type                                   content
=================================  =====================================  ====================================
``/current_pose``                  geometry_msgs/PoseStamped              measured tool pose
``/current_velocity``              geometry_msgs/TwistStamped             measured tool twist
``/human_wrench``                  geometry_msgs/WrenchStamped            hand force (and torque) used
``/robot_ref_pos``                 geometry_msgs/PoseStamped              the nominal reference
``/prediction``                    nav_msgs/Path                          intent prediction, pose i at t_k + (i+1)·dt
``/alpha``                         std_msgs/Float64                       the game's α (the trial's, or given)
``/faults``                        diagnostic_msgs/DiagnosticArray        the tick's fault flags
``/joint_states``                  sensor_msgs/JointState                 measured joint positions
``/forward_velocity_controller/    std_msgs/Float64MultiArray             commanded joint velocities
commands``
=================================  =====================================  ====================================

The first four are the topics of the thesis' recordings, so the file reads back as a
training trial (:func:`coassist.data.bags.load_bag_trial`). A trial on fewer than 3 or 6
DOFs fills the pose's missing axes from ``meta.extra["start_pose"]`` when there is one
(the drive's start pose), else 0 and the identity orientation. Ticks whose prediction is
NaN (none in use) publish no path. Fault levels: OK with no flag, ERROR when the safety
layer stopped the robot (STOPPED, CONTACT_FORCE_LIMIT or a robot stop), WARN otherwise.
"""

from __future__ import annotations

import math
import os
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from coassist._io import atomic_write, remove_stale, temp_name
from coassist.data.trial import Trial
from coassist.interfaces import Fault, fault_names
from coassist.spatial import quaternion_from_rotation_vector

__all__ = [
    "FAULT_STATUS_NAME",
    "MCAP_TOPICS",
    "TickMessages",
    "fault_array",
    "fault_level",
    "float64_multi_array",
    "ros2_schema",
    "write_chunk_crcs",
    "write_trial_mcap",
]

#: Topic -> message type of what :func:`write_trial_mcap` writes.
MCAP_TOPICS: dict[str, str] = {
    "/current_pose": "geometry_msgs/msg/PoseStamped",
    "/current_velocity": "geometry_msgs/msg/TwistStamped",
    "/human_wrench": "geometry_msgs/msg/WrenchStamped",
    "/robot_ref_pos": "geometry_msgs/msg/PoseStamped",
    "/prediction": "nav_msgs/msg/Path",
    "/alpha": "std_msgs/msg/Float64",
    "/faults": "diagnostic_msgs/msg/DiagnosticArray",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/forward_velocity_controller/commands": "std_msgs/msg/Float64MultiArray",
}
#: ``DiagnosticStatus.name`` of the fault flags.
FAULT_STATUS_NAME = "coassist: fault flags"
_STOPS = Fault.STOPPED | Fault.CONTACT_FORCE_LIMIT | Fault.ROBOT_PROTECTIVE_STOP | Fault.ROBOT_EMERGENCY_STOP
_INSTALL_HINT = "writing MCAP needs rosbags: pip install 'coassist[bags]'"


def fault_level(flags: int) -> int:
    """``DiagnosticStatus`` level of a tick's flags: 0 OK, 1 WARN, 2 ERROR (module docstring)."""
    f = Fault(int(flags))
    if f & _STOPS:
        return 2
    return 1 if f else 0


def _full(rows: np.ndarray, fill: np.ndarray) -> np.ndarray:
    """(T, 6) poses from (T, d) rows: the missing axes from ``fill`` (6,)."""
    out = np.tile(fill, (rows.shape[0], 1))
    out[:, : rows.shape[1]] = rows
    return out


class TickMessages:
    """The messages of one tick (module docstring's table), as :func:`write_trial_mcap` writes them.

    One builder for the file and for the live view (:mod:`coassist.runtime.foxglove`), so the
    two carry the same topics, types and values. ``ts``: a rosbags typestore (ROS 2 Humble);
    ``frame_id``: the frame of every pose and wrench; ``joint_names``: the names of
    ``/joint_states``; ``dt_ns``: the period [ns] (pose i of a prediction is stamped
    ``ns + (i + 1)·dt_ns``).
    """

    def __init__(self, ts: Any, frame_id: str, joint_names: Sequence[str] = (), dt_ns: int = 0) -> None:
        self.ts, self.frame_id = ts, frame_id
        self.joint_names = list(joint_names)
        self.dt_ns = int(dt_ns)
        t = ts.types
        self.Time, self.Header = t["builtin_interfaces/msg/Time"], t["std_msgs/msg/Header"]
        self.Point, self.Quat, self.Pose = (
            t["geometry_msgs/msg/Point"],
            t["geometry_msgs/msg/Quaternion"],
            t["geometry_msgs/msg/Pose"],
        )
        self.V3 = t["geometry_msgs/msg/Vector3"]

    def header(self, ns: int) -> Any:
        return self.Header(stamp=self.Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=self.frame_id)

    def pose(self, p6: np.ndarray) -> Any:
        q = quaternion_from_rotation_vector(p6[3:6])
        return self.Pose(position=self.Point(*map(float, p6[:3])), orientation=self.Quat(*map(float, q)))

    def pose_stamped(self, ns: int, p6: np.ndarray) -> Any:
        return self.ts.types["geometry_msgs/msg/PoseStamped"](header=self.header(ns), pose=self.pose(p6))

    def v3(self, v: np.ndarray) -> Any:
        return self.V3(*map(float, v))

    def tick(
        self,
        ns: int,
        pose6: np.ndarray,
        velocity6: np.ndarray,
        wrench6: np.ndarray,
        reference6: np.ndarray,
        prediction: np.ndarray | None = None,
        alpha: float | None = None,
        flags: int = 0,
        joints: np.ndarray | None = None,
        joint_velocity: np.ndarray | None = None,
    ) -> list[tuple[str, Any]]:
        """(topic, message) of one tick stamped ``ns``, in the file's order.

        pose6, velocity6, wrench6, reference6 : (6,) [m, rad; m/s, rad/s; N, N·m].
        prediction : (H, ≤ 6) poses at t + (i+1)·dt, the missing axes taken from ``pose6``;
        None or not finite: no ``/prediction``.  alpha : None or NaN: no ``/alpha``.
        flags : the tick's :class:`~coassist.interfaces.Fault` bits.  joints : (J,) measured
        q [rad] and joint_velocity (J,) the commanded q̇ [rad/s] (zeros when None); None: no joint topics.
        """
        T = self.ts.types
        m = self
        out: list[tuple[str, Any]] = [
            ("/current_pose", m.pose_stamped(ns, pose6)),
            (
                "/current_velocity",
                T["geometry_msgs/msg/TwistStamped"](
                    header=m.header(ns),
                    twist=T["geometry_msgs/msg/Twist"](linear=m.v3(velocity6[:3]), angular=m.v3(velocity6[3:])),
                ),
            ),
            (
                "/human_wrench",
                T["geometry_msgs/msg/WrenchStamped"](
                    header=m.header(ns),
                    wrench=T["geometry_msgs/msg/Wrench"](force=m.v3(wrench6[:3]), torque=m.v3(wrench6[3:])),
                ),
            ),
            ("/robot_ref_pos", m.pose_stamped(ns, reference6)),
        ]
        if prediction is not None and np.all(np.isfinite(prediction)):
            rows = _full(prediction, pose6)
            dt_ns = self.dt_ns
            out.append(
                (
                    "/prediction",
                    T["nav_msgs/msg/Path"](
                        header=m.header(ns),
                        poses=[m.pose_stamped(ns + (i + 1) * dt_ns, rows[i]) for i in range(rows.shape[0])],
                    ),
                )
            )
        if alpha is not None and math.isfinite(alpha):
            out.append(("/alpha", T["std_msgs/msg/Float64"](data=float(alpha))))
        out.append(("/faults", fault_array(self.ts, m.header(ns), int(flags))))
        if joints is not None:
            out.append(
                (
                    "/joint_states",
                    T["sensor_msgs/msg/JointState"](
                        header=m.header(ns),
                        name=self.joint_names,
                        position=np.asarray(joints, dtype=np.float64),
                        velocity=np.zeros(0),
                        effort=np.zeros(0),
                    ),
                )
            )
            qd = np.zeros(len(joints)) if joint_velocity is None else joint_velocity
            out.append(("/forward_velocity_controller/commands", float64_multi_array(self.ts, qd)))
        return out


def ros2_schema(ts: Any, msgtype: str) -> str:
    """The ``ros2msg`` text of ``msgtype`` (its fields, then every type it uses): the schema an MCAP
    file written here embeds for it, and the one the live view advertises."""
    text, _ = ts.generate_msgdef(msgtype, ros_version=2)
    return text


def write_trial_mcap(
    trial: Trial,
    path: str | os.PathLike[str],
    *,
    alpha: float | Sequence[float] | np.ndarray | None = None,
    joint_names: Sequence[str] | None = None,
    frame_id: str = "base",
    start_ns: int = 0,
) -> Path:
    """Write ``trial`` to ``path`` (``.mcap``) atomically: the whole file or none.

    Parameters
    ----------
    trial : the trial (any source).
    path : the file to write; parent folders are created.
    alpha : the game's α, one number for the run or one per tick (n,); None: the trial's own
        (:attr:`~coassist.data.Trial.alpha`, recorded by every loop), else no ``/alpha``.
    joint_names : names for ``/joint_states`` (default ``joint_1 …``); used when the trial has joints.
    frame_id : frame of the poses and wrenches.
    start_ns : header stamp of tick 0 [ns since the epoch] (0: the trial's own clock).

    Returns
    -------
    Path
        ``path``.
    """
    try:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ImportError(f"{_INSTALL_HINT} ({exc})") from exc
    path = Path(path)
    if path.suffix != ".mcap":
        raise ValueError(f"{path}: an MCAP file must end in .mcap")
    if not isinstance(frame_id, str):
        raise ValueError(f"frame_id must be a string, got {frame_id!r}")
    if isinstance(start_ns, bool) or not isinstance(start_ns, (int, np.integer)) or start_ns < 0:
        raise ValueError(f"start_ns must be an int >= 0, got {start_ns!r}")
    n = trial.n_samples
    alphas = None
    if alpha is None:
        alpha = trial.alpha
    if alpha is not None:
        alphas = (
            np.broadcast_to(np.asarray(alpha, dtype=float), (n,))
            if np.ndim(alpha) == 0
            else np.asarray(alpha, dtype=float)
        )
        if alphas.shape != (n,):
            raise ValueError(f"alpha must be one number or {n} (one per tick), got shape {alphas.shape}")
    joints = trial.joints
    if joints is not None:
        names = list(joint_names) if joint_names is not None else [f"joint_{i + 1}" for i in range(joints.shape[1])]
        if len(names) != joints.shape[1] or not all(isinstance(s, str) for s in names):
            raise ValueError(f"joint_names must be {joints.shape[1]} strings, got {joint_names!r}")

    ts = get_typestore(Stores.ROS2_HUMBLE)
    start = np.zeros(6)
    sp = trial.meta.extra.get("start_pose")
    if sp is not None and len(sp) == 6:
        start = np.asarray(sp, dtype=float)
    pose6, ref6 = _full(trial.pose, start), _full(trial.reference, start)
    vel6 = _full(trial.velocity, np.zeros(6))
    wr6 = _full(trial.wrench, np.zeros(6))
    stamps = [int(start_ns) + round(float(t) * 1e9) for t in trial.time]
    m = TickMessages(ts, frame_id, names if joints is not None else (), round(trial.meta.dt * 1e9))

    # rosbags writes a bag folder: a pid-named one beside the file (not in /tmp), so what a killed
    # writer leaves is removed by the next write there (coassist._io.remove_stale)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(path.parent, path.name)
    tmp = path.parent / temp_name(path.name, "new")
    os.mkdir(tmp)
    try:
        bag = tmp / "bag"
        with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            conn = {
                topic: w.add_connection(topic, msgtype, typestore=ts)
                for topic, msgtype in MCAP_TOPICS.items()
                if (topic != "/alpha" or alphas is not None)
                and (topic not in ("/joint_states", "/forward_velocity_controller/commands") or joints is not None)
                and (topic != "/prediction" or trial.prediction is not None)
            }
            for k in range(n):
                ns = stamps[k]
                qd = None
                if joints is not None and trial.joint_velocity is not None:
                    qd = trial.joint_velocity[k]
                messages = m.tick(
                    ns,
                    pose6[k],
                    vel6[k],
                    wr6[k],
                    ref6[k],
                    prediction=None if trial.prediction is None else trial.prediction[k],
                    alpha=None if alphas is None else float(alphas[k]),
                    flags=0 if trial.fault is None else int(trial.fault[k]),
                    joints=None if joints is None else joints[k],
                    joint_velocity=qd,
                )
                for topic, msg in messages:
                    w.write(conn[topic], ns, ts.serialize_cdr(msg, MCAP_TOPICS[topic]))
        inner = bag / "bag.mcap"
        write_chunk_crcs(inner)

        def copy(fh: Any) -> None:
            with open(inner, "rb") as src:
                shutil.copyfileobj(src, fh)

        return atomic_write(path, copy)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


_MCAP_MAGIC = b"\x89MCAP0\r\n"


def write_chunk_crcs(path: str | os.PathLike[str]) -> int:
    """Fill in the CRC-32 of every uncompressed chunk of the MCAP file ``path``, in place; returns how many.

    rosbags' writer leaves a chunk's ``uncompressed_crc`` 0 ("not computed"), so a reader
    cannot tell a damaged message from a good one; with it, every reader that checks
    chunk CRCs (rosbags, the ``mcap`` library, Foxglove) refuses a chunk whose bytes
    changed. Layout (MCAP spec, chunk record 0x06): opcode u8, length u64, then start
    u64, end u64, uncompressed size u64, uncompressed CRC u32, compression (u32 length +
    text), records length u64, records. Compressed chunks are left as they are.
    """
    import struct
    import zlib

    with open(path, "r+b") as fh:
        data = fh.read()
        if not data.startswith(_MCAP_MAGIC):
            raise ValueError(f"{path}: not an MCAP file")
        pos, n = len(_MCAP_MAGIC), 0
        while pos + 9 <= len(data):
            opcode = data[pos]
            (length,) = struct.unpack_from("<Q", data, pos + 1)
            body = pos + 9
            if opcode == 0x02:  # footer: the end
                break
            if opcode == 0x06:
                (compression_len,) = struct.unpack_from("<I", data, body + 28)
                compression = data[body + 32 : body + 32 + compression_len]
                records_at = body + 32 + compression_len + 8
                (records_len,) = struct.unpack_from("<Q", data, records_at - 8)
                if not compression:
                    fh.seek(body + 24)
                    fh.write(struct.pack("<I", zlib.crc32(data[records_at : records_at + records_len])))
                    n += 1
            pos = body + length
    return n


def fault_array(ts: Any, header: Any, flags: int) -> Any:
    """``diagnostic_msgs/DiagnosticArray`` of one tick's flags: one status, a KeyValue per flag set."""
    t = ts.types
    names = fault_names(flags)
    status = t["diagnostic_msgs/msg/DiagnosticStatus"](
        level=fault_level(flags),
        name=FAULT_STATUS_NAME,
        message=", ".join(names) or "ok",
        hardware_id="coassist",
        values=[t["diagnostic_msgs/msg/KeyValue"](key="flags", value=str(int(flags)))]
        + [t["diagnostic_msgs/msg/KeyValue"](key=name, value="1") for name in names],
    )
    return t["diagnostic_msgs/msg/DiagnosticArray"](header=header, status=[status])


def float64_multi_array(ts: Any, values: np.ndarray) -> Any:
    """``std_msgs/Float64MultiArray`` with a one-dimensional layout (what ros2_control's forward controllers take)."""
    t = ts.types
    data = np.asarray(values, dtype=np.float64)
    layout = t["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    return t["std_msgs/msg/Float64MultiArray"](layout=layout, data=data)
