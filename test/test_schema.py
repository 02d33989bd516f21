# SPDX-License-Identifier: Apache-2.0
"""Schema-driven CDR (`leadscrew_ros.bag.schema`) against rosbags: payloads rosbags writes
(both byte orders) decode to the same values, and the encoder writes rosbags' bytes exactly,
for std_msgs/Float32MultiArray, sensor_msgs/JointState and the audio types of both
audio_common packages (`audiomsgs`); hostile payloads raise CdrError, never anything else."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from leadscrew_ros.bag import audiomsgs, msgdefs, schema
from leadscrew_ros.bag.schema import CdrError, SchemaError


def _store(package=None):
    """A Jazzy typestore, with one audio_common package's types registered from our texts."""
    store = get_typestore(Stores.ROS2_JAZZY)
    if package:
        types = {}
        for name, text in audiomsgs.TEXTS[package].items():
            types.update(get_types_from_msg(text, name))
        store.register(types)
    return store


JAZZY = _store()
STORES = {p: _store(p) for p in (audiomsgs.DRIVERS, audiomsgs.MGONZS13)}


def _as_plain(value):
    """A rosbags message as nested dicts (numpy arrays kept)."""
    if hasattr(value, "__dataclass_fields__"):
        return {
            k: _as_plain(getattr(value, k))
            for k in value.__dataclass_fields__
            if k != "__msgtype__"
        }
    if isinstance(value, list):
        return [_as_plain(v) for v in value]
    return value


def _same(ours, theirs):
    if isinstance(theirs, dict):
        assert set(ours) == set(theirs)
        for k in theirs:
            _same(ours[k], theirs[k])
    elif isinstance(theirs, list):
        assert len(ours) == len(theirs)
        for a, b in zip(ours, theirs, strict=True):
            _same(a, b)
    elif isinstance(theirs, np.ndarray):
        assert isinstance(ours, np.ndarray) and ours.dtype.kind == theirs.dtype.kind
        np.testing.assert_array_equal(ours, theirs)
    else:
        assert ours == theirs


def _check(store, typename, msg, text):
    parsed = schema.parse(text, typename)
    for little in (True, False):
        data = store.serialize_cdr(msg, typename, little_endian=little)
        _same(parsed.decode(data), _as_plain(msg))
    reference = store.serialize_cdr(msg, typename, little_endian=True)
    assert parsed.encode(_as_plain(msg)) == bytes(reference)
    back = store.deserialize_cdr(parsed.encode(_as_plain(msg)), typename)
    _same(_as_plain(back), _as_plain(msg))


def _header(t, sec=1_767_225_600, nanosec=5, frame="mic"):
    return t["std_msgs/msg/Header"](t["builtin_interfaces/msg/Time"](sec, nanosec), frame)


@given(
    st.lists(st.floats(width=32, allow_nan=False), max_size=40),
    st.lists(
        st.tuples(st.text(max_size=5, alphabet="abcxyz"), st.integers(0, 99), st.integers(0, 99)),
        max_size=3,
    ),
    st.integers(0, 2**32 - 1),
)
@settings(max_examples=40, deadline=None, derandomize=True)
def test_float32_multi_array_matches_rosbags(data, dims, offset):
    t = JAZZY.types
    layout = t["std_msgs/msg/MultiArrayLayout"](
        [t["std_msgs/msg/MultiArrayDimension"](*d) for d in dims], offset
    )
    msg = t["std_msgs/msg/Float32MultiArray"](layout, np.array(data, np.float32))
    _check(
        JAZZY,
        "std_msgs/msg/Float32MultiArray",
        msg,
        msgdefs.definition("std_msgs/msg/Float32MultiArray"),
    )


TEXT = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=7)


@given(st.lists(TEXT, max_size=4), st.integers(0, 5), st.integers(0, 3), TEXT)
@settings(max_examples=40, deadline=None, derandomize=True)
def test_joint_state_matches_rosbags(names, n_position, n_effort, frame):
    t = JAZZY.types
    rng = np.random.default_rng(len(names) + n_position)
    msg = t["sensor_msgs/msg/JointState"](
        _header(t, frame=frame),
        names,
        rng.normal(size=n_position),
        np.array([], float),
        rng.normal(size=n_effort),
    )
    _check(
        JAZZY, "sensor_msgs/msg/JointState", msg, msgdefs.definition("sensor_msgs/msg/JointState")
    )


@pytest.mark.parametrize("n", [0, 1, 3, 1024])
def test_ros_drivers_audio_matches_rosbags(n):
    store, pkg = STORES[audiomsgs.DRIVERS], audiomsgs.DRIVERS
    t = store.types
    raw = np.arange(2 * n, dtype=np.uint16).astype(np.uint8)
    stamped = t[audiomsgs.AUDIO_DATA_STAMPED](_header(t), t[audiomsgs.AUDIO_DATA](raw))
    text = audiomsgs.definition(audiomsgs.AUDIO_DATA_STAMPED, pkg)
    _check(store, audiomsgs.AUDIO_DATA_STAMPED, stamped, text)
    assert audiomsgs.encode_audio_data_stamped(
        1_767_225_600_000_000_005, raw.tobytes(), "mic"
    ) == bytes(store.serialize_cdr(stamped, audiomsgs.AUDIO_DATA_STAMPED))
    info = t[audiomsgs.AUDIO_INFO](1, 48000, "S16LE", 768000, "wave")
    _check(store, audiomsgs.AUDIO_INFO, info, audiomsgs.definition(audiomsgs.AUDIO_INFO, pkg))
    assert audiomsgs.encode_audio_info(1, 48000, "S16LE", 768000, "wave") == bytes(
        store.serialize_cdr(info, audiomsgs.AUDIO_INFO)
    )


@pytest.mark.parametrize(
    "fmt,dtype",
    [
        (audiomsgs.PA_FLOAT32, np.float32),
        (audiomsgs.PA_INT16, np.int16),
        (audiomsgs.PA_INT8, np.int8),
        (audiomsgs.PA_UINT8, np.uint8),
    ],
)
def test_mgonzs13_audio_matches_rosbags(fmt, dtype):
    store, pkg = STORES[audiomsgs.MGONZS13], audiomsgs.MGONZS13
    t = store.types
    samples = (np.arange(7) * 3).astype(dtype)
    arrays = {
        n: np.array([], d)
        for n, d in (
            ("float32_data", np.float32),
            ("int32_data", np.int32),
            ("int16_data", np.int16),
            ("int8_data", np.int8),
            ("uint8_data", np.uint8),
        )
    }
    arrays[
        {
            np.float32: "float32_data",
            np.int16: "int16_data",
            np.int8: "int8_data",
            np.uint8: "uint8_data",
        }[dtype]
    ] = samples
    audio = t[audiomsgs.AUDIO](
        t[audiomsgs.AUDIO_DATA](**arrays), t[audiomsgs.AUDIO_INFO](fmt, 1, 16000, 7)
    )
    msg = t[audiomsgs.AUDIO_STAMPED](_header(t), audio)
    _check(store, audiomsgs.AUDIO_STAMPED, msg, audiomsgs.definition(audiomsgs.AUDIO_STAMPED, pkg))
    assert audiomsgs.encode_audio_stamped(
        1_767_225_600_000_000_005, samples, 16000, 1, fmt, "mic"
    ) == bytes(store.serialize_cdr(msg, audiomsgs.AUDIO_STAMPED))


def test_parse_skips_constants_and_defaults_and_reads_array_kinds():
    text = (
        '# comment\nint32 FOO=3\nstring BAR = "a=b # c"\nuint8 x 7\n'
        "float64[3] fixed\nint16[<=4] bounded\nstring<=8 name\nstring<=8[] names\n"
        "Header header\n" + msgdefs.DELIMITER + "\nMSG: std_msgs/Header\n"
        "builtin_interfaces/Time stamp\nstring frame_id\n"
        + msgdefs.DELIMITER
        + "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    )
    s = schema.parse(text, "pkg/msg/T")
    assert [(f.name, f.type, f.array, f.length) for f in s.fields()] == [
        ("x", "uint8", "", 0),
        ("fixed", "float64", "fixed", 3),
        ("bounded", "int16", "bounded", 4),
        ("name", "string", "", 0),
        ("names", "string", "sequence", 0),
        ("header", "std_msgs/msg/Header", "", 0),
    ]
    value = {
        "x": 7,
        "fixed": np.array([1.0, 2.0, 3.0]),
        "bounded": [1, -2],
        "name": "ab",
        "names": ["c", ""],
        "header": {"stamp": {"sec": -1, "nanosec": 9}, "frame_id": "f"},
    }
    back = s.decode(s.encode(value))
    assert back["fixed"].tolist() == [1.0, 2.0, 3.0] and back["bounded"].tolist() == [1, -2]
    assert back["names"] == ["c", ""] and back["header"]["stamp"] == {"sec": -1, "nanosec": 9}
    with pytest.raises(CdrError, match="exactly 3"):
        s.encode({**value, "fixed": [1.0]})
    with pytest.raises(CdrError, match="bound 4"):
        s.encode({**value, "bounded": [1] * 5})
    with pytest.raises(CdrError, match="range"):
        s.encode({**value, "bounded": [40000]})
    with pytest.raises(CdrError, match="not an integer"):
        s.encode({**value, "x": 1.5})


@pytest.mark.parametrize(
    "text,match",
    [
        ("foo/Bar x\n", "not defined"),
        ("int32\n", "not 'type name'"),
        ("wstring w\n", "wstring"),
        ("int32 x[\n", "cannot parse"),
        ("pkg/T t\n" + msgdefs.DELIMITER + "\nMSG: pkg/T\npkg/T again\n", "recursive"),
    ],
)
def test_bad_schema_text_is_one_schema_error(text, match):
    with pytest.raises(SchemaError, match=match):
        schema.parse(text, "pkg/msg/T")


AUDIO = audiomsgs.message_schema(audiomsgs.AUDIO_DATA_STAMPED)
GOOD = audiomsgs.encode_audio_data_stamped(1_000_000_005, bytes(range(10)), "mic")


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"\x00",
        b"\x00\x01\x00",
        b"\x07\x07\x00\x00" + GOOD[4:],
        GOOD[:-1],
        GOOD[:12],
        GOOD[:20],
        GOOD[:-14] + b"\xff\xff\xff\x7f" + GOOD[-10:],  # data length beyond the payload
        GOOD[:12] + b"\xff\xff\xff\xff" + GOOD[16:],  # frame length huge
        GOOD[:12] + b"m\xffc\x00" + GOOD[16:],  # frame not UTF-8
        GOOD[:12] + b"mic!" + GOOD[16:],
    ],
)  # frame not NUL-terminated
def test_hostile_payloads_raise_cdr_error(payload):
    with pytest.raises(CdrError):
        AUDIO.decode(payload)


@given(st.binary(max_size=64))
@settings(max_examples=300, deadline=None, derandomize=True)
def test_random_bytes_decode_or_raise_cdr_error(tail):
    for s in (AUDIO, audiomsgs.message_schema(audiomsgs.AUDIO_STAMPED, audiomsgs.MGONZS13)):
        try:
            s.decode(b"\x00\x01\x00\x00" + tail)
        except CdrError:
            pass
