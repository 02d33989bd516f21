# SPDX-License-Identifier: Apache-2.0
"""Test helper: the reference CDR payloads of rclpy messages that `leadscrew_ros.bag.cdr`'s
encoders must reproduce byte for byte, and `write_message` to record an rclpy message.

Fast CDR (through `rclpy.serialization`) leaves alignment padding unwritten, so stray process
memory lands in a log and one message serializes to different bytes; and it sizes the buffer
with alignment for empty sequences that it then does not use, leaving up to 4 such bytes per
empty sequence at the end, which strict readers (`rosbags`) reject. `cdr_payload` zeroes the
padding and cuts the payload at the end of the data; Fast CDR reads the result back
identically. The layout walk (XCDR1, as Fast CDR writes it) is compiled once per message class.
"""

from __future__ import annotations

import functools

from rclpy.serialization import serialize_message

from leadscrew_ros.bag import msgdefs

_BASIC_SIZE = {
    "boolean": 1,
    "octet": 1,
    "char": 1,
    "int8": 1,
    "uint8": 1,
    "int16": 2,
    "uint16": 2,
    "int32": 4,
    "uint32": 4,
    "float": 4,
    "int64": 8,
    "uint64": 8,
    "double": 8,
}
# Field kinds of a compiled layout.
_BASIC, _STRING, _NESTED, _SEQUENCE, _ARRAY = range(5)
_ENCAPSULATION = 4  # bytes of the CDR header before the data


class _Unsized(Exception):
    """A field type whose CDR size this module does not know (e.g. wstring, long double)."""


def cdr_payload(msg) -> bytes:
    """`serialize_message(msg)` with the padding zeroed and the unused tail cut."""
    data = serialize_message(msg)
    layout = _layout(type(msg))
    if layout is None:
        return data
    gaps: list[tuple[int, int]] = []
    end = _ENCAPSULATION + _walk(msg, layout, 0, gaps)
    if end > len(data):  # not the layout we expect: leave the bytes alone
        return data
    if not gaps:
        return data[:end]
    out = bytearray(data[:end])
    for start, stop in gaps:
        out[_ENCAPSULATION + start : _ENCAPSULATION + stop] = bytes(stop - start)
    return bytes(out)


@functools.cache
def _layout(cls) -> tuple | None:
    """((field, kind, element), ...) of a message class; None if a field is unsized."""
    try:
        return tuple(
            (name, *_kind(slot))
            for name, slot in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES, strict=True)
        )
    except _Unsized:
        return None


def _kind(slot) -> tuple[int, object]:
    kind = type(slot).__name__
    if kind == "BasicType":
        if slot.typename not in _BASIC_SIZE:
            raise _Unsized(slot.typename)
        return _BASIC, _BASIC_SIZE[slot.typename]
    if kind in ("UnboundedString", "BoundedString"):
        return _STRING, None
    if kind == "NamespacedType":
        return _NESTED, _nested_layout(slot)
    if kind in ("UnboundedSequence", "BoundedSequence", "Array"):
        return (_ARRAY if kind == "Array" else _SEQUENCE), _kind(slot.value_type)
    raise _Unsized(kind)


def _nested_layout(slot) -> tuple:
    import importlib

    module = importlib.import_module(".".join(slot.namespaces))
    layout = _layout(getattr(module, slot.name))
    if layout is None:
        raise _Unsized(slot.name)
    return layout


def _align(pos: int, size: int, gaps: list) -> int:
    pad = -pos % size
    if pad:
        gaps.append((pos, pos + pad))
    return pos + pad


def _walk(msg, layout: tuple, pos: int, gaps: list) -> int:
    """Offset after the last byte of `msg` serialized at `pos`; alignment gaps go to `gaps`."""
    for name, kind, element in layout:
        pos = _value(getattr(msg, name), kind, element, pos, gaps)
    return pos


def _value(value, kind: int, element, pos: int, gaps: list) -> int:
    if kind == _BASIC:
        return _align(pos, element, gaps) + element
    if kind == _STRING:
        return _align(pos, 4, gaps) + 4 + len(value.encode()) + 1
    if kind == _NESTED:
        return _walk(value, element, pos, gaps)
    if kind == _SEQUENCE:
        pos = _align(pos, 4, gaps) + 4
    if len(value) == 0:  # an empty sequence is not aligned for its elements
        return pos
    item_kind, item = element
    if item_kind == _BASIC:
        return _align(pos, item, gaps) + item * len(value)
    for v in value:
        pos = _value(v, item_kind, item, pos, gaps)
    return pos


def write_message(
    recorder, topic: str, msg, log_time_ns: int | None = None, publish_time_ns: int | None = None
) -> None:
    """Record an rclpy message with `Recorder.write_serialized` (publish time defaults to the
    header stamp, else the log time, as the node records its outputs)."""
    if publish_time_ns is None:
        stamp = getattr(getattr(msg, "header", None), "stamp", None)
        if stamp is not None:
            publish_time_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
    recorder.write_serialized(
        topic, msgdefs.type_name(msg), cdr_payload(msg), log_time_ns, publish_time_ns
    )
