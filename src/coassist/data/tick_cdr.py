"""One tick's ROS 2 messages as CDR bytes, written directly: what the live view sends.

The same messages as :class:`coassist.data.trial_mcap.TickMessages` (the MCAP file's
topics, types and values), serialised without building message objects: rosbags builds
and serialises a tick in 0.8 ms (1.5 ms with a 50-pose prediction) of pure Python, which
a thread beside the control loop would hold the interpreter for; this writes the bytes
with one ``struct`` call per field group (measured: docs/foxglove.md). The bytes are the
ones rosbags' ``serialize_cdr`` gives for the same message, byte for byte
(tests/data/test_tick_cdr.py checks every topic against it).

The format is XCDR1 little endian, as ROS 2 (Fast DDS) and rosbags write it: the
encapsulation header ``00 01 00 00``, then the fields in order, each primitive aligned
to its own size counted from the end of that header; a string is a u32 length (the NUL
included), its bytes and a NUL; a sequence a u32 count, then its elements (the 8-byte
alignment of a float64 sequence only when it has any).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator, Sequence

import numpy as np

from coassist.data.trial_mcap import FAULT_STATUS_NAME, fault_level
from coassist.interfaces import fault_names
from coassist.spatial import quaternion_from_rotation_vector

__all__ = ["TickEncoder"]

_ENCAPSULATION = b"\x00\x01\x00\x00"
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_POSE = struct.Struct("<7d")
_V6 = struct.Struct("<6d")
_F64 = struct.Struct("<d")


def _string(text: str) -> bytes:
    """A CDR string's length and bytes (the NUL included), to be written at a 4-aligned offset."""
    raw = text.encode("utf-8") + b"\x00"
    return _U32.pack(len(raw)) + raw


class _Buffer:
    """A CDR payload being written: alignment counts from the end of the encapsulation header."""

    __slots__ = ("b",)

    def __init__(self) -> None:
        self.b = bytearray(_ENCAPSULATION)

    def align(self, n: int) -> None:
        r = (len(self.b) - 4) % n
        if r:
            self.b += bytes(n - r)

    def raw4(self, data: bytes) -> None:
        """Bytes that start with a 4-aligned field (a u32, an i32, a string)."""
        self.align(4)
        self.b += data

    def doubles(self, packed: bytes) -> None:
        self.align(8)
        self.b += packed

    def float64_sequence(self, values: np.ndarray) -> None:
        self.raw4(_U32.pack(len(values)))
        if len(values):
            self.align(8)
            self.b += np.ascontiguousarray(values, dtype="<f8").tobytes()


def _quaternion(rv: np.ndarray) -> tuple[float, float, float, float]:
    x, y, z, w = quaternion_from_rotation_vector(rv).tolist()
    return x, y, z, w


class TickEncoder:
    """CDR bytes of one tick's messages (module docstring), for one trial's frame and joints.

    frame_id : the frame of every pose and wrench.  joint_names : ``/joint_states``' names.
    dt_ns : the period [ns] (prediction pose i is stamped ``ns + (i + 1)·dt_ns``).
    """

    def __init__(self, frame_id: str = "base", joint_names: Sequence[str] = (), dt_ns: int = 0) -> None:
        self.frame_id = str(frame_id)
        self._frame = _string(self.frame_id)
        self.joint_names = [str(n) for n in joint_names]
        self._names = [_string(n) for n in self.joint_names]
        self.dt_ns = int(dt_ns)
        # a PoseStamped that starts 8-aligned: i32 sec, u32 nsec, the frame string, padding to 8, 7 doubles
        head = len(self._frame)
        self._path_record = np.dtype(
            {
                "names": ["sec", "nsec", "head", "pose"],
                "formats": ["<i4", "<u4", f"S{head}", ("<f8", (7,))],
                "offsets": [0, 4, 8, 8 + head + (-(8 + head) % 8)],
                "itemsize": 8 + head + (-(8 + head) % 8) + 56,
            }
        )

    def _header(self, buf: _Buffer, ns: int) -> None:
        buf.raw4(_STAMP.pack(ns // 1_000_000_000, ns % 1_000_000_000) + self._frame)

    def _pose(self, buf: _Buffer, p6: np.ndarray, q: tuple[float, float, float, float] | None = None) -> None:
        x, y, z = float(p6[0]), float(p6[1]), float(p6[2])
        buf.doubles(_POSE.pack(x, y, z, *(q if q is not None else _quaternion(p6[3:6]))))

    def pose_stamped(self, ns: int, p6: np.ndarray) -> bytes:
        """geometry_msgs/PoseStamped: p6 (6,) position [m] and rotation vector [rad]."""
        buf = _Buffer()
        self._header(buf, ns)
        self._pose(buf, p6)
        return bytes(buf.b)

    def _six(self, ns: int, v6: np.ndarray) -> bytes:
        """TwistStamped or WrenchStamped: a header and two Vector3 (the same layout)."""
        buf = _Buffer()
        self._header(buf, ns)
        buf.doubles(_V6.pack(*np.asarray(v6, dtype=float).tolist()))
        return bytes(buf.b)

    def path(self, ns: int, rows6: np.ndarray) -> bytes:
        """nav_msgs/Path: pose i (rows6 (H, 6)) stamped ``ns + (i + 1)·dt_ns``.

        Every PoseStamped after the first starts 8-aligned and has the same size (a header with
        this frame, padding to 8, seven doubles), so those are written as one numpy record array;
        the first is written field by field (its padding depends on where it starts).
        """
        rows6 = np.asarray(rows6, dtype=float)
        n = rows6.shape[0]
        buf = _Buffer()
        self._header(buf, ns)
        buf.raw4(_U32.pack(n))
        if n == 0:
            return bytes(buf.b)
        # the orientations: one quaternion per distinct rotation (a path on the x-y plane has one)
        rv = rows6[:, 3:6]
        if (rv == rv[0]).all():
            quats = np.broadcast_to(np.asarray(_quaternion(rv[0])), (n, 4))
        else:
            cache: dict[tuple[float, float, float], tuple[float, float, float, float]] = {}
            quats = np.array(
                [cache.get(r) or cache.setdefault(r, _quaternion(np.asarray(r))) for r in map(tuple, rv.tolist())]
            )
        stamps = ns + (np.arange(1, n + 1, dtype=np.int64) * self.dt_ns)
        self._header(buf, int(stamps[0]))
        buf.doubles(_POSE.pack(*rows6[0, :3].tolist(), *quats[0].tolist()))
        if n > 1:
            records = np.zeros(n - 1, dtype=self._path_record)
            records["sec"] = stamps[1:] // 1_000_000_000
            records["nsec"] = stamps[1:] % 1_000_000_000
            records["head"] = self._frame  # the frame's length and bytes, as every header has them
            records["pose"][:, :3] = rows6[1:, :3]
            records["pose"][:, 3:] = quats[1:]
            buf.b += records.tobytes()
        return bytes(buf.b)

    def faults(self, ns: int, flags: int) -> bytes:
        """diagnostic_msgs/DiagnosticArray of the flags (:func:`coassist.data.trial_mcap.fault_array`)."""
        names = fault_names(flags)
        values = [("flags", str(int(flags)))] + [(name, "1") for name in names]
        buf = _Buffer()
        self._header(buf, ns)
        buf.raw4(_U32.pack(1))  # one status
        buf.b += bytes((fault_level(flags),))
        buf.raw4(_string(FAULT_STATUS_NAME))
        buf.raw4(_string(", ".join(names) or "ok"))
        buf.raw4(_string("coassist"))
        buf.raw4(_U32.pack(len(values)))
        for key, value in values:
            buf.raw4(_string(key))
            buf.raw4(_string(value))
        return bytes(buf.b)

    def joint_state(self, ns: int, q: np.ndarray) -> bytes:
        """sensor_msgs/JointState: the names, positions q (J,) [rad], no velocities or efforts."""
        buf = _Buffer()
        self._header(buf, ns)
        buf.raw4(_U32.pack(len(self._names)))
        for name in self._names:  # each string's length 4-aligned
            buf.raw4(name)
        buf.float64_sequence(np.asarray(q, dtype=float))
        buf.raw4(_U32.pack(0) + _U32.pack(0))  # velocity, effort: empty
        return bytes(buf.b)

    @staticmethod
    def float64_multi_array(values: np.ndarray) -> bytes:
        """std_msgs/Float64MultiArray with an empty layout (no dims, offset 0)."""
        buf = _Buffer()
        buf.raw4(_U32.pack(0) + _U32.pack(0))
        buf.float64_sequence(np.asarray(values, dtype=float))
        return bytes(buf.b)

    @staticmethod
    def float64(value: float) -> bytes:
        buf = _Buffer()
        buf.doubles(_F64.pack(float(value)))
        return bytes(buf.b)

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
    ) -> list[tuple[str, bytes]]:
        """(topic, CDR bytes) of one tick, in the order and on the conditions of
        :meth:`TickMessages.tick <coassist.data.trial_mcap.TickMessages.tick>` (its arguments:
        ``prediction`` (H, ≤ 6), the missing axes taken from ``pose6``)."""
        return list(
            self.messages(ns, pose6, velocity6, wrench6, reference6, prediction, alpha, flags, joints, joint_velocity)
        )

    def messages(
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
    ) -> Iterator[tuple[str, bytes]]:
        """:meth:`tick`, one message at a time (each encoded when it is asked for)."""
        yield "/current_pose", self.pose_stamped(ns, pose6)
        yield "/current_velocity", self._six(ns, velocity6)
        yield "/human_wrench", self._six(ns, wrench6)
        yield "/robot_ref_pos", self.pose_stamped(ns, reference6)
        if prediction is not None and np.all(np.isfinite(prediction)):
            rows = np.tile(np.asarray(pose6, dtype=float), (prediction.shape[0], 1))
            rows[:, : prediction.shape[1]] = prediction
            yield "/prediction", self.path(ns, rows)
        if alpha is not None and math.isfinite(alpha):
            yield "/alpha", self.float64(alpha)
        yield "/faults", self.faults(ns, int(flags))
        if joints is not None:
            yield "/joint_states", self.joint_state(ns, joints)
            qd = np.zeros(len(joints)) if joint_velocity is None else joint_velocity
            yield "/forward_velocity_controller/commands", self.float64_multi_array(qd)
