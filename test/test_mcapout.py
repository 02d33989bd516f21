# SPDX-License-Identifier: Apache-2.0
"""The replay's lean MCAP writer (bag/mcapout.py): what mcap's own reader finds through the
summary and the indexes, and what our strict reader reads, equal what was written."""

from __future__ import annotations

import io

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from leadscrew_ros.bag.logfile import read_messages
from leadscrew_ros.bag.mcapout import McapOut

SCHEMA = ("std_msgs/msg/Float64", "ros2msg", b"float64 data")


def written(chunk_bytes: int, late_channel: bool) -> tuple[bytes, list[tuple]]:
    """A file of two channels (messages out of log-time order across them), several chunks
    when `chunk_bytes` is small; and the messages as (topic, log, publish, sequence, data)."""
    fh = io.BytesIO()
    out = McapOut(fh, "ros2", "test", chunk_bytes)
    schema = out.register_schema(*SCHEMA)
    a = out.register_channel("/a", "cdr", schema, {"offered_qos_profiles": ""})
    b = out.register_channel("/b", "cdr", schema, {})
    sent = []
    for i in range(500):
        for channel, topic, t in ((a, "/a", 1000 + 10 * i), (b, "/b", 995 + 10 * i)):
            data = bytes([i % 256]) * (i % 7)
            out.add_message(channel, t, data, t + 1, i)
            sent.append((topic, t, t + 1, i, data))
    if late_channel:  # registered after the last message: summary only
        out.register_channel("/late", "cdr", schema, {})
    out.finish()
    return fh.getvalue(), sent


@pytest.mark.parametrize("chunk_bytes", [1 << 20, 256])
def test_mcap_reader_finds_every_message_through_the_indexes(chunk_bytes):
    data, sent = written(chunk_bytes, late_channel=True)
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    stats = summary.statistics
    assert stats.message_count == len(sent) == 1000
    assert dict(stats.channel_message_counts) == {1: 500, 2: 500}
    assert (stats.message_start_time, stats.message_end_time) == (995, 5990)
    assert stats.chunk_count == len(summary.chunk_indexes)
    assert stats.chunk_count == 1 if chunk_bytes > len(data) else stats.chunk_count > 10
    assert [c.topic for c in summary.channels.values()] == ["/a", "/b", "/late"]
    # log-time order goes through the chunk and message indexes
    got = [
        (c.topic, m.log_time, m.publish_time, m.sequence, m.data)
        for _, c, m in reader.iter_messages(log_time_order=True)
    ]
    assert got == sorted(sent, key=lambda s: s[1])
    # as written: a plain scan of the data section
    scanned = [
        (c.topic, m.log_time, m.publish_time, m.sequence, m.data)
        for _, c, m in make_reader(io.BytesIO(data)).iter_messages(log_time_order=False)
    ]
    assert scanned == sent


def test_our_strict_reader_reads_it_as_written(tmp_path):
    data, sent = written(4096, late_channel=False)
    path = tmp_path / "out.mcap"
    path.write_bytes(data)
    got = [
        (m.topic.name, m.log_time_ns, m.publish_time_ns, m.sequence, m.data)
        for m in read_messages(path)
    ]
    assert got == sent


def test_the_layout_is_the_one_of_mcaps_writer():
    """Same records in the same places as mcap.writer.Writer with its defaults, apart from
    the compressed chunk bytes (another zstd level) and the library string."""
    ours, sent = written(1 << 20, late_channel=False)
    fh = io.BytesIO()
    w = Writer(fh)
    w.start("ros2", "test")
    schema = w.register_schema(*SCHEMA)
    ids = {
        "/a": w.register_channel("/a", "cdr", schema, {"offered_qos_profiles": ""}),
        "/b": w.register_channel("/b", "cdr", schema, {}),
    }
    for topic, t, pt, seq, data in sent:
        w.add_message(ids[topic], t, data, pt, seq)
    w.finish()
    theirs = make_reader(io.BytesIO(fh.getvalue())).get_summary()
    mine = make_reader(io.BytesIO(ours)).get_summary()
    assert mine.statistics == theirs.statistics
    assert mine.schemas == theirs.schemas and mine.channels == theirs.channels
    (a,), (b,) = mine.chunk_indexes, theirs.chunk_indexes
    assert (
        a.message_start_time,
        a.message_end_time,
        a.uncompressed_size,
        a.message_index_offsets.keys(),
    ) == (
        b.message_start_time,
        b.message_end_time,
        b.uncompressed_size,
        b.message_index_offsets.keys(),
    )
