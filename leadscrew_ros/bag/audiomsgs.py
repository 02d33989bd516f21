# SPDX-License-Identifier: Apache-2.0
"""Message definitions of the two audio_common packages, bundled as text, and their encoders.

Neither package is installable here (not on PyPI, no wheel), and both are called
`audio_common_msgs` with types of the same names but different fields, so they cannot share
the `jazzy_msgs/share` tree `msgdefs` reads: the texts live here, verbatim.

ros-drivers audio_common (branch ros2, released into Jazzy;
github.com/ros-drivers/audio_common, `audio_common_msgs/msg/*.msg`):

- `AudioData`: ``uint8[] data``
- `AudioDataStamped`: ``std_msgs/Header header``, ``audio_common_msgs/AudioData audio``
- `AudioInfo`: ``uint8 channels``, ``uint32 sample_rate``, ``string sample_format`` (e.g.
  S16LE), ``uint32 bitrate``, ``string coding_format`` (e.g. wave, mp3)

mgonzs13 audio_common (github.com/mgonzs13/audio_common, main, `audio_common_msgs/msg/*.msg` as
of version 4.0.x; its capturer publishes `AudioStamped` on `audio`, the array named by
`info.format`, a PortAudio sample format constant, filled):

- `AudioData`: ``float32[] float32_data``, ``int32[] int32_data``, ``int16[] int16_data``,
  ``int8[] int8_data``, ``uint8[] uint8_data`` (2023 versions also had ``int32[]
  int24_data``; the decoder is schema-driven and takes either)
- `AudioInfo`: ``int32 format``, ``int32 channels``, ``int32 rate``, ``int32 chunk``
- `Audio`: ``audio_common_msgs/AudioData audio_data``, ``audio_common_msgs/AudioInfo info``
- `AudioStamped`: ``std_msgs/Header header``, ``audio_common_msgs/Audio audio``

(The issue described mgonzs13's `AudioStamped` as header, `AudioData audio`, `AudioInfo info`
side by side; the repository nests them in `Audio`. `bag.audio` reads both layouts.)

`definition` gives the complete `ros2msg` schema text of a root type (root, then each
dependency after 80 '=' and `MSG:`, as rosbag2 writes it), with std_msgs/Header and
builtin_interfaces/Time from `msgdefs`. The encoders write XCDR1 little endian through
`schema` (the same bytes Fast CDR writes): for test logs and the virtual bench.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import msgdefs, schema

DRIVERS, MGONZS13 = "ros-drivers", "mgonzs13"
AUDIO_DATA = "audio_common_msgs/msg/AudioData"
AUDIO_DATA_STAMPED = "audio_common_msgs/msg/AudioDataStamped"
AUDIO_INFO = "audio_common_msgs/msg/AudioInfo"
AUDIO = "audio_common_msgs/msg/Audio"
AUDIO_STAMPED = "audio_common_msgs/msg/AudioStamped"
HEADER = "std_msgs/msg/Header"

# 'pkg/msg/Type' -> .msg text, per package
TEXTS: dict[str, dict[str, str]] = {
    DRIVERS: {
        AUDIO_DATA: "uint8[] data\n",
        AUDIO_DATA_STAMPED: "std_msgs/Header header\naudio_common_msgs/AudioData audio\n",
        AUDIO_INFO: (
            "uint8 channels       # Number of channels\n"
            "uint32 sample_rate   # Sampling rate [Hz]\n"
            "string sample_format # Audio format (e.g. S16LE)\n"
            "uint32 bitrate       # Amount of audio data per second [bits/s]\n"
            "string coding_format # Audio coding format (e.g. WAVE, MP3)\n"
        ),
    },
    MGONZS13: {
        AUDIO_DATA: (
            "float32[] float32_data\nint32[] int32_data\nint16[] int16_data\n"
            "int8[] int8_data \nuint8[] uint8_data\n"
        ),
        AUDIO_INFO: "int32 format\nint32 channels\nint32 rate\nint32 chunk",
        AUDIO: "audio_common_msgs/AudioData audio_data\naudio_common_msgs/AudioInfo info",
        AUDIO_STAMPED: "std_msgs/Header header\naudio_common_msgs/Audio audio",
    },
}
# PortAudio sample formats (portaudio.h): mgonzs13's AudioInfo.format
PA_FLOAT32, PA_INT32, PA_INT24, PA_INT16, PA_INT8, PA_UINT8 = 0x1, 0x2, 0x4, 0x8, 0x10, 0x20


def definition(name: str, package: str = DRIVERS) -> str:
    """`ros2msg` schema text of an audio type of `package` (DRIVERS or MGONZS13).

    Parameters
    ----------
    name : str
        'audio_common_msgs/msg/<Type>' of that package.
    package : str
        Which audio_common: `DRIVERS` or `MGONZS13`.

    Returns
    -------
    str
        Root definition, then every dependency once, depth first in field order.

    Raises
    ------
    KeyError
        `name` is not a type of `package`.
    """
    texts = TEXTS[package]
    parts, seen = [texts[name].rstrip("\n")], {name}

    def text_of(type_name: str) -> str:
        return texts[type_name] if type_name in texts else msgdefs.msg_text(type_name)

    def visit(type_name: str) -> None:
        for dep in msgdefs._field_types(text_of(type_name), type_name.split("/")[0]):
            if dep not in seen:
                seen.add(dep)
                pkg, _, typ = dep.split("/")
                parts.append(
                    f"{msgdefs.DELIMITER}\nMSG: {pkg}/{typ}\n{text_of(dep).rstrip(chr(10))}"
                )
                visit(dep)

    visit(name)
    return "\n".join(parts) + "\n"


_SCHEMAS: dict[tuple[str, str], schema.MessageSchema] = {}


def message_schema(name: str, package: str = DRIVERS) -> schema.MessageSchema:
    """The parsed `definition` (cached)."""
    key = (name, package)
    if key not in _SCHEMAS:
        _SCHEMAS[key] = schema.parse(definition(name, package), name)
    return _SCHEMAS[key]


def _stamp(stamp_ns: int) -> dict[str, int]:
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def encode_audio_data_stamped(stamp_ns: int, data: bytes | np.ndarray, frame_id: str = "") -> bytes:
    """ros-drivers AudioDataStamped: header (stamp [ns since the epoch], frame) and the raw
    sample bytes `data` (interleaved, in the AudioInfo's sample_format)."""
    raw = np.frombuffer(bytes(data), np.uint8) if not isinstance(data, np.ndarray) else data
    return message_schema(AUDIO_DATA_STAMPED).encode(
        {"header": {"stamp": _stamp(stamp_ns), "frame_id": frame_id}, "audio": {"data": raw}}
    )


def encode_audio_info(
    channels: int,
    sample_rate: int,
    sample_format: str = "S16LE",
    bitrate: int = 0,
    coding_format: str = "wave",
) -> bytes:
    """ros-drivers AudioInfo."""
    return message_schema(AUDIO_INFO).encode(
        {
            "channels": channels,
            "sample_rate": sample_rate,
            "sample_format": sample_format,
            "bitrate": bitrate,
            "coding_format": coding_format,
        }
    )


def encode_audio_stamped(
    stamp_ns: int,
    samples: np.ndarray,
    rate: int,
    channels: int = 1,
    fmt: int = PA_FLOAT32,
    frame_id: str = "",
    chunk: int | None = None,
) -> bytes:
    """mgonzs13 AudioStamped: `samples` (interleaved, of the numpy type of `fmt`: float32,
    int32, int16, int8 or uint8) in the array `fmt` names, and the info."""
    array = {
        PA_FLOAT32: "float32_data",
        PA_INT32: "int32_data",
        PA_INT16: "int16_data",
        PA_INT8: "int8_data",
        PA_UINT8: "uint8_data",
    }[fmt]
    frames = len(samples) // max(channels, 1)
    audio: dict[str, Any] = {
        "audio_data": {array: samples},
        "info": {
            "format": fmt,
            "channels": channels,
            "rate": rate,
            "chunk": frames if chunk is None else chunk,
        },
    }
    return message_schema(AUDIO_STAMPED, MGONZS13).encode(
        {"header": {"stamp": _stamp(stamp_ns), "frame_id": frame_id}, "audio": audio}
    )
