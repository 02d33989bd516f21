# SPDX-License-Identifier: Apache-2.0
"""CDR decoders of the replay (`leadscrew_ros.bag.cdr`) against rclpy's and rosbags' serializers;
malformed payloads raise ValueError and nothing else."""

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from leadscrew_ros.bag.cdr import decode_float64, decode_joint_state
from leadscrew_ros.ros.serialization import cdr_payload

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
FLOATS = st.floats(allow_nan=False, width=64)
NAMES = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12)


def joint_state(names, position, velocity, effort, sec=12, nanosec=345, frame="base"):
    msg = JointState(name=list(names), position=list(position), velocity=list(velocity),
                     effort=list(effort))
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = sec, nanosec, frame
    return msg


def rosbags_joint_state(little_endian: bool, names, position, velocity):
    import numpy as np
    t = TYPESTORE.types
    header = t["std_msgs/msg/Header"](t["builtin_interfaces/msg/Time"](7, 8), "frame")
    msg = t["sensor_msgs/msg/JointState"](header, list(names), np.array(position, float),
                                          np.array(velocity, float), np.array([], float))
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


@pytest.mark.parametrize("data, problem", [
    (b"", "no encapsulation header"),
    (b"\x00\x01\x00\x00\x00\x00\x00\x00", "expected 12"),
    (b"\x00\x03\x00\x00" + bytes(8), "unsupported CDR encapsulation"),
    (b"\x01\x00\x00\x00" + bytes(8), "unsupported CDR encapsulation"),
])
def test_float64_malformed(data, problem):
    with pytest.raises(ValueError, match=problem):
        decode_float64(data)


@given(st.lists(NAMES, max_size=4), st.lists(FLOATS, max_size=4), st.lists(FLOATS, max_size=4),
       st.lists(FLOATS, max_size=3), NAMES)
@settings(max_examples=60, deadline=None, derandomize=True)
def test_joint_state_round_trip_through_rclpy(names, position, velocity, effort, frame):
    d = decode_joint_state(cdr_payload(joint_state(names, position, velocity, effort,
                                                   frame=frame)))
    assert d == (12_000_000_345, frame, tuple(names), tuple(position), tuple(velocity),
                 tuple(effort))


@pytest.mark.parametrize("little_endian", [True, False])
def test_joint_state_both_byte_orders(little_endian):
    d = decode_joint_state(rosbags_joint_state(little_endian, ["a", "screw"], [1.0, -2.0],
                                               [3.5, 4.5]))
    assert d.stamp_ns == 7_000_000_008 and d.frame_id == "frame"
    assert d.name == ("a", "screw") and d.position == (1.0, -2.0) and d.velocity == (3.5, 4.5)
    assert d.effort == ()


def test_joint_state_every_truncation_is_a_value_error():
    data = cdr_payload(joint_state(["screw"], [1.0], [2.0], []))
    for cut in range(len(data)):
        with pytest.raises(ValueError):
            decode_joint_state(data[:cut])


# Layout: encapsulation 0-3, stamp 4-11, frame_id length 12-15, "base\0" 16-20, name count 24.
@pytest.mark.parametrize("patch, problem", [
    ((24, struct.pack("<I", 10 ** 9)), "overruns"),             # name count
    ((12, struct.pack("<I", 0)), "not terminated"),             # frame_id length 0
    ((20, b"\x01"), "not terminated"),                          # frame_id NUL overwritten
])
def test_joint_state_malformed(patch, problem):
    data = bytearray(cdr_payload(joint_state(["screw"], [1.0], [2.0], [], frame="base")))
    offset, raw = patch
    data[offset:offset + len(raw)] = raw
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
