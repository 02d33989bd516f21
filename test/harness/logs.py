# SPDX-License-Identifier: Apache-2.0
"""Test logs and the offline entry points shared by the replay, probability and fleet tests:
hand-written MCAP files, rosbags' independent rosbag2 writer, mcap_ros2 decoding (not the
replay's own decoders), and one-call replay / CLI runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosbags.typesys import Stores, get_typestore
from std_msgs.msg import Float64

from leadscrew_ros.bag import msgdefs
from leadscrew_ros.cli import main
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.timeline import InputSettings

from .cdr_reference import cdr_payload

# zero deadbands: every input that changes the point is a recompute
EXACT = dict(speed_deadband_rad_s=0.0, load_deadband_n=0.0, nut_deadband_m=0.0)
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def run_replay(log, out, workers=0, **inputs):
    return replay(
        log,
        SqueakModel(),
        out,
        ReplaySettings(InputSettings(**inputs), workers=workers, progress=False),
    )


def cli(capsys, *argv):
    """`leadscrew-squeak *argv` in this process: (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def decoded(path: Path, topics=None):
    """(topic, log_time, publish_time, sequence, raw, decoded) of an MCAP file in file order."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [
            (c.topic, m.log_time, m.publish_time, m.sequence, m.data, d)
            for _, c, m, d in reader.iter_decoded_messages(topics, log_time_order=False)
        ]


def write_mcap(
    path: Path, messages, profile="ros2", encodings=("cdr", "ros2msg"), chunked=True
) -> Path:
    """messages: (topic, type name, payload, log time ns)."""
    with open(path, "wb") as f:
        w = Writer(f, use_chunking=chunked)
        w.start(profile=profile)
        channels = {}
        for topic, type_name, payload, t in messages:
            if topic not in channels:
                schema = w.register_schema(
                    type_name, encodings[1], msgdefs.definition(type_name).encode()
                )
                channels[topic] = w.register_channel(topic, encodings[0], schema)
            w.add_message(channels[topic], t, payload, t)
        w.finish()
    return path


def f64(topic, value, t):
    """A std_msgs/Float64 message for `write_mcap`."""
    return topic, "std_msgs/msg/Float64", cdr_payload(Float64(data=value)), t


def rosbags_log(
    path: Path, joints: list[str], samples: int = 120, rate_hz: float = 20.0, version: int = 9
) -> Path:
    """JointState-only speed and nut (several joints, ours second) plus a Float64 load,
    written by rosbags' rosbag2 writer in MCAP storage."""
    t = TYPESTORE.types
    profile = StrokeProfile(duration_s=samples / rate_hz)
    with RosbagsWriter(path, version=version, storage_plugin=StoragePlugin.MCAP) as w:
        js = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=TYPESTORE)
        load = w.add_connection("/axial_load", "std_msgs/msg/Float64", typestore=TYPESTORE)
        for k in range(samples):
            s = profile.state(k / rate_hz)
            now = 1_700_000_000_000_000_000 + int(k * 1e9 / rate_hz)
            header = t["std_msgs/msg/Header"](
                t["builtin_interfaces/msg/Time"](*divmod(now, 1_000_000_000)), ""
            )
            n = len(joints)
            msg = t["sensor_msgs/msg/JointState"](
                header,
                joints,
                np.array([0.3] * (n - 1) + [s.screw_angle_rad]),
                np.array([9.0] * (n - 1) + [s.speed_rad_s]),
                np.zeros(0),
            )
            w.write(js, now, TYPESTORE.serialize_cdr(msg, js.msgtype))
            w.write(
                load,
                now + 1000,
                TYPESTORE.serialize_cdr(t["std_msgs/msg/Float64"](s.load_n), load.msgtype),
            )
    return path
