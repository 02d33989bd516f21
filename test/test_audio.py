# SPDX-License-Identifier: Apache-2.0
"""`bag.audio.read_audio` on every input kind (ros-drivers AudioDataStamped + AudioInfo,
mgonzs13 AudioStamped in both layouts, Float32MultiArray, WAV; a log written by rosbags) and
on hostile data: each problem is a one-line warning or a one-line AudioError, never a
traceback."""

import struct

import numpy as np
import pytest
from scipy.io import wavfile

from harness.audio_logs import DRIVERS_DATA
from leadscrew_ros.bag import audiomsgs, logmeta, schema
from leadscrew_ros.bag.audio import (
    AudioError,
    AudioSettings,
    LiveAudio,
    MissingRateError,
    read_audio,
)
from leadscrew_ros.bag.cdr import FLOAT64, encode_float64
from leadscrew_ros.bag.recorder import Recorder, RecordSettings
from leadscrew_ros.model.acoustics.samples import SampleTrack

T0 = 1_767_225_600_000_000_000
RATE = 48000
SCHEMAS = {name: audiomsgs.definition(name) for name in audiomsgs.TEXTS[audiomsgs.DRIVERS]}
MG_SCHEMAS = {
    name: audiomsgs.definition(name, audiomsgs.MGONZS13)
    for name in audiomsgs.TEXTS[audiomsgs.MGONZS13]
}
F32MA = "std_msgs/msg/Float32MultiArray"
F32MA_SCHEMA = schema.parse(
    __import__("leadscrew_ros.bag.msgdefs", fromlist=["x"]).definition(F32MA), F32MA
)


def _write(tmp_path, messages, schemas=SCHEMAS, metadata=None):
    """A bag of (topic, type, payload, log time [ns]) in that order, with a Float64 topic's
    first message at T0 (the log's time origin) and the MCAP metadata records `metadata`."""
    rec = Recorder(
        RecordSettings(
            directory=str(tmp_path), split_size_mb=0.0, split_duration_s=0.0, compression="none"
        ),
        schemas=schemas,
        metadata=metadata or {},
    )
    assert rec.start(T0)
    rec.write_serialized("/motor_speed", FLOAT64, encode_float64(1.0), T0)
    for topic, type_name, data, t in messages:
        rec.write_serialized(topic, type_name, data, t)
    rec.stop()
    assert not rec.error
    return rec.bag


def _tone(n, f=1000.0, amp=0.5, rate=RATE):
    return (amp * np.sin(2 * np.pi * f * np.arange(n) / rate)).astype(np.float32)


def _s16(x):
    return np.round(np.clip(x, -1, 1) * 32767).astype("<i2")


def _drivers(
    x,
    start_s=0.1,
    chunk=4800,
    info=None,
    info_at=None,
    fmt="S16LE",
    rate=RATE,
    channels=1,
    to_bytes=None,
):
    """ros-drivers messages of samples `x` (frames x channels interleaved when 2-d)."""
    to_bytes = to_bytes or (lambda a: _s16(a).tobytes())
    info = info or audiomsgs.encode_audio_info(channels, rate, fmt, rate * 16, "wave")
    out = []
    flat = x.reshape(-1)
    per = chunk * channels
    for k in range(0, flat.size, per):
        stamp = T0 + int(round((start_s + k / channels / rate) * 1e9))
        part = flat[k : k + per]
        out.append(
            (
                "/microphone",
                audiomsgs.AUDIO_DATA_STAMPED,
                audiomsgs.encode_audio_data_stamped(stamp, to_bytes(part)),
                stamp + int(part.size / channels / rate * 1e9),
            )
        )
    at = T0 + int(2e8) if info_at is None else info_at
    out.insert(1, ("/microphone_info", audiomsgs.AUDIO_INFO, info, at))  # after a chunk
    return sorted(out, key=lambda m: m[3])


def test_ros_drivers_s16_mono_placed_at_its_stamps(tmp_path):
    x = _tone(3 * 4800 + 100)
    track = read_audio(_write(tmp_path, _drivers(x)))
    assert track.source == "/microphone" and track.sample_rate_hz == RATE
    assert track.t0_s == pytest.approx(0.1, abs=1e-9) and track.warnings == []
    np.testing.assert_array_equal(track.samples, (_s16(x) / np.float32(32768)))
    assert track.samples.dtype == np.float32


@pytest.mark.parametrize(
    "fmt,dtype,scale", [("S32LE", "<i4", 2**31 - 1), ("F32LE", "<f4", 1.0), ("S16BE", ">i2", 32767)]
)
def test_ros_drivers_stereo_formats_and_channel(tmp_path, fmt, dtype, scale):
    left, right = _tone(2000, 500.0), _tone(2000, 3000.0, 0.25)
    frames = np.column_stack([left, right])

    def to_bytes(a):
        return (a * scale).astype(dtype).tobytes() if dtype[1] != "f" else a.astype(dtype).tobytes()

    log = _write(tmp_path, _drivers(frames, chunk=512, fmt=fmt, channels=2, to_bytes=to_bytes))
    track = read_audio(log, channel=1)
    np.testing.assert_allclose(track.samples, right, atol=1e-4)
    assert track.warnings == []
    with pytest.raises(AudioError, match="channel 2 asked of /microphone, which has 2"):
        read_audio(log, channel=2)


def _mg(x, fmt=audiomsgs.PA_INT16, chunk=512, rate=16000, start_s=0.0):
    dtype, scale = {
        audiomsgs.PA_INT16: (np.int16, 32767),
        audiomsgs.PA_FLOAT32: (np.float32, 1.0),
        audiomsgs.PA_UINT8: (np.uint8, None),
    }[fmt]
    out = []
    for k in range(0, x.size, chunk):
        part = x[k : k + chunk]
        values = (
            (np.round(part * 127) + 128).astype(np.uint8)
            if scale is None
            else (part * scale).astype(dtype)
        )
        stamp = T0 + int(round((start_s + k / rate) * 1e9))
        out.append(
            (
                "/audio",
                audiomsgs.AUDIO_STAMPED,
                audiomsgs.encode_audio_stamped(stamp, values, rate, 1, fmt),
                stamp + 1,
            )
        )
    return out


@pytest.mark.parametrize(
    "fmt,atol", [(audiomsgs.PA_INT16, 1e-4), (audiomsgs.PA_FLOAT32, 0), (audiomsgs.PA_UINT8, 1e-2)]
)
def test_mgonzs13_audio_stamped(tmp_path, fmt, atol):
    x = _tone(1600, 440.0, rate=16000)
    track = read_audio(_write(tmp_path, _mg(x, fmt), MG_SCHEMAS))
    assert track.sample_rate_hz == 16000 and track.t0_s == 0.0 and track.warnings == []
    np.testing.assert_allclose(track.samples, x, atol=atol)


def test_mgonzs13_flat_layout_and_wrong_array(tmp_path):
    """The issue's layout (AudioStamped: header, AudioData audio, AudioInfo info side by side)
    reads too; a message filling another array than its format names is used and warned."""
    texts = audiomsgs.TEXTS[audiomsgs.MGONZS13]
    flat = (
        "std_msgs/Header header\naudio_common_msgs/AudioData audio\n"
        "audio_common_msgs/AudioInfo info\n"
    )
    text = audiomsgs.definition(audiomsgs.AUDIO_STAMPED, audiomsgs.MGONZS13).replace(
        texts[audiomsgs.AUDIO_STAMPED], flat
    )
    s = schema.parse(text, audiomsgs.AUDIO_STAMPED)
    x = _tone(1024, 440.0, rate=16000)
    msgs = [
        (
            "/audio",
            audiomsgs.AUDIO_STAMPED,
            s.encode(
                {
                    "header": {"stamp": {"sec": T0 // 10**9, "nanosec": k * 32_000_000}},
                    "audio": {"float32_data": x[k * 512 : (k + 1) * 512]},
                    "info": {
                        "format": audiomsgs.PA_INT16,
                        "channels": 1,
                        "rate": 16000,
                        "chunk": 512,
                    },
                }
            ),
            T0 + k,
        )
        for k in range(2)
    ]
    track = read_audio(_write(tmp_path, msgs, {audiomsgs.AUDIO_STAMPED: text}))
    np.testing.assert_array_equal(track.samples, x)
    assert track.warnings == [
        "2 messages fill another array than their format names "
        "(format 8 but float32_data filled); used it"
    ]


def _f32ma_chunks(x, rate=RATE):
    return [
        (
            "/mic",
            F32MA,
            F32MA_SCHEMA.encode({"data": x[k : k + 1000]}),
            T0 + int((k + 1000) / rate * 1e9),
        )
        for k in range(0, x.size, 1000)
    ]


def test_float32_multi_array_needs_the_rate(tmp_path):
    x = _tone(4000, 800.0)
    log = _write(tmp_path, _f32ma_chunks(x))
    with pytest.raises(MissingRateError, match="carries no sample rate.*listen.sample_rate_hz"):
        read_audio(log)
    track = read_audio(log, sample_rate_hz=RATE)
    np.testing.assert_array_equal(track.samples, x)
    assert track.t0_s == pytest.approx(0.0, abs=1e-6) and track.warnings == []


def test_float32_multi_array_rate_from_the_nodes_record(tmp_path):
    """The node's own recording (microphone as Float32MultiArray) carries its
    listen.sample_rate_hz in the metadata record: read at that rate, a given one wins."""
    rate = 16000
    x = _tone(4000, 800.0, rate=rate)
    record = logmeta.LogMetadata({}, {}, {"listen.sample_rate_hz": float(rate)}).record()
    log = _write(tmp_path, _f32ma_chunks(x, rate), metadata={logmeta.RECORD_NAME: record})
    track = read_audio(log)
    assert track.sample_rate_hz == rate and track.warnings == []
    np.testing.assert_array_equal(track.samples, x)
    assert track.duration_s == pytest.approx(x.size / rate, rel=1e-9)
    assert read_audio(log, sample_rate_hz=RATE).sample_rate_hz == RATE


@pytest.mark.parametrize("dtype", [np.int16, np.int32, np.float32, np.uint8])
def test_wav_beside_the_log(tmp_path, dtype):
    x = _tone(4800, 250.0)
    data = {
        np.int16: lambda: (x * 32767).astype(np.int16),
        np.int32: lambda: (x * 2**31).astype(np.int32),
        np.float32: lambda: x,
        np.uint8: lambda: np.round(x * 127 + 128).astype(np.uint8),
    }[dtype]()
    path = tmp_path / "mic.wav"
    wavfile.write(
        path, RATE, np.column_stack([data, data // 2 if dtype != np.float32 else data / 2])
    )
    track = read_audio(wav=path, wav_start_s=1.5)
    assert track.t0_s == 1.5 and track.sample_rate_hz == RATE and track.source == str(path)
    np.testing.assert_allclose(track.samples, x, atol=1e-2)
    with pytest.raises(AudioError, match="channel 2 asked of a 2-channel WAV"):
        read_audio(wav=path, channel=2)
    (tmp_path / "bad.wav").write_bytes(b"RIFF....nope")
    with pytest.raises(AudioError, match="not a readable WAV file"):
        read_audio(wav=tmp_path / "bad.wav")


def test_log_written_by_rosbags(tmp_path):
    """An independent producer: rosbags' rosbag2 MCAP writer with the registered types."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    for name, text in audiomsgs.TEXTS[audiomsgs.DRIVERS].items():
        store.register(get_types_from_msg(text, name))
    t = store.types
    x = _tone(4096, 700.0)
    with Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        info = w.add_connection("/mic_info", audiomsgs.AUDIO_INFO, typestore=store)
        mic = w.add_connection("/mic", audiomsgs.AUDIO_DATA_STAMPED, typestore=store)
        w.write(
            info,
            T0,
            store.serialize_cdr(
                t[audiomsgs.AUDIO_INFO](1, RATE, "S16LE", 0, "wave"), audiomsgs.AUDIO_INFO
            ),
        )
        for k in range(0, 4096, 1024):
            stamp = T0 + int(k / RATE * 1e9)
            msg = t[audiomsgs.AUDIO_DATA_STAMPED](
                t["std_msgs/msg/Header"](
                    t["builtin_interfaces/msg/Time"](*divmod(stamp, 10**9)), ""
                ),
                t[audiomsgs.AUDIO_DATA](np.frombuffer(_s16(x[k : k + 1024]).tobytes(), np.uint8)),
            )
            w.write(mic, stamp + 1, store.serialize_cdr(msg, audiomsgs.AUDIO_DATA_STAMPED))
    track = read_audio(tmp_path / "bag")
    np.testing.assert_allclose(track.samples, x, atol=1 / 32767)
    assert track.t0_s == 0.0 and track.warnings == []


# ----------------------------------------------------------------------------- hostile
def test_nan_and_beyond_full_scale_float_samples_are_warned(tmp_path):
    x = _tone(1000)
    x[10:13] = np.nan
    x[500] = np.inf
    x[600] = 3.0
    log = _write(tmp_path, _drivers(x, fmt="F32LE", to_bytes=lambda a: a.astype("<f4").tobytes()))
    track = read_audio(log)
    assert np.isnan(track.samples[[10, 11, 12, 500]]).all()
    assert np.isfinite(np.delete(track.samples, [10, 11, 12, 500])).all()
    assert track.warnings == [
        "4 NaN/inf samples: the detector frames holding them are not scored",
        "float samples beyond full scale (peak 3): wrong sample format or scaling?",
    ]


def test_unknown_format_and_mp3_are_one_line_errors(tmp_path):
    x = _tone(1000)
    bad = audiomsgs.encode_audio_info(1, RATE, "S13XE", 0, "wave")
    with pytest.raises(AudioError, match=r"unknown sample_format 'S13XE'; known: S8, U8"):
        read_audio(_write(tmp_path / "a", _drivers(x, info=bad)))
    mp3 = audiomsgs.encode_audio_info(1, 16000, "", 32000, "mp3")
    with pytest.raises(AudioError) as err:
        read_audio(_write(tmp_path / "b", _drivers(x, info=mp3)))
    assert "coded as 'mp3' (compressed), not PCM/wave" in str(err.value)
    assert "\n" not in str(err.value)


def test_empty_truncated_and_partial_messages_are_counted(tmp_path):
    x = _tone(3 * 480)
    msgs = _drivers(x, chunk=480)
    good = msgs[-1]
    stamp = T0 + int(0.12e9)  # the third chunk's stamp
    msgs += [
        (
            "/microphone",
            audiomsgs.AUDIO_DATA_STAMPED,
            audiomsgs.encode_audio_data_stamped(stamp, b""),
            good[3] + 1,
        ),
        ("/microphone", audiomsgs.AUDIO_DATA_STAMPED, good[2][:-7], good[3] + 2),
        (
            "/microphone",
            audiomsgs.AUDIO_DATA_STAMPED,
            audiomsgs.encode_audio_data_stamped(stamp, _s16(x[:5]).tobytes() + b"\x01"),
            good[3] + 3,
        ),
    ]
    track = read_audio(_write(tmp_path, msgs))
    assert track.samples.size == 3 * 480  # the 5 samples of the last one overlap: trimmed
    w = track.warnings
    assert any(
        line.startswith(
            "1 audio messages not decodable, skipped (first: "
            "audio_common_msgs/msg/AudioDataStamped.audio.data: "
        )
        for line in w
    ), w
    assert "1 empty audio messages" in w
    assert (
        "1 audio messages end in a partial frame of 1 bytes, dropped (truncated or wrong "
        "sample format?)" in w
    )
    assert "1 chunks overlap the samples before them; 5 samples trimmed" in w


def test_gaps_are_filled_and_a_long_one_ends_the_track(tmp_path):
    x = _tone(4 * 4800)
    msgs = _drivers(x)
    msgs.remove([m for m in msgs if m[0] == "/microphone"][1])  # the second chunk lost
    track = read_audio(_write(tmp_path / "a", msgs))
    assert track.samples.size == x.size
    assert np.isnan(track.samples[4800:9600]).all() and np.isfinite(track.samples[9600:]).all()
    assert track.warnings == ["1 gaps between chunks (0.1 s in all): no sound there, not scored"]
    track = read_audio(_write(tmp_path / "b", msgs), settings=AudioSettings(max_gap_s=0.05))
    assert track.samples.size == 4800
    assert track.warnings == [
        "a gap of 0.1 s at t = 0.300 s (> max_gap_s 0.05 s): the track "
        "ends there, 2 messages after it ignored"
    ]


def _stamped(msgs, stamp_of):
    """`msgs` with each microphone message's header stamp replaced by stamp_of(k, stamp)."""
    out, k = [], 0
    for topic, type_name, payload, t in msgs:
        if topic == "/microphone":
            msg = DRIVERS_DATA.decode(payload)
            stamp = msg["header"]["stamp"]
            ns = stamp_of(k, int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"]))
            raw = np.asarray(msg["audio"]["data"], np.uint8)
            payload = audiomsgs.encode_audio_data_stamped(ns, raw)
            k += 1
        out.append((topic, type_name, payload, t))
    return out


def test_stamps_on_another_clock_are_placed_by_the_log_times(tmp_path):
    """Header stamps from a device's boot clock (1.77e9 s off the log's): every chunk placed by
    its log time, so the track starts where the log says (it started at t = -1.77e9 s)."""
    x = _tone(10 * 4800)
    msgs = _drivers(x)
    right = read_audio(_write(tmp_path / "a", msgs))
    track = read_audio(_write(tmp_path / "b", _stamped(msgs, lambda k, ns: ns - T0 + 12_345)))
    assert track.t0_s == pytest.approx(right.t0_s, abs=1e-6)
    assert np.array_equal(track.samples, right.samples)
    assert track.warnings == [
        "the audio's header stamps are -1.767e+09 s off the log's clock (another clock?): "
        "every chunk placed by its log time"
    ]


@pytest.mark.parametrize("jump_s", [-3.0, 5.0])
@pytest.mark.parametrize("first", [7, 3])
def test_a_stamp_jump_is_placed_by_the_log_time(tmp_path, jump_s, first):
    """From the 8th (4th) of 10 chunks on the stamps jump back 3 s (a clock reset) or ahead
    5 s while the log times run on: those chunks are placed by their log times (most chunks
    jumped: the stamps are taken as another clock), nothing is dropped (the track ended at the
    jump: of 12 s only 4 s used)."""
    x = _tone(10 * 4800)
    msgs = _drivers(x)
    right = read_audio(_write(tmp_path / "a", msgs))
    jumped = _stamped(msgs, lambda k, ns: ns + int(jump_s * 1e9) if k >= first else ns)
    track = read_audio(_write(tmp_path / "b", jumped))
    assert track.t0_s == pytest.approx(right.t0_s, abs=1e-6)
    assert np.array_equal(track.samples, right.samples)
    said = (
        f"{10 - first} audio messages stamped more than resync_s off their log time (a stamp "
        f"jump, stamps running backwards; first at t = {0.1 * (first + 1):.3f} s): placed by "
        "their log times"
        if first > 5
        else f"the audio's header stamps are {jump_s:+.4g} s off the log's clock (another "
        "clock?): every chunk placed by its log time"
    )
    assert track.warnings == [said]


def test_a_dropout_of_seconds_is_no_sound_not_the_end(tmp_path):
    """The microphone silent for 5 s (no messages, stamps and log times both): kept as NaN,
    not scored, the rest of the stroke read (max_gap_s 60 s)."""
    x = _tone(20 * 4800)
    msgs = [
        (
            topic,
            kind,
            payload,
            t + (int(5e9) if topic == "/microphone" and t > T0 + int(1e9) else 0),
        )
        for topic, kind, payload, t in _stamped(
            _drivers(x), lambda k, ns: ns + (int(5e9) if k >= 9 else 0)
        )
    ]
    track = read_audio(_write(tmp_path, msgs))
    assert track.samples.size == x.size + 5 * RATE
    gap = np.isnan(track.samples)
    assert gap.sum() == 5 * RATE and gap[9 * 4800 : 9 * 4800 + 5 * RATE].all()
    assert track.warnings == ["1 gaps between chunks (5 s in all): no sound there, not scored"]


def test_sample_rate_change_keeps_the_first_segment(tmp_path):
    x = _tone(4 * 4800)
    msgs = _drivers(x)
    msgs.append(
        (
            "/microphone_info",
            audiomsgs.AUDIO_INFO,
            audiomsgs.encode_audio_info(1, 44100, "S16LE", 0, "wave"),
            T0 + int(0.35e9),
        )
    )
    msgs.sort(key=lambda m: m[3])
    track = read_audio(_write(tmp_path, msgs))
    assert track.samples.size == 2 * 4800
    assert track.warnings == [
        "sample rate changed from 48000 Hz to 44100 Hz at t = 0.300 s: "
        "the first segment kept, 2 messages after it ignored"
    ]


def test_topic_choice(tmp_path):
    x = _tone(960)
    log = _write(tmp_path / "none", [])
    with pytest.raises(AudioError, match="no audio topic"):
        read_audio(log)
    msgs = _drivers(x) + [
        (t.replace("/microphone", "/mic2"), ty, d, s) for t, ty, d, s in _drivers(x)
    ]
    log = _write(tmp_path / "two", sorted(msgs, key=lambda m: m[3]))
    with pytest.raises(
        AudioError,
        match="several audio topics, choose one: /mic2 "
        r"\(ros-drivers AudioDataStamped\), /microphone",
    ):
        read_audio(log)
    assert read_audio(log, topic="mic2").source == "/mic2"
    with pytest.raises(AudioError, match="/motor_speed is not an audio topic"):
        read_audio(log, topic="/motor_speed")
    with pytest.raises(AudioError, match="/nope is not an AudioInfo topic"):
        read_audio(log, topic="/mic2", info_topic="/nope")
    assert read_audio(log, topic="/mic2", info_topic="/microphone_info").samples.size == 960


def test_live_audio_decodes_chunks_with_the_latest_info():
    """The node's AudioDataStamped decoder: the samples `read_audio` would give, at the rate of
    the latest AudioInfo; no info yet, mp3, an unknown format or an empty chunk is a ValueError
    (the listener counts it); a malformed AudioInfo keeps the last good one."""
    live = LiveAudio(channel=1)
    tone = (np.sin(np.arange(960) * 0.2) * 20000).astype("<i2")
    stereo = np.column_stack([np.zeros_like(tone), tone]).ravel()
    chunk = audiomsgs.encode_audio_data_stamped(1, stereo.tobytes())
    with pytest.raises(ValueError, match="no AudioInfo yet"):
        live(chunk)
    live.info(audiomsgs.encode_audio_info(2, 48000, "S16LE"))
    samples, rate = live(chunk)
    assert rate == 48000.0 and samples.dtype == np.float32
    np.testing.assert_array_equal(samples, tone / np.float32(32768))
    live.info(b"\x00\x01\x00\x00")
    assert live.error.startswith("AudioInfo not taken") and live(chunk)[1] == 48000.0
    for info, problem in (
        (audiomsgs.encode_audio_info(2, 16000, "S16LE", coding_format="mp3"), "mp3"),
        (audiomsgs.encode_audio_info(2, 48000, "S13LE"), "unknown sample_format"),
    ):
        live.info(info)
        with pytest.raises(ValueError, match=problem):
            live(chunk)
    live.info(audiomsgs.encode_audio_info(1, 44100, "F32LE"))
    with pytest.raises(ValueError, match="empty"):
        live(audiomsgs.encode_audio_data_stamped(1, b""))
    live.channel = 0
    samples, rate = live(audiomsgs.encode_audio_data_stamped(1, np.float32([0.5, -0.25]).tobytes()))
    assert rate == 44100.0 and samples.tolist() == [0.5, -0.25]


def test_a_logs_track_is_on_disk_and_reads_by_slices_as_a_whole(tmp_path):
    """The track of a log is a `SampleTrack` on disk (no copy of the sound in memory): any
    slice across chunks, a gap and a trimmed overlap reads as the same stretch of the whole;
    contiguous chunks are one piece of the file."""
    x = _tone(6 * 480)
    msgs = _drivers(x, chunk=480)
    msgs.remove([m for m in msgs if m[0] == "/microphone"][2])  # a gap: NaN
    whole = read_audio(_write(tmp_path / "a", msgs))
    assert isinstance(whole.samples, SampleTrack) and not isinstance(whole.samples, np.ndarray)
    assert len(whole.samples._source) == 3  # two pieces of the file and the gap between
    a = np.asarray(whole.samples)
    assert a.dtype == np.float32 and a.size == x.size
    np.testing.assert_array_equal(a[:960], _s16(x[:960]) / np.float32(32768))
    assert np.isnan(a[960:1440]).all()
    rng = np.random.default_rng(5)
    for i, j in rng.integers(0, a.size + 1, size=(60, 2)).tolist():
        i, j = min(i, j), max(i, j)
        np.testing.assert_array_equal(whole.samples[i:j], a[i:j])
    np.testing.assert_array_equal(whole.samples.span(470, 1500)[5:600], a[475:1070])
    np.testing.assert_array_equal(whole.samples[-10:], a[-10:])
    assert whole.samples[5:5].size == 0 and whole.samples[a.size + 3 :].size == 0


def test_a_wav_is_read_by_slices_from_the_file_and_a_24_bit_one_whole(tmp_path):
    """A PCM WAV's channel is a `SampleTrack` on the file (no copy in memory): its slices equal
    the whole read, inf becomes NaN and is counted, the peak beyond full scale is said; a
    24-bit WAV (no memory map) is read whole, to the same full scale."""
    x = _tone(3000, 440.0, amp=0.9)
    x[[7, 2500]] = np.inf
    x[100] = 1.5
    path = tmp_path / "stereo.wav"
    wavfile.write(path, RATE, np.column_stack([x / 3, x]).astype(np.float32))
    track = read_audio(wav=path, channel=1)
    assert isinstance(track.samples, SampleTrack) and track.samples.size == x.size
    whole = np.asarray(track.samples)
    np.testing.assert_array_equal(whole[np.isfinite(x)], x[np.isfinite(x)].astype(np.float32))
    assert np.isnan(whole[[7, 2500]]).all()
    for i, j in ((0, 10), (5, 2999), (2499, 2501), (2990, 3000)):
        np.testing.assert_array_equal(track.samples[i:j], whole[i:j])
    assert track.warnings == [
        "2 NaN/inf samples: the detector frames holding them are not scored",
        "float samples beyond full scale (peak 1.5): wrong scaling?",
    ]
    v = np.round(_tone(2000, 300.0) * (2**23 - 1)).astype(np.int64)
    data = b"".join(int(s).to_bytes(3, "little", signed=True) for s in v)
    fmt = struct.pack("<IHHIIHH", 16, 1, 1, RATE, RATE * 3, 3, 24)
    (tmp_path / "s24.wav").write_bytes(
        b"RIFF"
        + struct.pack("<I", 36 + len(data))
        + b"WAVEfmt "
        + fmt
        + b"data"
        + struct.pack("<I", len(data))
        + data
    )
    s24 = read_audio(wav=tmp_path / "s24.wav")
    np.testing.assert_allclose(s24.samples, v / 2**23, atol=1e-6)
