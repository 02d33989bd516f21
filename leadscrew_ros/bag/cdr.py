# SPDX-License-Identifier: Apache-2.0
"""Small, defensive decoders of the CDR payloads the replay reads from logs: std_msgs/Float64
and sensor_msgs/JointState (XCDR1 as Fast CDR and rosbags write it, either byte order).

Log data is untrusted, so every length and count is checked against the payload before it is
used and any malformation raises ValueError. (The offline replay never hands log data to
rclpy's `deserialize_message`, which leaves rcutils error state behind on corrupt bytes;
`replay --publish` does, once per payload in its up-front check, and never sends a payload that
fails it.) Bytes after the last field are
ignored: Fast CDR may pad a payload.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

_ENCAPSULATION = {b"\x00\x00": ">", b"\x00\x01": "<"}     # CDR_BE, CDR_LE
_HEADER = 4                                                # encapsulation kind + options
_U32 = {e: struct.Struct(e + "I") for e in "<>"}
_F64 = {e: struct.Struct(e + "d") for e in "<>"}
_STAMP = {e: struct.Struct(e + "iI") for e in "<>"}


class JointStateData(NamedTuple):
    stamp_ns: int
    frame_id: str
    name: tuple[str, ...]
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    effort: tuple[float, ...]


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
        return bytes(data[pos:pos + n - 1]).decode("utf-8"), pos + n
    except UnicodeDecodeError as exc:
        raise ValueError(f"string is not UTF-8: {exc.reason}") from None


def _float64s(data: bytes, pos: int, endian: str) -> tuple[tuple[float, ...], int]:
    n, pos = _count(data, pos, endian, 8)
    if n == 0:
        return (), pos
    pos = _aligned(pos, 8)
    _check(data, pos + 8 * n)
    return struct.unpack_from(f"{endian}{n}d", data, pos), pos + 8 * n


def decode_joint_state(data: bytes) -> JointStateData:
    """sensor_msgs/JointState: header stamp and frame, joint names, position, velocity, effort."""
    endian = _endian(data)
    _check(data, _HEADER + 8)
    sec, nanosec = _STAMP[endian].unpack_from(data, _HEADER)
    frame_id, pos = _string(data, _HEADER + 8, endian)
    count, pos = _count(data, pos, endian, 5)           # a string: u32 length + NUL at least
    names = []
    for _ in range(count):
        name, pos = _string(data, pos, endian)
        names.append(name)
    position, pos = _float64s(data, pos, endian)
    velocity, pos = _float64s(data, pos, endian)
    effort, _ = _float64s(data, pos, endian)
    return JointStateData(sec * 1_000_000_000 + nanosec, frame_id, tuple(names), position,
                          velocity, effort)
