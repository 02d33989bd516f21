# SPDX-License-Identifier: Apache-2.0
"""Listening (`listen.*`): the node with a microphone in-process (a synthesised chunk stream on
`microphone`): squeak/heard and squeak/heard_frequency, the measurement status both ways, a
flood of chunks against the predictions, the recording of the microphone; listening off; and
the rclpy-free `live.listen.Listener` on its own.

Chunks are published at the pace of the sound they hold (the node places them by their arrival
time), 0.1 s each; every wait has a deadline, nothing depends on how fast the machine is.
"""

from __future__ import annotations

import array
import math
import threading
import time

import numpy as np
import pytest
from rclpy.parameter import Parameter
from std_msgs.msg import Bool, Float32MultiArray, Float64

from harness.ros import COLLECT
from harness.squeak import SQUEAK, STABLE, at
from leadscrew_ros.bag import messages
from leadscrew_ros.live.listen import (
    KEY_ANALYSED_S,
    KEY_BACKGROUND,
    KEY_DROPPED,
    KEY_HEARD,
    KEY_HEARD_FREQUENCY,
    KEY_HEARD_S,
    KEY_MALFORMED,
    KEY_UNUSABLE_S,
    Listener,
)
from leadscrew_ros.live.settings import ListenSettings
from leadscrew_ros.live.status import Level
from leadscrew_ros.model.acoustics.synthesis import microphone

RATE, CHUNK_S = 48000, 0.1
TONE_HZ = 2651.0
LISTEN = {"listen.enabled": True, "listen.window_s": 0.5}


class Mic:
    """A microphone publisher on the test's probe and the heard outputs it receives."""

    def __init__(self, ros):
        self.ros = ros
        self.pub = ros.probe.create_publisher(Float32MultiArray, "microphone", 10)
        ros.wait_matched(self.pub)
        self.heard: list[bool] = []
        self.frequency: list[float] = []
        ros.probe.create_subscription(
            Bool, messages.HEARD, lambda m: self.heard.append(m.data), COLLECT
        )
        ros.probe.create_subscription(
            Float64, messages.HEARD_FREQUENCY, lambda m: self.frequency.append(m.data), COLLECT
        )
        self.sent = 0  # samples so far: the synthesised signal's time

    def samples(self, seconds: float, tone_hz: float | None, speed: float = 0.0) -> np.ndarray:
        n = int(round(seconds * RATE))
        t = np.array([0.0, n / RATE])
        squeak = np.full(2, np.nan if tone_hz is None else tone_hz)
        return microphone(t, [speed, speed], squeak, 0.05, RATE, seed=self.sent)[:n]

    def publish(self, x: np.ndarray) -> None:
        self.pub.publish(Float32MultiArray(data=array.array("f", x.astype(np.float32).tobytes())))
        self.sent += x.size

    def stream(self, seconds: float, tone_hz: float | None, speed: float = 0.0, until=None) -> None:
        """Chunks at the pace of their sound for `seconds` (or until `until()` holds)."""
        x = self.samples(seconds, tone_hz, speed)
        step = int(CHUNK_S * RATE)
        start = time.monotonic()
        for k in range(0, x.size, step):
            self.ros.spin_until(
                lambda k=k: time.monotonic() - start >= k / RATE, 10.0, "the time of the next chunk"
            )
            self.publish(x[k : k + step])
            if until is not None and until():
                return


def measurement(ros, predicate=lambda s: True, timeout: float = 10.0):
    """The latest measurement status of this test's node, once it satisfies `predicate`."""
    found = []

    def check():
        msg = ros.latest.get("/diagnostics")
        found[:] = [s for s in (msg.status if msg else []) if s.name.endswith(": measurement")]
        return bool(found) and predicate(found[0])

    ros.spin_until(check, timeout, "a matching measurement status")
    return found[0]


def values(status) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


def level(status) -> Level:
    return Level(status.level[0])


# ----------------------------------------------------------------------------- heard
def test_a_tone_is_heard_at_its_frequency_and_silence_is_not(ros):
    node = ros.start(**LISTEN)
    mic = Mic(ros)
    ros.spin_until(
        lambda: mic.heard == [False] and mic.frequency == [0.0], 10.0, "the latched 'nothing heard'"
    )
    assert level(measurement(ros)) == Level.STALE  # no sound yet
    mic.stream(3.0, TONE_HZ, until=lambda: mic.heard[-1])
    ros.spin_until(lambda: mic.heard[-1] and mic.frequency[-1] > 0, 10.0, "squeak heard")
    assert mic.frequency[-1] == pytest.approx(TONE_HZ, rel=0.01)
    s = measurement(ros, lambda s: values(s)[KEY_HEARD] == "true")
    assert float(values(s)[KEY_HEARD_FREQUENCY]) == pytest.approx(TONE_HZ, rel=0.01)
    # noise and motor orders only: the squeak ends, 0 Hz
    mic.stream(3.0, None, until=lambda: not mic.heard[-1])
    ros.spin_until(lambda: not mic.heard[-1] and mic.frequency[-1] == 0.0, 10.0, "nothing heard")
    mic.stream(0.8, None)
    assert not mic.heard[-1] and mic.frequency[-1] == 0.0
    s = measurement(ros, lambda s: level(s) == Level.OK)
    assert s.message == "no squeak heard, none predicted"
    assert node.listener.malformed == 0 and node.listener.dropped == 0


def test_noise_alone_is_never_heard(ros):
    ros.start(**LISTEN)
    mic = Mic(ros)
    ros.node.listener.speed_rad_s = 40.0  # motor orders of 40 rad/s in the sound
    mic.stream(1.5, None, speed=40.0)
    s = measurement(ros, lambda s: float(values(s)[KEY_ANALYSED_S]) >= 1.4)
    assert values(s)[KEY_HEARD] == "false" and values(s)[KEY_HEARD_S] == "0.000"
    assert mic.heard and not any(mic.heard) and set(mic.frequency) == {0.0}


# ----------------------------------------------------------------------------- measurement
def test_measurement_ok_when_heard_and_predicted_agree(ros):
    ros.start(**LISTEN)
    mic = Mic(ros)
    core = at(ros, SQUEAK)  # squeak predicted at 20 rad/s, 200 N
    mode = core.squeak_modes[0]
    mic.stream(
        4.0,
        mode.frequency_hz,
        SQUEAK,
        until=lambda: level(measurement(ros)) == Level.OK and mic.heard[-1],
    )
    s = measurement(ros, lambda s: level(s) == Level.OK and "heard squeak" in s.message)
    assert s.message == (
        f"heard squeak at {float(values(s)[KEY_HEARD_FREQUENCY]):.0f} Hz, "
        f"predicted ({mode.label} {mode.frequency_hz:.0f} Hz)"
    )


def test_measurement_warns_of_a_squeak_heard_but_not_predicted(ros):
    ros.start(**LISTEN)
    mic = Mic(ros)
    at(ros, STABLE)  # 100 rad/s: no squeak predicted
    mic.stream(4.0, TONE_HZ, STABLE, until=lambda: level(measurement(ros)) == Level.WARN)
    s = measurement(ros, lambda s: level(s) == Level.WARN)
    assert (
        s.message == f"heard squeak at {float(values(s)[KEY_HEARD_FREQUENCY]):.0f} Hz, "
        "none predicted"
    )
    assert float(values(s)[KEY_HEARD_FREQUENCY]) == pytest.approx(TONE_HZ, rel=0.01)


def test_measurement_warns_of_a_squeak_predicted_but_not_heard(ros):
    ros.start(**LISTEN)
    mic = Mic(ros)
    core = at(ros, SQUEAK)
    mic.stream(4.0, None, SQUEAK, until=lambda: level(measurement(ros)) == Level.WARN)
    s = measurement(ros, lambda s: level(s) == Level.WARN)
    assert s.message == f"predicted squeak (P {core.probability:.2f}), none heard"


def test_no_sound_for_the_window_is_stale(ros):
    ros.start(**LISTEN)
    mic = Mic(ros)
    mic.stream(0.5, None)
    measurement(ros, lambda s: level(s) == Level.OK)
    s = measurement(ros, lambda s: level(s) == Level.STALE)  # the window passes
    assert s.message.startswith("no sound for ")


# ----------------------------------------------------------------------------- flood
def test_a_flood_of_chunks_never_delays_predictions_and_drops_are_counted(ros):
    node = ros.start(**LISTEN, **{"listen.queue_chunks": 4})
    mic = Mic(ros)
    listener = node.listener
    release, entered = threading.Event(), threading.Event()
    push = listener._detector.push

    def stuck(*args, **kwargs):  # the analysis is stuck on its first chunk
        entered.set()
        release.wait(30.0)
        return push(*args, **kwargs)

    listener._detector.push = stuck
    x = mic.samples(6.0, TONE_HZ)
    step = int(CHUNK_S * RATE)

    def flood(chunks: range) -> None:  # as fast as the probe can publish
        for k in chunks:
            mic.publish(x[k * step : (k + 1) * step])
            ros.drain(2)

    try:
        flood(range(50))
        ros.spin_until(
            lambda: listener.received >= 10 and entered.is_set(), 10.0, "chunks at the node"
        )
        for speed in (SQUEAK, STABLE, SQUEAK):  # predictions go on meanwhile
            at(ros, speed)
        flood(range(50, 60))
        assert listener.dropped > 0
        s = measurement(ros, lambda s: "dropped" in s.message)
        assert int(values(s)[KEY_DROPPED]) > 0 and level(s) >= Level.WARN
        assert "chunk(s) dropped in all: the analysis cannot keep up" in s.message
        assert not release.is_set()  # the analysis was stuck all along
    finally:
        release.set()
    s = measurement(ros, lambda s: int(values(s)[KEY_DROPPED]) == listener.dropped)
    assert listener.received == int(values(s)["chunks"])


# ----------------------------------------------------------------------------- wiring
def test_listening_off_subscribes_to_no_microphone_and_has_no_measurement(ros):
    node = ros.start()
    at(ros, STABLE)
    ros.spin_until(lambda: len(ros.latest["/diagnostics"].status) == 2, 5.0, "diagnostics")
    assert [s.name.rsplit(": ", 1)[1] for s in ros.latest["/diagnostics"].status] == [
        "squeak prediction",
        "recording",
    ]
    assert node.listener is None
    assert ros.probe.count_subscribers(f"{ros.ns}/microphone") == 0
    assert ros.probe.count_publishers(f"{ros.ns}/{messages.HEARD}") == 0


def test_the_microphone_is_recorded_like_every_input(ros, tmp_path):
    node = ros.start(**LISTEN, **{"record.enabled": True, "record.directory": str(tmp_path)})
    mic = Mic(ros)
    topic = f"{ros.ns}/microphone"
    assert topic in node.recorder.losses
    mic.stream(0.5, TONE_HZ)
    ros.spin_until(lambda: node.recorder.count(topic) == 5, 10.0, "5 chunks in the bag")


def test_listen_settings_apply_while_running(ros):
    node = ros.start(**LISTEN)
    old = node.listener
    result = node.set_parameters([Parameter("listen.min_duration_s", value=0.1)])
    assert result[0].successful and node.listener is not old
    assert node.listener.detector_settings.min_duration_s == 0.1
    assert not node.set_parameters([Parameter("listen.enabled", value=False)])[0].successful
    assert not node.set_parameters([Parameter("listen.hop_s", value=0.5)])[0].successful


# ----------------------------------------------------------------------------- Listener
def _wait(condition, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timeout"
        time.sleep(0.01)


def test_listener_counts_malformed_chunks_and_stops():
    listener = Listener(ListenSettings(enabled=True))

    def bad(data: bytes):
        raise ValueError("not audio")

    try:
        assert listener.status(0.0).level == Level.STALE
        listener.offer(b"x", time.monotonic(), bad)
        _wait(lambda: listener.malformed == 1)
        s = listener.status(time.monotonic())
        assert s.values[KEY_MALFORMED] == "1" and listener.error == "not audio"
    finally:
        listener.close()
    assert not listener._thread.is_alive()


def test_listener_places_chunks_on_the_clock():
    """Contiguous chunks despite jitter; a gap (or chunks dropped before) starts anew."""
    listener = Listener(ListenSettings(enabled=True))
    chunk = np.random.default_rng(0).normal(0.0, 0.01, 4800).astype(np.float32)
    try:
        for k, jitter in enumerate((0.0, 0.05, -0.05, 0.0)):
            listener.offer(b"", 100.1 + 0.1 * k + jitter, lambda _: (chunk, None))
        listener.offer(b"", 101.4, lambda _: (chunk, None))  # 0.9 s gap
        _wait(lambda: listener._audio_end is not None and math.isclose(listener._audio_end, 101.4))
        _wait(lambda: len(listener._analysed) == 5)
        times = [h.time_s for h in listener._analysed]
        assert times[:4] == pytest.approx([100.05 + 0.1 * k for k in range(4)])
        assert listener._detector.warnings[-1].startswith("audio discontinuity")
    finally:
        listener.close()


def test_a_muted_microphone_is_not_scored_and_said():
    """Chunks of a constant signal (a muted channel with an offset): nothing heard, nothing
    scored (analysed_s stays 0), their time in unusable_s and a WARN note; then a tone is
    heard and scored as before."""
    listener = Listener(ListenSettings(enabled=True, window_s=0.5))
    mute = np.full(4800, 0.2, np.float32)
    t = np.arange(4800) / RATE
    try:
        for k in range(10):
            listener.offer(b"", 100.1 + 0.1 * k, lambda _: (mute, None))
        _wait(lambda: listener.analysed == 10)
        listener.collect()
        s = listener.status(101.0)
        assert s.values[KEY_UNUSABLE_S] == "1.000" and s.values[KEY_ANALYSED_S] == "0.000"
        assert s.level >= Level.WARN and "no usable sound (1.0 s in all" in s.message
        assert s.values[KEY_HEARD] == "false"
        for k in range(10, 20):
            tone = (0.1 * np.sin(2 * np.pi * TONE_HZ * (t + 0.1 * k))).astype(np.float32)
            listener.offer(b"", 100.1 + 0.1 * k, lambda _, x=tone: (x, None))
        _wait(lambda: listener.analysed == 20)
        listener.collect()
        s = listener.status(102.0)
        assert s.values[KEY_HEARD] == "true" and float(s.values[KEY_ANALYSED_S]) > 0.5
        assert s.values[KEY_UNUSABLE_S] == "1.000" and "no usable sound" not in s.message
    finally:
        listener.close()


@pytest.mark.parametrize("speedup, rate", [(1.0, 44100.0), (10.0, 48000.0), (1.0, 48000.0)])
def test_a_sound_arriving_off_its_rate_is_a_warning(speedup, rate):
    """48 kHz chunks analysed as 44.1 kHz, or played at 10x real time: the measurement status
    says so (it said OK, 'heard squeak at 825 Hz, predicted'); at its own pace nothing."""
    listener = Listener(ListenSettings(enabled=True, window_s=0.5, sample_rate_hz=rate))
    chunk = np.random.default_rng(1).normal(0.0, 0.01, 4800).astype(np.float32)
    step = 0.1 / speedup  # 4800 samples of 48 kHz sound every step seconds
    n = int(5.0 / step) + 1
    try:
        for k in range(n):  # one at a time: a full queue would drop chunks
            listener.offer(b"", 100.0 + k * step, lambda _: (chunk, None))
            _wait(lambda k=k: listener.analysed == k + 1)
        s = listener.status(100.0 + (n - 1) * step)
        said = "samples/s but is analysed at"
        if speedup == 1.0 and rate == 48000.0:
            assert listener.pace is None and said not in s.message
        else:
            assert s.level >= Level.WARN and said in s.message
            assert listener.pace[0] == pytest.approx(48000.0 * speedup, rel=0.01)
    finally:
        listener.close()


def test_the_listener_learns_the_room_while_the_drive_rests():
    """A fan (1170 Hz) heard for 1 s with the drive at rest: the measurement's key-values list
    it as background; then, the drive moving, it is not heard as squeak."""
    listener = Listener(ListenSettings(enabled=True, window_s=0.5))
    t = np.arange(4800) / RATE
    noise = np.random.default_rng(2)
    try:
        for k in range(20):
            now = 100.1 + 0.1 * k
            listener.note_speed(now - 0.1, 0.0 if k < 10 else 50.0)
            fan = 0.01 * np.sin(2 * np.pi * 1170.0 * (t + 0.1 * k))
            x = (fan + 0.002 * noise.standard_normal(t.size)).astype(np.float32)
            listener.offer(b"", now, lambda _, x=x: (x, None))
            _wait(lambda k=k: listener.analysed == k + 1)
        listener.collect()
        s = listener.status(102.0)
        assert s.values[KEY_BACKGROUND] == "1170" and s.values[KEY_HEARD] == "false"
    finally:
        listener.close()


def test_audio_common_classes_only_where_ros_drivers_audio_common_is_installed(monkeypatch):
    """Not installed here: no audio_stamped input. With ros-drivers' audio_common_msgs its two
    classes; with the incompatible package of the same name (no AudioDataStamped), none."""
    import sys
    import types

    from leadscrew_ros.ros.node import audio_common_classes

    assert audio_common_classes() is None
    drivers = types.ModuleType("audio_common_msgs.msg")
    drivers.AudioDataStamped, drivers.AudioInfo = (
        type("AudioDataStamped", (), {}),
        type("AudioInfo", (), {}),
    )
    package = types.ModuleType("audio_common_msgs")
    package.msg = drivers
    monkeypatch.setitem(sys.modules, "audio_common_msgs", package)
    monkeypatch.setitem(sys.modules, "audio_common_msgs.msg", drivers)
    assert audio_common_classes() == (drivers.AudioDataStamped, drivers.AudioInfo)
    other = types.ModuleType("audio_common_msgs.msg")
    other.AudioStamped, other.AudioInfo = type("AudioStamped", (), {}), drivers.AudioInfo
    monkeypatch.setitem(sys.modules, "audio_common_msgs.msg", other)
    package.msg = other
    assert audio_common_classes() is None


def test_motor_orders_of_a_speed_ramp_are_not_heard():
    """The detector gets the speed history, not only the latest speed: the orders of a ramp
    stay orders within each 0.1 s chunk (with the latest speed alone, order 12 of this ramp
    was heard as short squeaks at 198 and 209 Hz)."""
    rate, duration = 48000, 3.0
    t = np.arange(0.0, duration + 0.01, 0.01)
    speed = 40.0 + 40.0 * t  # 40 -> 160 rad/s: order 12 sweeps 76 -> 306 Hz
    sound = microphone(t, speed, np.full(t.size, np.nan), sample_rate_hz=rate, seed=3)
    listener = Listener(ListenSettings(enabled=True))
    step = rate // 10
    try:
        for k in range(0, sound.size - step + 1, step):
            end = (k + step) / rate
            for ts, v in zip(
                t[(t > end - 0.1) & (t <= end)], speed[(t > end - 0.1) & (t <= end)], strict=True
            ):
                listener.note_speed(100.0 + ts, float(v))
            chunk = sound[k : k + step]
            listener.offer(b"", 100.0 + end, lambda _, c=chunk: (c, None))
        _wait(lambda: listener.analysed == sound.size // step)
        assert not any(h.heard for h in listener._analysed), listener._detector.rejected
    finally:
        listener.close()
