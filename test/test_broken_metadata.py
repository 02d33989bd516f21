# SPDX-License-Identifier: Apache-2.0
"""A rosbag2 bag directory whose metadata.yaml is broken or disagrees with its files (issue 19):
rosbags, the independent reader, refuses or misreads each case built here; `info` (text and
--json), `replay` and `review` say what is wrong and that `recover BAGDIR` mends it, the files
are still read; after `recover` rosbags reads every message and nothing is reported."""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path

import pytest
import yaml
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.rosbag2.errors import ReaderError

from harness.logs import cli, rosbags_log, run_replay
from leadscrew_ros.bag.bagmeta import METADATA, problem, read_info
from leadscrew_ros.bag.logfile import cut_off_bags
from leadscrew_ros.review.fleet import FleetSettings, review_one
from leadscrew_ros.review.timeline import InputSettings

SAMPLES = 40


def _edit(change):
    def text(good: dict) -> str:
        doc = copy.deepcopy(good)
        change(doc["rosbag2_bagfile_information"])
        return yaml.safe_dump(doc)

    return text


def _pop(key):
    return _edit(lambda i: i.pop(key))


def _set(key, value):
    return _edit(lambda i: i.__setitem__(key, value))


def _ghost(i):
    i["relative_file_paths"].append("ghost_1.mcap")


# name -> metadata.yaml text from the good mapping, and the words the problem names
CASES = {
    "invalid YAML": (lambda good: "rosbag2_bagfile_information: [\n  : :\n", "invalid YAML"),
    "empty": (lambda good: "", "the document is empty"),
    "a list": (lambda good: "- 1\n- 2\n", "not a mapping"),
    "wrong top key": (lambda good: "rosbag2: {}\n", "no 'rosbag2_bagfile_information'"),
    "no version": (_pop("version"), "no 'version'"),
    "no duration": (_pop("duration"), "no 'duration'"),
    "no topics": (_pop("topics_with_message_count"), "no 'topics_with_message_count'"),
    "version a string": (_set("version", "nine"), "'version' is 'nine'"),
    "version 99": (_set("version", 99), "version 99"),
    "unknown storage": (_set("storage_identifier", "rosbag_v1"), "storage_identifier"),
    "start a string": (_set("starting_time", "noon"), "'starting_time' is 'noon'"),
    "a topic without type": (
        _edit(lambda i: i["topics_with_message_count"][0]["topic_metadata"].pop("type")),
        "has no 'type'",
    ),
    "a listed file missing": (_edit(_ghost), "lists ghost_1.mcap, which does not exist"),
    "message count": (_set("message_count", 999), "says 999 messages, the files hold 80"),
    "a topic count": (
        _edit(lambda i: i["topics_with_message_count"][0].__setitem__("message_count", 7)),
        "per-topic counts disagree",
    ),
    "a topic left out": (
        _edit(lambda i: i["topics_with_message_count"].pop()),
        "per-topic counts disagree",
    ),
}


@pytest.fixture(scope="module")
def good_bag(tmp_path_factory) -> Path:
    return rosbags_log(tmp_path_factory.mktemp("good") / "bag", ["screw"], samples=SAMPLES)


@pytest.fixture(params=sorted(CASES))
def broken(request, good_bag, tmp_path) -> tuple[Path, str]:
    """(bag directory with the case's metadata.yaml, words its problem names)."""
    bag = tmp_path / "bag"
    shutil.copytree(good_bag, bag)
    make, words = CASES[request.param]
    good = yaml.safe_load((good_bag / METADATA).read_text())
    (bag / METADATA).write_text(make(good))
    return bag, words


def rosbags_count(bag: Path) -> int:
    """Messages rosbags reads from the bag directory (ReaderError if it refuses it)."""
    with RosbagsReader(bag) as reader:
        read = sum(1 for _ in reader.messages())
        assert read == reader.message_count == sum(c.msgcount for c in reader.connections), (
            "rosbags reads the bag consistently"
        )
        return read


def test_the_good_bag_is_fine_for_rosbags_and_for_us(good_bag, capsys):
    assert rosbags_count(good_bag) == 2 * SAMPLES
    assert problem(good_bag) == "" and read_info(good_bag)["message_count"] == 2 * SAMPLES
    code, out, _ = cli(capsys, "info", good_bag)
    assert code == 0 and METADATA not in out
    code, out, _ = cli(capsys, "info", "--json", good_bag)
    assert [f["metadata_problem"] for f in json.loads(out)] == [""]


def test_rosbags_refuses_or_misreads_each_case(broken):
    bag, _ = broken
    with pytest.raises((ReaderError, AssertionError)):
        rosbags_count(bag)


def test_info_says_what_is_wrong_and_that_recover_mends_it(broken, capsys):
    bag, words = broken
    code, out, err = cli(capsys, "info", bag)
    assert code == 0 and not err
    assert f"{bag / 'bag.mcap'}: complete" in out  # the file itself is whole
    (line,) = [ln for ln in out.splitlines() if METADATA in ln]
    assert line.startswith(f"{bag}: {METADATA} ") and words in line
    assert line.endswith(f"`leadscrew-squeak recover {bag}` mends it")
    code, out, _ = cli(capsys, "info", "--json", bag)
    (entry,) = json.loads(out)
    assert code == 0 and entry["complete"] and words in entry["metadata_problem"]


def test_replay_reads_the_files_and_warns(broken, tmp_path):
    bag, words = broken
    r = run_replay(bag, tmp_path / "out", joint_name="screw")
    assert r.messages == 2 * SAMPLES and r.predictions > 0
    assert words in r.metadata_problem and r.metadata_problem in r.warnings
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["metadata_problem"] == r.metadata_problem
    assert f"warning: {r.metadata_problem}" in r.summary_text()


def test_review_row_is_ok_with_the_problem_in_its_note(broken, good_bag, tmp_path):
    """As a cut-off recording: reviewed from what the files hold, the row says what is wrong."""
    bag, words = broken
    settings = FleetSettings(inputs=InputSettings(joint_name="screw"), report=False)
    row = review_one(str(bag), str(tmp_path / "review"), "bag", settings)["row"]
    good = review_one(str(good_bag), str(tmp_path / "review_good"), "bag", settings)["row"]
    assert row["status"] == "ok" and not row["error"]
    assert words in row["note"] and f"recover {bag}` mends it" in row["note"]
    assert good["note"] == "" and row["messages"] == good["messages"]
    assert row["peak_probability"] == good["peak_probability"]


def test_recover_mends_it_and_rosbags_reads_every_message(broken, capsys):
    bag, _ = broken
    assert cut_off_bags(bag.parent) == []  # not cut off: `recover BAGDIR`, as info says
    code, out, _ = cli(capsys, "recover", bag)
    assert code == 0 and f"{bag / METADATA} regenerated" in out
    assert rosbags_count(bag) == 2 * SAMPLES
    code, out, _ = cli(capsys, "info", bag)
    assert METADATA not in out
    code, out, _ = cli(capsys, "recover", bag)
    assert out.splitlines()[-1].startswith(f"nothing to recover: {bag} is complete")
