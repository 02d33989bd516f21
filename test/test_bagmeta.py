# SPDX-License-Identifier: Apache-2.0
"""`bag.bagmeta`: rosbag2's metadata.yaml (version 9) of a bag directory. The times, counts and
files it states are those of the bag's messages, and rosbags (an independent reader) opens the
directory with it and finds the same messages."""

from pathlib import Path

import pytest
import yaml
from rosbags.rosbag2 import Reader as RosbagsReader

from harness.logs import f64, write_mcap
from leadscrew_ros.bag.bagmeta import METADATA, BagStats, FileStats, TopicStats, disagreement

T0 = 1_700_000_000_000_000_000


def test_file_stats_follow_the_earliest_and_latest_log_time():
    f = FileStats(Path("x_0.mcap"))
    assert (f.start_ns, f.end_ns, f.messages) == (None, None, 0)
    for t in (T0 + 50, T0 + 10, T0 + 90, T0 + 30):  # not in time order
        f.add(t)
    assert (f.start_ns, f.end_ns, f.messages) == (T0 + 10, T0 + 90, 4)


def test_info_of_a_split_bag():
    files = [
        FileStats(Path("bag_0.mcap"), T0 + 100, T0 + 900, 5),
        FileStats(Path("bag_1.mcap"), T0 + 1000, T0 + 2500, 3),
        FileStats(Path("bag_2.mcap")),
    ]  # a file without messages
    topics = [
        TopicStats("/motor_speed", "std_msgs/msg/Float64", 6, "- history: 3\n"),
        TopicStats("/squeak/risk", "std_msgs/msg/Float64", 2),
    ]
    info = BagStats(files, topics, {"unit_id": 7}).info()["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["bag_0.mcap", "bag_1.mcap", "bag_2.mcap"]
    assert info["starting_time"] == {"nanoseconds_since_epoch": T0 + 100}
    assert info["duration"] == {"nanoseconds": 2400}
    assert info["message_count"] == 8
    assert [f["message_count"] for f in info["files"]] == [5, 3, 0]
    assert [f["starting_time"]["nanoseconds_since_epoch"] for f in info["files"]] == [
        T0 + 100,
        T0 + 1000,
        T0 + 100,
    ]  # an empty file: the bag's start
    assert [f["duration"]["nanoseconds"] for f in info["files"]] == [800, 1500, 0]
    [speed, risk] = info["topics_with_message_count"]
    assert speed == {
        "topic_metadata": {
            "name": "/motor_speed",
            "type": "std_msgs/msg/Float64",
            "serialization_format": "cdr",
            "offered_qos_profiles": "- history: 3\n",
            "type_description_hash": "",
        },
        "message_count": 6,
    }
    assert risk["message_count"] == 2
    assert info["custom_data"] == {"unit_id": "7"}  # strings, as rosbag2 keeps them
    assert info["ros_distro"] == "jazzy"


def test_an_empty_bag_starts_and_lasts_zero():
    info = BagStats().info()["rosbag2_bagfile_information"]
    assert info["starting_time"] == {"nanoseconds_since_epoch": 0}
    assert info["duration"] == {"nanoseconds": 0} and info["message_count"] == 0
    assert info["files"] == [] and info["topics_with_message_count"] == []


def test_an_empty_bag_agrees_with_rosbag2s_largest_start_time_but_a_full_one_does_not():
    """rosbag2 writes an empty bag's start as the largest time point (its empty_bag test
    resource): that is no disagreement; with messages, another start is one."""
    empty = BagStats(files=[FileStats(Path("b_0.db3"))]).info()["rosbag2_bagfile_information"]
    rosbag2 = {**empty, "starting_time": {"nanoseconds_since_epoch": 2**63 - 1}}
    assert disagreement(rosbag2, empty) == ""
    full = BagStats(files=[FileStats(Path("b_0.db3"), T0, T0 + 10, 2)]).info()
    full = full["rosbag2_bagfile_information"]
    assert disagreement({**full, "starting_time": rosbag2["starting_time"]}, full).startswith(
        "starting_time {'nanoseconds_since_epoch': 9223372036854775807} is not the messages'"
    )


@pytest.mark.parametrize("splits", [1, 3])
def test_rosbags_opens_the_bag_directory_with_it(tmp_path, splits):
    bag = tmp_path / "bag"
    bag.mkdir()
    stats, topics = BagStats(custom_data={"note": "test"}), {}
    for i in range(splits):
        msgs = [
            f64("/motor_speed" if k % 2 else "/axial_load", float(k), T0 + i * 10**9 + k)
            for k in range(10)
        ]
        path = write_mcap(bag / f"bag_{i}.mcap", msgs)
        fs = FileStats(path)
        for topic, type_name, _, t in msgs:
            fs.add(t)
            topics.setdefault(topic, TopicStats(topic, type_name)).count += 1
        stats.files.append(fs)
    stats.topics = list(topics.values())
    stats.write(bag)
    doc = yaml.safe_load((bag / METADATA).read_text())
    assert doc == stats.info()
    with RosbagsReader(bag) as reader:
        assert reader.message_count == 10 * splits
        assert reader.start_time == T0
        assert reader.duration == (splits - 1) * 10**9 + 9 + 1  # rosbags: end - start + 1
        assert {c.topic: c.msgcount for c in reader.connections} == {
            "/motor_speed": 5 * splits,
            "/axial_load": 5 * splits,
        }
        assert len(list(reader.messages())) == 10 * splits
