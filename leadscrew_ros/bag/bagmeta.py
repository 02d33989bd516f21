# SPDX-License-Identifier: Apache-2.0
"""rosbag2 `metadata.yaml` of a bag directory: written by the recorder and by `recover`.

`ros2 bag info/play` and rosbags need it to open a bag directory; rosbag2 regenerates it with
`ros2 bag reindex`, which `recover BAGDIR` does here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml

METADATA = "metadata.yaml"
ROS_DISTRO = "jazzy"


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
