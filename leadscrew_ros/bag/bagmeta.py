# SPDX-License-Identifier: Apache-2.0
"""rosbag2 `metadata.yaml` of a bag directory: written by the recorder and by `recover`.

`ros2 bag info/play` and rosbags need it to open a bag directory; rosbag2 regenerates it with
`ros2 bag reindex`, which `recover BAGDIR` does here. `problem` is the one rule of what a
metadata.yaml must be: what rosbags needs to open the bag (valid YAML, the keys and types it
reads, a storage it has, every file listed there) and what the bag's files hold (the same files,
message count, per-topic counts, start and duration), so that another tool finds the messages
we read; `info`, `replay`, `review` report it and `recover` rewrites the file when it fails.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml

METADATA = "metadata.yaml"
ROS_DISTRO = "jazzy"
STORAGES = {"mcap": ".mcap", "sqlite3": ".db3"}  # storage_identifier -> file suffix
MAX_VERSION = 9  # the newest rosbags (and Jazzy) reads
# The keys of `rosbag2_bagfile_information` rosbags reads (a missing one: it refuses the bag)
_REQUIRED = {
    "version": int,
    "storage_identifier": str,
    "relative_file_paths": list,
    "starting_time": dict,
    "duration": dict,
    "message_count": int,
    "topics_with_message_count": list,
}
_KINDS = {int: "a whole number", str: "a string", list: "a list", dict: "a mapping"}


@dataclass
class FileStats:
    """One MCAP file of a bag: its path and the log times [ns] and count of its messages."""

    path: Path
    start_ns: int | None = None
    end_ns: int | None = None
    messages: int = 0

    def add(self, log_time_ns: int) -> None:
        """Count one message logged at `log_time_ns` [ns] in this file."""
        self.messages += 1
        self.start_ns = log_time_ns if self.start_ns is None else min(self.start_ns, log_time_ns)
        self.end_ns = log_time_ns if self.end_ns is None else max(self.end_ns, log_time_ns)


@dataclass
class TopicStats:
    """One topic of a bag in metadata.yaml: name, type, message count, offered QoS."""

    name: str
    type_name: str  # 'pkg/msg/Type'
    count: int = 0
    offered_qos_profiles: str = ""


@dataclass
class BagStats:
    """What metadata.yaml says of a bag: its files, its topics and custom data."""

    files: list[FileStats] = field(default_factory=list)
    topics: list[TopicStats] = field(default_factory=list)
    custom_data: dict[str, str] = field(default_factory=dict)

    def info(self) -> dict:
        """The `rosbag2_bagfile_information` mapping (metadata version 9)."""
        files = self.files
        starts = [f.start_ns for f in files if f.start_ns is not None]
        ends = [f.end_ns for f in files if f.end_ns is not None]
        start = min(starts, default=0)
        return {
            "rosbag2_bagfile_information": {
                "version": 9,
                "storage_identifier": "mcap",
                "relative_file_paths": [f.path.name for f in files],
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": max(ends, default=start) - start},
                "message_count": sum(f.messages for f in files),
                "topics_with_message_count": [
                    {
                        "topic_metadata": {
                            "name": t.name,
                            "type": t.type_name,
                            "serialization_format": "cdr",
                            "offered_qos_profiles": t.offered_qos_profiles,
                            "type_description_hash": "",
                        },
                        "message_count": t.count,
                    }
                    for t in self.topics
                ],
                "compression_format": "",
                "compression_mode": "",
                "files": [
                    {
                        "path": f.path.name,
                        "starting_time": {"nanoseconds_since_epoch": f.start_ns or start},
                        "duration": {"nanoseconds": (f.end_ns or start) - (f.start_ns or start)},
                        "message_count": f.messages,
                    }
                    for f in files
                ],
                "custom_data": {str(k): str(v) for k, v in self.custom_data.items()},
                "ros_distro": ROS_DISTRO,
            }
        }

    def write(self, bag: Path) -> None:
        """Write `bag/metadata.yaml` (raises OSError)."""
        (Path(bag) / METADATA).write_text(yaml.safe_dump(self.info(), sort_keys=False))


def _whole(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _mapping(value: object, what: str) -> dict:
    if not isinstance(value, dict):
        raise ValueError(
            f"{what} is {type(value).__name__ if value is not None else 'empty'}, not a mapping"
        )
    return value


def read_info(bag: Path) -> dict:
    """The `rosbag2_bagfile_information` of `bag/metadata.yaml`, checked as rosbags reads it.

    Parameters
    ----------
    bag : Path
        The bag directory.

    Returns
    -------
    dict
        The mapping, with every key rosbags needs, of the type it needs.

    Raises
    ------
    FileNotFoundError
        There is no metadata.yaml.
    ValueError
        What is wrong with it, one line (rosbags would refuse the bag).
    """
    bag = Path(bag)
    try:
        doc = yaml.safe_load((bag / METADATA).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise ValueError(f"unreadable: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ValueError("not UTF-8 text") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        raise ValueError(f"invalid YAML{where}: {getattr(exc, 'problem', None) or exc}") from None
    if "rosbag2_bagfile_information" not in _mapping(doc, "the document"):
        raise ValueError("no 'rosbag2_bagfile_information'")
    info = _mapping(doc["rosbag2_bagfile_information"], "rosbag2_bagfile_information")
    for key, kind in _REQUIRED.items():
        if key not in info:
            raise ValueError(f"no {key!r}")
        if not (_whole(info[key]) if kind is int else isinstance(info[key], kind)):
            raise ValueError(f"{key!r} is {info[key]!r}, not {_KINDS[kind]}")
    if not 1 <= info["version"] <= MAX_VERSION:
        raise ValueError(f"version {info['version']} (rosbags reads 1 to {MAX_VERSION})")
    if info["storage_identifier"] not in STORAGES:
        raise ValueError(
            f"storage_identifier {info['storage_identifier']!r}, not one of {', '.join(STORAGES)}"
        )
    for key, inner in (("starting_time", "nanoseconds_since_epoch"), ("duration", "nanoseconds")):
        if not _whole(info[key].get(inner)):
            raise ValueError(f"{key}.{inner} is {info[key].get(inner)!r}, not a whole number")
    for name in info["relative_file_paths"]:
        if not isinstance(name, str) or not name:
            raise ValueError(f"relative_file_paths has {name!r}, not a file name")
        if not (bag / Path(name).name).is_file():
            raise ValueError(f"lists {Path(name).name}, which does not exist")
    for k, entry in enumerate(info["topics_with_message_count"]):
        what = f"topics_with_message_count[{k}]"
        topic = _mapping(_mapping(entry, what).get("topic_metadata"), f"{what}.topic_metadata")
        for key in ("name", "type", "serialization_format"):
            if not isinstance(topic.get(key), str):
                raise ValueError(f"{what}.topic_metadata has no {key!r}")
        if topic["serialization_format"] != "cdr":
            raise ValueError(
                f"topic {topic['name']} is serialized as {topic['serialization_format']!r}, not cdr"
            )
        if not _whole(entry.get("message_count")):
            raise ValueError(f"{what} has no whole 'message_count'")
    return info


def topic_counts(info: dict) -> dict[str, int]:
    """Messages per topic name of a `rosbag2_bagfile_information` (a name listed with two
    types: their sum; topics without messages left out)."""
    counts: dict[str, int] = {}
    for t in info.get("topics_with_message_count") or []:
        if isinstance(t, dict) and isinstance(t.get("topic_metadata"), dict):
            name = t["topic_metadata"].get("name")
            counts[name] = counts.get(name, 0) + (t.get("message_count") or 0)
    return {name: n for name, n in counts.items() if n}


def disagreement(old: dict, new: dict) -> str:
    """What a metadata mapping `old` says differently from `new` (that of the bag's files,
    `BagStats.info`): files, message count, per-topic counts, start, duration (of a bag with
    messages); '' if nothing."""
    listed = [Path(str(n)).name for n in old.get("relative_file_paths") or []]
    if listed != new["relative_file_paths"]:
        missing = [n for n in new["relative_file_paths"] if n not in listed]
        return (
            f"does not list {', '.join(missing)} of the bag"
            if missing
            else f"lists the files {', '.join(listed) or 'none'}, the bag has "
            f"{', '.join(new['relative_file_paths']) or 'none'}"
        )
    if old.get("message_count") != new["message_count"]:
        return f"says {old.get('message_count')} messages, the files hold {new['message_count']}"
    was, now = topic_counts(old), topic_counts(new)
    if was != now:
        diff = sorted(set(was) | set(now), key=str)
        shown = [
            f"{n} {was.get(n, 0)} (files: {now.get(n, 0)})"
            for n in diff
            if was.get(n, 0) != now.get(n, 0)
        ]
        return (
            "per-topic counts disagree with the files: "
            + ", ".join(shown[:3])
            + (f" and {len(shown) - 3} more" if len(shown) > 3 else "")
        )
    if not new["message_count"]:  # no time span: rosbag2 writes the largest time point
        return ""
    for key in ("starting_time", "duration"):
        if old.get(key) != new[key]:
            return f"{key} {old.get(key)} is not the messages' {new[key]}"
    return ""


def problem(bag: Path, actual: BagStats | None = None) -> str:
    """What is wrong with the metadata.yaml of bag directory `bag`; '' when rosbags opens the
    bag with it and finds the messages of `actual` (what the files hold; None: not compared)
    or when there is none (a bag being recorded, or split files without one).

    Parameters
    ----------
    bag : Path
        The bag directory.
    actual : BagStats, optional
        The bag's files as read.

    Returns
    -------
    str
        One line starting 'metadata.yaml ', or ''.
    """
    try:
        info = read_info(bag)
    except FileNotFoundError:
        return ""
    except ValueError as exc:
        return f"{METADATA} is broken: {exc}"
    if actual is not None:
        storage = STORAGES[info["storage_identifier"]]
        if any(f.path.suffix != storage for f in actual.files):
            return (
                f"{METADATA} says storage {info['storage_identifier']}, the bag's files "
                f"are {actual.files[0].path.suffix}"
            )
        wrong = disagreement(info, actual.info()["rosbag2_bagfile_information"])
        if wrong:
            return f"{METADATA} disagrees with the files: {wrong}"
    return ""
