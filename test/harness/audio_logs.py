# SPDX-License-Identifier: Apache-2.0
"""Virtual-bench logs with their microphone changed: written again (our `Recorder`) with every
message as it was except the audio, which a function turns into other messages (another
format, hostile data), or which is dropped for a WAV file beside the log."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.io import wavfile

from leadscrew_ros.bag import audiomsgs, msgdefs, schema
from leadscrew_ros.bag.audio import FLOAT32_MULTI_ARRAY, read_audio
from leadscrew_ros.bag.logsource import open_log
from leadscrew_ros.bag.recorder import Recorder, RecordSettings
from leadscrew_ros.bag.virtual_bench import MIC_INFO_TOPIC, MIC_TOPIC

# (topic, type, payload, log time [ns]); a change returns a list of them (empty: dropped)
Message = tuple[str, str, bytes, int]
Change = Callable[[int, str, bytes, int], list[Message]]
F32MA_SCHEMA = schema.parse(msgdefs.definition(FLOAT32_MULTI_ARRAY), FLOAT32_MULTI_ARRAY)
DRIVERS_DATA = audiomsgs.message_schema(audiomsgs.AUDIO_DATA_STAMPED)


def rewrite(bag: Path, out_dir: Path, change: Change, name: str = "changed") -> Path:
    """`bag` written again into `out_dir`: messages on the microphone and its info topic
    become `change(k, topic, payload, log_time_ns)` (k counts them), the rest as they were."""
    source = open_log(bag)
    schemas = {n: audiomsgs.definition(n) for n in audiomsgs.TEXTS[audiomsgs.DRIVERS]}
    rec = Recorder(
        RecordSettings(
            directory=str(out_dir), split_size_mb=0.0, split_duration_s=0.0, compression="none"
        ),
        name=name,
        schemas=schemas,
    )
    messages = list(source.messages())
    assert rec.start(messages[0][1].log_time_ns)
    k = 0
    for _, m in messages:
        if m.topic.name in (MIC_TOPIC, MIC_INFO_TOPIC):
            out = change(k, m.topic.name, m.data, m.log_time_ns)
            k += 1
        else:
            out = [(m.topic.name, m.topic.type_name, m.data, m.log_time_ns)]
        for topic, type_name, data, t in out:
            rec.write_serialized(topic, type_name, data, t)
    rec.stop()
    assert not rec.error, rec.error
    return rec.bag


def samples_of(data: bytes) -> tuple[int, np.ndarray]:
    """(stamp [ns], S16LE samples as float32 full scale) of a bench AudioDataStamped."""
    msg = DRIVERS_DATA.decode(data)
    stamp = msg["header"]["stamp"]
    raw = np.asarray(msg["audio"]["data"], np.uint8).tobytes()
    return (
        int(stamp["sec"]) * 1_000_000_000 + int(stamp["nanosec"]),
        np.frombuffer(raw, "<i2") / np.float32(32768),
    )


def as_float32_multi_array(bag: Path, out_dir: Path) -> Path:
    """The bench log with its microphone as std_msgs/Float32MultiArray chunks on
    /microphone (no info: the rate must be given), logged as before."""

    def change(k: int, topic: str, data: bytes, t: int) -> list[Message]:
        if topic == MIC_INFO_TOPIC:
            return []
        _, x = samples_of(data)
        return [
            (MIC_TOPIC, FLOAT32_MULTI_ARRAY, F32MA_SCHEMA.encode({"data": x.astype(np.float32)}), t)
        ]

    return rewrite(bag, out_dir, change, "multiarray")


def with_wav_beside(bag: Path, out_dir: Path) -> tuple[Path, Path, float]:
    """The bench log without its microphone topics and the microphone as a 16-bit WAV file in
    the new bag directory; (bag, WAV, time of its first sample after the log's start [s])."""
    track = read_audio(bag)
    new = rewrite(bag, out_dir, lambda *_: [], "wav")
    wav = new / "microphone.wav"
    wavfile.write(
        wav,
        int(track.sample_rate_hz),
        np.round(np.asarray(track.samples) * 32768).clip(-32768, 32767).astype("<i2"),
    )
    return new, wav, track.t0_s
