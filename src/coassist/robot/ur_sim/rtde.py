"""The RTDE wire format (port 30004): package framing, field names and types, recipes.

From UR's RTDE guide (the field → type table) and ``rtde/serialize.py`` of UR's Python client
library (the serialisation); every number is big-endian. A package is::

    size : uint16   the whole package in bytes, these 3 header bytes included
    type : uint8    one of the package types below (an ASCII letter)
    payload

Package types and payloads (protocol version 2, the one ur_rtde asks for):

=====  ====  ====================================  ==========================================
type   char  client → controller                   controller → client
=====  ====  ====================================  ==========================================
86     V     uint16 protocol version               uint8 accepted (1/0)
118    v     (empty)                               uint32 major, minor, bugfix, build
79     O     double frequency [Hz] + "a,b,c" names  uint8 recipe id + "TYPE,TYPE,…"
73     I     "a,b,c" names                          uint8 recipe id + "TYPE,TYPE,…"
83     S     (empty)                               uint8 accepted
80     P     (empty)                               uint8 accepted
85     U     uint8 input recipe id + values         uint8 output recipe id + values
77     M     —                                      uint8 n + message, uint8 n + source, uint8 level
=====  ====  ====================================  ==========================================

A setup reply names the type of every field in order; a name the controller does not have
is ``NOT_FOUND`` (the recipe is then refused: id 0), an input another connection already
writes is ``IN_USE`` (refused too). Values are packed in the recipe's order with the types'
struct codes (:data:`STRUCT_CODES`).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

from coassist.errors import CoassistError

__all__ = [
    "INPUT_FIELDS",
    "OUTPUT_FIELDS",
    "STRUCT_CODES",
    "FieldError",
    "PackageReader",
    "Recipe",
    "field_available",
    "package",
    "text_message",
]

REQUEST_PROTOCOL_VERSION = 86
GET_URCONTROL_VERSION = 118
TEXT_MESSAGE = 77
DATA_PACKAGE = 85
CONTROL_PACKAGE_SETUP_OUTPUTS = 79
CONTROL_PACKAGE_SETUP_INPUTS = 73
CONTROL_PACKAGE_START = 83
CONTROL_PACKAGE_PAUSE = 80

HEADER = struct.Struct(">HB")
#: Largest package: the size field is a uint16.
MAX_PACKAGE = 0xFFFF

#: struct codes of the RTDE types (big-endian packing is added by :class:`Recipe`).
STRUCT_CODES = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}
#: Values per field of each type (1 for a scalar).
WIDTH = {t: (int(c[:-1]) if len(c) > 1 else 1) for t, c in STRUCT_CODES.items()}


def _registers(prefix: str, kind: str, n: int = 48) -> dict[str, str]:
    return {f"{prefix}_{kind}_register_{i}": ("INT32" if kind == "int" else "DOUBLE") for i in range(n)}


def _bit_registers(prefix: str) -> dict[str, str]:
    out = {f"{prefix}_bit_registers0_to_31": "UINT32", f"{prefix}_bit_registers32_to_63": "UINT32"}
    out.update({f"{prefix}_bit_register_{i}": "BOOL" for i in range(64, 128)})
    return out


#: What a client may write (input recipes), name → type (the RTDE guide's inputs).
INPUT_FIELDS: dict[str, str] = {
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
    "external_force_torque": "VECTOR6D",
    **_bit_registers("input"),
    **_registers("input", "int"),
    **_registers("input", "double"),
}

#: What the controller sends (output recipes), name → type (the RTDE guide's outputs).
OUTPUT_FIELDS: dict[str, str] = {
    "timestamp": "DOUBLE",
    "target_q": "VECTOR6D",
    "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D",
    "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D",
    "actual_current": "VECTOR6D",
    "actual_current_window": "VECTOR6D",
    "actual_current_as_torque": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",
    "actual_TCP_speed": "VECTOR6D",
    "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D",
    "tcp_offset": "VECTOR6D",
    "actual_digital_input_bits": "UINT64",
    "actual_configurable_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE",
    "target_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64",
    "actual_configurable_digital_output_bits": "UINT64",
    "runtime_state": "UINT32",
    "elbow_position": "VECTOR3D",
    "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE",
    "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32",
    "tool_analog_input0": "DOUBLE",
    "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32",
    "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE",
    "ft_raw_wrench": "VECTOR6D",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D",
    "script_control_line": "UINT32",
    "target_gravity": "VECTOR3D",
    "control_step": "UINT64",
    **_bit_registers("output"),
    **_registers("output", "int"),
    **_registers("output", "double"),
    # the input registers can be read back as outputs
    **_bit_registers("input"),
    **_registers("input", "int"),
    **_registers("input", "double"),
}

#: Fields newer than the first RTDE controllers: ``name → ((CB3 major, minor, bugfix), (e-Series …))``,
#: the first software that has them (the versions ur_rtde checks before asking); None: not on that line.
_SINCE: dict[str, tuple[tuple[int, int, int] | None, tuple[int, int, int] | None]] = {
    "ft_raw_wrench": (None, (5, 9, 0)),
    "payload": ((3, 11, 0), (5, 5, 1)),
    "payload_cog": ((3, 11, 0), (5, 5, 1)),
    "payload_inertia": ((3, 15, 0), (5, 11, 0)),
    "tcp_offset": ((3, 6, 0), (5, 0, 0)),
    "target_gravity": ((3, 15, 0), (5, 11, 0)),
    "control_step": (None, (5, 23, 0)),
}
#: The double and int output registers 0-23 came with 3.4 (CB3) / 5.0; 24-47 with 3.9 / 5.3.
_REGISTER_SINCE: dict[bool, tuple[tuple[int, int, int] | None, tuple[int, int, int] | None]] = {
    False: ((3, 4, 0), (5, 0, 0)),
    True: ((3, 9, 0), (5, 3, 0)),
}


def field_available(name: str, version: Sequence[int]) -> bool:
    """Whether a controller of software ``version`` (major, minor, bugfix, …) knows the output ``name``."""
    major = int(version[0])
    here = tuple(int(v) for v in version[:3])
    since: tuple[tuple[int, int, int] | None, tuple[int, int, int] | None]
    if name.startswith(("output_int_register_", "output_double_register_")):
        since = _REGISTER_SINCE[int(name.rsplit("_", 1)[1]) >= 24]
    else:
        since = _SINCE.get(name, ((0, 0, 0), (0, 0, 0)))
    first = since[0] if major < 5 else since[1]
    return first is not None and here >= first


class FieldError(CoassistError, ValueError):
    """A recipe names a field the controller refuses (``NOT_FOUND`` / ``IN_USE``)."""


@dataclass(frozen=True)
class Recipe:
    """One recipe: its id, its fields' names and RTDE types, and their big-endian struct.

    id : the recipe id (uint8; 1 upward per connection, in setup order).
    names, types : the fields in the client's order and their RTDE type names.
    """

    id: int
    names: tuple[str, ...]
    types: tuple[str, ...]

    def __post_init__(self) -> None:
        if len(self.names) != len(self.types):
            raise ValueError("Recipe: one type per name")
        object.__setattr__(self, "_struct", struct.Struct(">" + "".join(STRUCT_CODES[t] for t in self.types)))

    @property
    def size(self) -> int:
        """Bytes of one package's values (the recipe id excluded)."""
        return self._struct.size  # type: ignore[attr-defined]

    def pack(self, values: Sequence[object]) -> bytes:
        """A data package ('U') of this recipe: the id, then ``values`` (one per field; a vector a sequence)."""
        flat: list[object] = []
        for t, v in zip(self.types, values, strict=True):
            if WIDTH[t] == 1:
                flat.append(v)
            else:
                flat.extend(v)  # type: ignore[arg-type]
        return package(DATA_PACKAGE, bytes((self.id,)) + self._struct.pack(*flat))  # type: ignore[attr-defined]

    def unpack(self, payload: bytes) -> dict[str, object]:
        """The values of a data package's payload after its recipe id byte, name → value (vectors as tuples).

        Raises :class:`ValueError` when the payload is not this recipe's size.
        """
        if len(payload) != self.size:
            raise ValueError(f"recipe {self.id}: {len(payload)} bytes of values, expected {self.size}")
        flat = self._struct.unpack(payload)  # type: ignore[attr-defined]
        out: dict[str, object] = {}
        i = 0
        for name, t in zip(self.names, self.types, strict=True):
            w = WIDTH[t]
            out[name] = flat[i] if w == 1 else tuple(flat[i : i + w])
            i += w
        return out


def package(kind: int, payload: bytes = b"") -> bytes:
    """One framed package: the 3-byte header (size, type) and ``payload``."""
    size = HEADER.size + len(payload)
    if size > MAX_PACKAGE:
        raise ValueError(f"an RTDE package holds at most {MAX_PACKAGE} bytes, this one {size}")
    return HEADER.pack(size, kind) + payload


def text_message(message: str, source: str = "URControl", level: int = 1) -> bytes:
    """A text message package ('M', protocol 2): ``level`` 0 exception, 1 error, 2 warning, 3 info."""
    m, s = message.encode()[:255], source.encode()[:255]
    return package(TEXT_MESSAGE, bytes((len(m),)) + m + bytes((len(s),)) + s + bytes((level,)))


class PackageReader:
    """Splits a byte stream into packages: :meth:`feed` bytes, iterate ``(type, payload)``.

    Raises :class:`ValueError` from :meth:`feed` on a size below the header's (the stream is
    then out of step and the connection must be closed, as the controller does).
    """

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> Iterator[tuple[int, bytes]]:
        """Add ``data``; yield every package now complete, in order."""
        self._buf += data
        while len(self._buf) >= HEADER.size:
            size, kind = HEADER.unpack_from(self._buf)
            if size < HEADER.size:
                raise ValueError(f"RTDE package of size {size} (below its own 3-byte header)")
            if len(self._buf) < size:
                return
            payload = bytes(self._buf[HEADER.size : size])
            del self._buf[:size]
            yield kind, payload


def split_names(payload: bytes) -> list[str]:
    """The comma-separated field names of a setup package (a trailing comma, as ur_rtde sends, is dropped)."""
    text = payload.decode("ascii", errors="replace")
    return [n.strip() for n in text.split(",") if n.strip()]


def join_types(types: Iterable[str]) -> bytes:
    return ",".join(types).encode()
