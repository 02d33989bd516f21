# SPDX-License-Identifier: Apache-2.0
"""The CDR codec of `leadscrew_ros.bag.cdr` against rclpy's and rosbags' serializers: decoders
read what both write, malformed payloads raise ValueError and nothing else; encoders write
exactly rclpy's payload (`cdr_reference.cdr_payload`: Fast CDR's bytes, padding zeroed and
slack cut), which rclpy and rosbags read back as the message."""

import array
import dataclasses
import math
import struct

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from harness.cdr_reference import cdr_payload
from leadscrew_ros.bag import cdr, msgdefs
from leadscrew_ros.bag.cdr import decode_float64, decode_joint_state

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
FLOATS = st.floats(allow_nan=False, width=64)
NAMES = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12)


def joint_state(names, position, velocity, effort, sec=12, nanosec=345, frame="base"):
    msg = JointState(
        name=list(names), position=list(position), velocity=list(velocity), effort=list(effort)
    )
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = sec, nanosec, frame
    return msg


def rosbags_joint_state(little_endian: bool, names, position, velocity):
    import numpy as np

    t = TYPESTORE.types
    header = t["std_msgs/msg/Header"](t["builtin_interfaces/msg/Time"](7, 8), "frame")
    msg = t["sensor_msgs/msg/JointState"](
        header,
        list(names),
        np.array(position, float),
        np.array(velocity, float),
        np.array([], float),
    )
    return TYPESTORE.serialize_cdr(msg, "sensor_msgs/msg/JointState", little_endian=little_endian)


@given(FLOATS)
@settings(max_examples=50, deadline=None, derandomize=True)
def test_float64_round_trip_through_rclpy(value):
    assert decode_float64(cdr_payload(Float64(data=value))) == value


@pytest.mark.parametrize("little_endian", [True, False])
def test_float64_both_byte_orders(little_endian):
    msg = TYPESTORE.types["std_msgs/msg/Float64"](-2.5)
    data = TYPESTORE.serialize_cdr(msg, "std_msgs/msg/Float64", little_endian=little_endian)
    assert decode_float64(data) == -2.5


def test_float64_nan_and_padding_pass_through():
    assert math.isnan(decode_float64(b"\x00\x01\x00\x00" + struct.pack("<d", math.nan)))
    assert decode_float64(b"\x00\x01\x00\x00" + struct.pack("<d", 1.0) + b"\x00" * 4) == 1.0


@pytest.mark.parametrize(
    "data, problem",
    [
        (b"", "no encapsulation header"),
        (b"\x00\x01\x00\x00\x00\x00\x00\x00", "expected 12"),
        (b"\x00\x03\x00\x00" + bytes(8), "unsupported CDR encapsulation"),
        (b"\x01\x00\x00\x00" + bytes(8), "unsupported CDR encapsulation"),
    ],
)
def test_float64_malformed(data, problem):
    with pytest.raises(ValueError, match=problem):
        decode_float64(data)


@given(
    st.lists(NAMES, max_size=4),
    st.lists(FLOATS, max_size=4),
    st.lists(FLOATS, max_size=4),
    st.lists(FLOATS, max_size=3),
    NAMES,
)
@settings(max_examples=60, deadline=None, derandomize=True)
def test_joint_state_round_trip_through_rclpy(names, position, velocity, effort, frame):
    d = decode_joint_state(cdr_payload(joint_state(names, position, velocity, effort, frame=frame)))
    assert d == (
        12_000_000_345,
        frame,
        tuple(names),
        tuple(position),
        tuple(velocity),
        tuple(effort),
    )


@pytest.mark.parametrize("little_endian", [True, False])
def test_joint_state_both_byte_orders(little_endian):
    d = decode_joint_state(
        rosbags_joint_state(little_endian, ["a", "screw"], [1.0, -2.0], [3.5, 4.5])
    )
    assert d.stamp_ns == 7_000_000_008 and d.frame_id == "frame"
    assert d.name == ("a", "screw") and d.position == (1.0, -2.0) and d.velocity == (3.5, 4.5)
    assert d.effort == ()


def test_joint_state_every_truncation_is_a_value_error():
    data = cdr_payload(joint_state(["screw"], [1.0], [2.0], []))
    for cut in range(len(data)):
        with pytest.raises(ValueError):
            decode_joint_state(data[:cut])


# Layout: encapsulation 0-3, stamp 4-11, frame_id length 12-15, "base\0" 16-20, name count 24.
@pytest.mark.parametrize(
    "patch, problem",
    [
        ((24, struct.pack("<I", 10**9)), "overruns"),  # name count
        ((12, struct.pack("<I", 0)), "not terminated"),  # frame_id length 0
        ((20, b"\x01"), "not terminated"),  # frame_id NUL overwritten
    ],
)
def test_joint_state_malformed(patch, problem):
    data = bytearray(cdr_payload(joint_state(["screw"], [1.0], [2.0], [], frame="base")))
    offset, raw = patch
    data[offset : offset + len(raw)] = raw
    with pytest.raises(ValueError, match=problem):
        decode_joint_state(bytes(data))


def test_joint_state_name_not_utf8():
    data = bytearray(cdr_payload(joint_state(["screw"], [], [], [], frame="base")))
    data[data.index(b"screw")] = 0xFF
    with pytest.raises(ValueError, match="not UTF-8"):
        decode_joint_state(bytes(data))


@given(st.binary(max_size=80))
@settings(max_examples=300, deadline=None, derandomize=True)
def test_random_bytes_decode_or_raise_value_error(data):
    for decode in (decode_float64, decode_joint_state):
        try:
            decode(data)
        except ValueError:
            pass


@given(st.data())
@settings(max_examples=100, deadline=None, derandomize=True)
def test_flipped_bits_decode_or_raise_value_error(data):
    payload = bytearray(cdr_payload(joint_state(["screw", "x"], [1.0, 2.0], [3.0], [4.0])))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(payload) - 1))
        payload[i] ^= 1 << data.draw(st.integers(0, 7))
    try:
        decode_joint_state(bytes(payload))
    except ValueError:
        pass


# ---------------------------------------------------------------------- encoders
ANY_FLOAT = st.floats(width=64)  # NaN, +-inf and -0.0 included
TEXT = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=24)
U32 = st.integers(0, 2**32 - 1)
STAMPS = st.tuples(st.integers(-(2**31), 2**31 - 1), st.integers(0, 999_999_999))


def sequences(element, long_size: int = 300):
    """Empty, short and long sequences: every length modulo the alignments."""
    return st.one_of(
        st.lists(element, max_size=5), st.lists(element, min_size=long_size, max_size=long_size + 7)
    )


def plain(value):
    """An rclpy or rosbags message as nested lists/dicts; floats as their 8 bytes (NaN, -0.0
    compare exactly), one-byte `bytes` (rclpy 'byte' fields) as ints."""
    if isinstance(value, (bytes, bytearray)) and len(value) == 1:
        return value[0]
    if isinstance(value, (float, np.floating)):
        return struct.pack("<d", value)
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    if isinstance(value, (list, tuple, array.array, np.ndarray)):
        return [plain(v) for v in value]
    fields = getattr(value, "get_fields_and_field_types", None)
    if fields is not None:  # rclpy
        return {n: plain(getattr(value, n)) for n in fields()}
    if dataclasses.is_dataclass(value):  # rosbags
        out = {
            f.name: plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if not f.name.startswith("_") and not f.name.isupper()
        }
        if value.__msgtype__ == "diagnostic_msgs/msg/DiagnosticStatus":
            out["level"] %= 256  # rosbags reads `byte` as int8, ROS as octet
        return out
    return value


def check_encoding(data: bytes, msg) -> None:
    """`data` is rclpy's payload of `msg`, which rclpy and rosbags read back as `msg`."""
    assert data == cdr_payload(msg)
    assert plain(deserialize_message(data, type(msg))) == plain(msg)
    assert plain(TYPESTORE.deserialize_cdr(data, msgdefs.type_name(msg))) == plain(msg)


def stamped(msg, stamp, frame_id):
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.header.frame_id = frame_id
    return msg


@given(ANY_FLOAT, st.booleans())
@settings(max_examples=100, deadline=None, derandomize=True)
def test_float64_and_bool_encode_as_rclpy(value, flag):
    check_encoding(cdr.encode_float64(value), Float64(data=value))
    check_encoding(cdr.encode_bool(flag), Bool(data=flag))
    assert plain(decode_float64(cdr.encode_float64(value))) == plain(value)
    assert cdr.decode_bool(cdr.encode_bool(flag)) is flag


@given(st.lists(st.tuples(TEXT, U32, U32), max_size=3), U32, sequences(ANY_FLOAT))
@settings(max_examples=150, deadline=None, derandomize=True)
def test_float64_multi_array_encodes_as_rclpy(dims, offset, data):
    dim = tuple(cdr.Dimension(*d) for d in dims)
    encoded = cdr.encode_float64_multi_array(dim, data, offset)
    check_encoding(
        encoded,
        Float64MultiArray(
            layout=MultiArrayLayout(
                dim=[MultiArrayDimension(label=d.label, size=d.size, stride=d.stride) for d in dim],
                data_offset=offset,
            ),
            data=data,
        ),
    )
    decoded = cdr.decode_float64_multi_array(encoded)
    assert (decoded.dim, decoded.data_offset) == (dim, offset)
    assert plain(decoded.data) == plain(data)


@given(
    STAMPS,
    TEXT,
    sequences(TEXT, 40),
    sequences(ANY_FLOAT),
    sequences(ANY_FLOAT),
    sequences(ANY_FLOAT),
)
@settings(max_examples=150, deadline=None, derandomize=True)
def test_joint_state_encodes_as_rclpy(stamp, frame, names, position, velocity, effort):
    js = cdr.JointStateData(
        stamp[0] * 1_000_000_000 + stamp[1],
        frame,
        tuple(names),
        tuple(position),
        tuple(velocity),
        tuple(effort),
    )
    encoded = cdr.encode_joint_state(js)
    check_encoding(
        encoded,
        stamped(
            JointState(name=names, position=position, velocity=velocity, effort=effort),
            stamp,
            frame,
        ),
    )
    assert plain(decode_joint_state(encoded)) == plain(js)


STATUSES = st.builds(
    cdr.DiagnosticStatusData,
    st.integers(0, 255),
    TEXT,
    TEXT,
    TEXT,
    st.lists(st.tuples(TEXT, TEXT), max_size=4).map(tuple),
)


@given(
    STAMPS,
    TEXT,
    st.one_of(st.lists(STATUSES, max_size=3), st.lists(STATUSES, min_size=30, max_size=33)),
)
@settings(max_examples=150, deadline=None, derandomize=True)
def test_diagnostic_array_encodes_as_rclpy(stamp, frame, status):
    msg = stamped(
        DiagnosticArray(
            status=[
                DiagnosticStatus(
                    level=bytes([s.level]),
                    name=s.name,
                    message=s.message,
                    hardware_id=s.hardware_id,
                    values=[KeyValue(key=k, value=v) for k, v in s.values],
                )
                for s in status
            ]
        ),
        stamp,
        frame,
    )
    check_encoding(
        cdr.encode_diagnostic_array(stamp[0] * 1_000_000_000 + stamp[1], tuple(status), frame), msg
    )


@pytest.mark.parametrize(
    "encode",
    [
        lambda: cdr.encode_float64_multi_array((cdr.Dimension("a\x00b", 1, 1),), []),
        lambda: cdr.encode_float64_multi_array((cdr.Dimension("x", 2**32, 1),), []),
        lambda: cdr.encode_float64_multi_array((), [], -1),
        lambda: cdr.encode_joint_state(cdr.JointStateData(2**31 * 10**9, "", (), (), (), ())),
        lambda: cdr.encode_joint_state(cdr.JointStateData(0, "\ud800", (), (), (), ())),
        lambda: cdr.encode_diagnostic_array(0, (cdr.DiagnosticStatusData(256, "", "", ""),)),
    ],
)
def test_values_cdr_cannot_hold_raise_value_error(encode):
    with pytest.raises(ValueError):
        encode()


def test_bool_other_than_0_or_1_is_malformed():
    with pytest.raises(ValueError, match="not 0 or 1"):
        cdr.decode_bool(b"\x00\x01\x00\x00\x02")
    assert cdr.decode_bool(b"\x00\x00\x00\x00\x01") is True  # big endian


@pytest.mark.parametrize("little_endian", [True, False])
def test_float64_multi_array_both_byte_orders(little_endian):
    t = TYPESTORE.types
    msg = t["std_msgs/msg/Float64MultiArray"](
        t["std_msgs/msg/MultiArrayLayout"](
            [t["std_msgs/msg/MultiArrayDimension"]("rows", 2, 6)], 3
        ),
        np.array([1.5, -2.0]),
    )
    data = TYPESTORE.serialize_cdr(
        msg, "std_msgs/msg/Float64MultiArray", little_endian=little_endian
    )
    assert cdr.decode_float64_multi_array(data) == ((cdr.Dimension("rows", 2, 6),), 3, (1.5, -2.0))


def test_float64_multi_array_every_truncation_is_a_value_error():
    data = cdr.encode_float64_multi_array((cdr.Dimension("ab", 1, 2),), [1.0, 2.0], 1)
    for cut in range(len(data)):
        with pytest.raises(ValueError):
            cdr.decode_float64_multi_array(data[:cut])


@given(st.binary(max_size=80))
@settings(max_examples=300, deadline=None, derandomize=True)
def test_random_bytes_decode_as_bool_or_multi_array_or_raise_value_error(data):
    for decode in (cdr.decode_bool, cdr.decode_float64_multi_array):
        try:
            decode(data)
        except ValueError:
            pass


def test_joint_state_stream_with_repeated_and_changing_names():
    """Names repeated from the previous message are taken without parsing them again: a
    stream that repeats, extends, shortens and swaps them decodes as each message alone."""
    stream = [
        (["screw"], [1.0], [2.0]),
        (["screw"], [3.0], [4.0]),
        (["screw", "x"], [5.0, 6.0], []),
        (["screw"], [7.0], [8.0]),
        (["scre"], [9.0], []),
        (["screw"], [], [1.5]),
    ]
    for names, position, velocity in stream * 2:
        d = decode_joint_state(cdr_payload(joint_state(names, position, velocity, [])))
        assert (d.name, d.position, d.velocity) == (tuple(names), tuple(position), tuple(velocity))
    big = rosbags_joint_state(False, ["screw"], [1.0], [2.0])
    assert decode_joint_state(big).position == (1.0,)
