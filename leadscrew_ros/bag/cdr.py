# SPDX-License-Identifier: Apache-2.0
"""Small CDR codec of the few message types the package reads and writes, without rclpy.

Decoders (std_msgs/Float64, Bool, Float64MultiArray, Float32MultiArray and
sensor_msgs/JointState; XCDR1 as Fast CDR and rosbags write it, either byte order) for what the
replay reads from logs, the demo's monitor receives and the node's microphone hears. Encoders
(the same types and diagnostic_msgs/DiagnosticArray) for what the node publishes and records,
the replay annotates and the synthetic logs hold: XCDR1 little endian, alignment counted from
the end of the 4-byte encapsulation header, padding zero and no unused tail, byte for byte the
payload Fast CDR writes with its padding zeroed and its slack cut (test/harness/cdr_reference.py
checks this against rclpy's serializer).

Log data is untrusted, so every length and count is checked against the payload before it is
used and any malformation raises ValueError. (The offline replay never hands log data to
rclpy's `deserialize_message`, which leaves rcutils error state behind on corrupt bytes;
`replay --publish` does, once per payload in its up-front check, and never sends a payload that
fails it.) Bytes after the last field are
ignored: Fast CDR may pad a payload.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

_ENCAPSULATION = {b"\x00\x00": ">", b"\x00\x01": "<"}  # CDR_BE, CDR_LE
_HEADER = 4  # encapsulation kind + options
_U32 = {e: struct.Struct(e + "I") for e in "<>"}
_F64 = {e: struct.Struct(e + "d") for e in "<>"}
_STAMP = {e: struct.Struct(e + "iI") for e in "<>"}
_LE_HEADER = b"\x00\x01\x00\x00"  # CDR_LE, no options
_F64_LE, _U32_LE, _TWO_U32_LE = struct.Struct("<d"), struct.Struct("<I"), struct.Struct("<II")
_PAD = [bytes(n) for n in range(9)]  # NUL, alignment padding
_BOOL_PAYLOADS = {False: _LE_HEADER + b"\x00", True: _LE_HEADER + b"\x01"}

# 'pkg/msg/Type' of the types this module knows.
FLOAT64, BOOL = "std_msgs/msg/Float64", "std_msgs/msg/Bool"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
FLOAT32_MULTI_ARRAY = "std_msgs/msg/Float32MultiArray"
JOINT_STATE = "sensor_msgs/msg/JointState"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"  # bundled for logs written without ROS


class JointStateData(NamedTuple):
    """sensor_msgs/JointState: the header stamp [ns] and frame, and per joint its name,
    position, velocity and effort (each may be empty)."""

    stamp_ns: int
    frame_id: str
    name: tuple[str, ...]
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    effort: tuple[float, ...]


class Dimension(NamedTuple):
    """std_msgs/MultiArrayDimension."""

    label: str
    size: int
    stride: int


class Float64MultiArrayData(NamedTuple):
    """std_msgs/Float64MultiArray: the layout (dimensions, data offset) and the data."""

    dim: tuple[Dimension, ...]
    data_offset: int
    data: tuple[float, ...]


class Float32MultiArrayData(NamedTuple):
    """std_msgs/Float32MultiArray: the layout (dimensions, data offset) and the data (float32,
    native byte order, a copy of the payload's)."""

    dim: tuple[Dimension, ...]
    data_offset: int
    data: np.ndarray


class DiagnosticStatusData(NamedTuple):
    """diagnostic_msgs/DiagnosticStatus: `values` are (key, value) pairs."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...] = ()


def _endian(data: bytes) -> str:
    if len(data) < _HEADER:
        raise ValueError(f"CDR payload of {len(data)} bytes has no encapsulation header")
    endian = _ENCAPSULATION.get(bytes(data[:2]))
    if endian is None:
        raise ValueError(f"unsupported CDR encapsulation 0x{bytes(data[:2]).hex()}")
    return endian


def decode_float64(data: bytes) -> float:
    """std_msgs/Float64: the value."""
    endian = _endian(data)
    if len(data) < _HEADER + 8:
        raise ValueError(f"Float64 payload of {len(data)} bytes, expected 12")
    return _F64[endian].unpack_from(data, _HEADER)[0]


def decode_bool(data: bytes) -> bool:
    """std_msgs/Bool: the value (a byte other than 0 or 1 is malformed)."""
    _endian(data)
    _check(data, _HEADER + 1)
    if data[_HEADER] > 1:
        raise ValueError(f"Bool payload holds {data[_HEADER]}, not 0 or 1")
    return bool(data[_HEADER])


def _aligned(pos: int, align: int) -> int:
    """`pos` moved up to a multiple of `align` counted from the CDR body (after the header)."""
    return pos + (_HEADER - pos) % align


def _check(data: bytes, end: int) -> None:
    if end > len(data):
        raise ValueError(f"CDR payload cut off at byte {len(data)} (needs {end})")


def _count(data: bytes, pos: int, endian: str, item_size: int) -> tuple[int, int]:
    """A sequence length at `pos` (refused if the rest of the payload cannot hold it) and the
    position after it."""
    pos = _aligned(pos, 4)
    _check(data, pos + 4)
    (n,) = _U32[endian].unpack_from(data, pos)
    if n * item_size > len(data) - pos - 4:
        raise ValueError(f"sequence of {n} items overruns the payload")
    return n, pos + 4


def _string(data: bytes, pos: int, endian: str) -> tuple[str, int]:
    n, pos = _count(data, pos, endian, 1)
    if n == 0 or data[pos + n - 1] != 0:
        raise ValueError("string not terminated by NUL")
    try:
        return bytes(data[pos : pos + n - 1]).decode("utf-8"), pos + n
    except UnicodeDecodeError as exc:
        raise ValueError(f"string is not UTF-8: {exc.reason}") from None


def _float64s(data: bytes, pos: int, endian: str) -> tuple[tuple[float, ...], int]:
    n, pos = _count(data, pos, endian, 8)
    if n == 0:
        return (), pos
    pos = _aligned(pos, 8)
    _check(data, pos + 8 * n)
    return struct.unpack_from(f"{endian}{n}d", data, pos), pos + 8 * n


# The frame and joint names of the last JointState decoded: (endian, their bytes, frame_id,
# names, position after them). A stream repeats them in every message, so a message whose
# bytes there are the same skips parsing them (one tuple, replaced whole: thread-safe).
_names_seen: tuple[str, bytes, str, tuple[str, ...], int] = ("", b"", "", (), 0)


def decode_joint_state(data: bytes) -> JointStateData:
    """sensor_msgs/JointState: header stamp and frame, joint names, position, velocity, effort."""
    global _names_seen
    endian = _endian(data)
    _check(data, _HEADER + 8)
    sec, nanosec = _STAMP[endian].unpack_from(data, _HEADER)
    seen_endian, seen, frame_id, names, pos = _names_seen
    if endian != seen_endian or data[_HEADER + 8 : pos] != seen:
        frame_id, pos = _string(data, _HEADER + 8, endian)
        count, pos = _count(data, pos, endian, 5)  # a string: u32 length + NUL at least
        parsed = []
        for _ in range(count):
            name, pos = _string(data, pos, endian)
            parsed.append(name)
        names = tuple(parsed)
        _names_seen = (endian, bytes(data[_HEADER + 8 : pos]), frame_id, names, pos)
    position, pos = _float64s(data, pos, endian)
    velocity, pos = _float64s(data, pos, endian)
    effort, _ = _float64s(data, pos, endian)
    return JointStateData(
        sec * 1_000_000_000 + nanosec, frame_id, names, position, velocity, effort
    )


def _layout(data: bytes, endian: str) -> tuple[tuple[Dimension, ...], int, int]:
    """std_msgs/MultiArrayLayout at the start of the body: dimensions, data offset and the
    position after it."""
    count, pos = _count(data, _HEADER, endian, 13)  # string (5 bytes at least), 2 x u32
    dims = []
    for _ in range(count):
        label, pos = _string(data, pos, endian)
        pos = _aligned(pos, 4)
        _check(data, pos + 8)
        size, stride = struct.unpack_from(endian + "II", data, pos)
        dims.append(Dimension(label, size, stride))
        pos += 8
    pos = _aligned(pos, 4)
    _check(data, pos + 4)
    (offset,) = _U32[endian].unpack_from(data, pos)
    return tuple(dims), offset, pos + 4


def decode_float64_multi_array(data: bytes) -> Float64MultiArrayData:
    """std_msgs/Float64MultiArray: layout dimensions, data offset and data."""
    endian = _endian(data)
    dims, offset, pos = _layout(data, endian)
    values, _ = _float64s(data, pos, endian)
    return Float64MultiArrayData(dims, offset, values)


def decode_float32_multi_array(data: bytes) -> Float32MultiArrayData:
    """std_msgs/Float32MultiArray: layout dimensions, data offset and data."""
    endian = _endian(data)
    dims, offset, pos = _layout(data, endian)
    n, pos = _count(data, pos, endian, 4)
    values = np.frombuffer(data, dtype=f"{endian}f4", count=n, offset=pos)
    return Float32MultiArrayData(dims, offset, values.astype(np.float32))


# ---------------------------------------------------------------------- encoders
class _Encoder:
    """Appends XCDR1 little-endian fields to a payload; a value out of its field's range
    raises ValueError."""

    def __init__(self) -> None:
        self.out = bytearray(_LE_HEADER)

    def _align(self, size: int) -> None:
        self.out += bytes(-(len(self.out) - _HEADER) % size)

    def _pack(self, fmt: str, size: int, *values: float) -> None:
        self._align(size)
        try:
            self.out += struct.pack("<" + fmt, *values)
        except struct.error as exc:
            raise ValueError(f"{values} does not fit CDR '{fmt}': {exc}") from None

    def octet(self, value: int) -> None:
        self._pack("B", 1, value)

    def u32(self, value: int) -> None:
        self._pack("I", 4, value)

    def string(self, value: str) -> None:
        raw = value.encode("utf-8")  # surrogates: UnicodeEncodeError
        if b"\x00" in raw:
            raise ValueError(f"string {value!r} holds a NUL, which ends a CDR string")
        self.u32(len(raw) + 1)
        self.out += raw + b"\x00"

    def strings(self, values: Sequence[str]) -> None:
        self.u32(len(values))
        for v in values:
            self.string(v)

    def f64s(self, values: Sequence[float]) -> None:
        """A float64 sequence (an empty one is not aligned for its elements, as Fast CDR)."""
        self.u32(len(values))
        if len(values):
            self._pack(f"{len(values)}d", 8, *values)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        """std_msgs/Header: stamp (builtin_interfaces/Time: int32 s, uint32 ns) and frame."""
        self._pack("iI", 4, *divmod(stamp_ns, 1_000_000_000))
        self.string(frame_id)

    def payload(self) -> bytes:
        return bytes(self.out)


def encode_float64(value: float) -> bytes:
    """std_msgs/Float64 (the value right after the header: already aligned)."""
    try:
        return _LE_HEADER + _F64_LE.pack(value)
    except struct.error as exc:
        raise ValueError(f"{value!r} does not fit CDR 'd': {exc}") from None


def encode_bool(value: bool) -> bytes:
    """std_msgs/Bool."""
    return _BOOL_PAYLOADS[bool(value)]


def encode_float64_multi_array(
    dim: tuple[Dimension, ...], data: Sequence[float], data_offset: int = 0
) -> bytes:
    """std_msgs/Float64MultiArray of layout dimensions `dim` and values `data` (written
    directly: every prediction publishes two)."""
    out = bytearray(_LE_HEADER)
    try:
        out += _U32_LE.pack(len(dim))
        for d in dim:  # label, size, stride: ends 4-aligned
            raw = d.label.encode("utf-8")
            if b"\x00" in raw:
                raise ValueError(f"string {d.label!r} holds a NUL, which ends a CDR string")
            out += _U32_LE.pack(len(raw) + 1)
            out += raw
            out += _PAD[1 + -(len(raw) + 1) % 4]  # the NUL and the padding
            out += _TWO_U32_LE.pack(d.size, d.stride)
        out += _TWO_U32_LE.pack(data_offset, len(data))
        if len(data):
            out += _PAD[-(len(out) - _HEADER) % 8]
            out += struct.pack(f"<{len(data)}d", *data)
    except struct.error as exc:
        raise ValueError(f"a Float64MultiArray field does not fit CDR: {exc}") from None
    return bytes(out)


def encode_joint_state(msg: JointStateData) -> bytes:
    """sensor_msgs/JointState."""
    e = _Encoder()
    e.header(msg.stamp_ns, msg.frame_id)
    e.strings(msg.name)
    for values in (msg.position, msg.velocity, msg.effort):
        e.f64s(values)
    return e.payload()


def encode_diagnostic_array(
    stamp_ns: int, status: tuple[DiagnosticStatusData, ...], frame_id: str = ""
) -> bytes:
    """diagnostic_msgs/DiagnosticArray stamped `stamp_ns` [ns since the epoch]."""
    e = _Encoder()
    e.header(stamp_ns, frame_id)
    e.u32(len(status))
    for s in status:
        e.octet(s.level)
        for text in (s.name, s.message, s.hardware_id):
            e.string(text)
        e.u32(len(s.values))
        for key, value in s.values:
            e.string(key)
            e.string(value)
    return e.payload()
