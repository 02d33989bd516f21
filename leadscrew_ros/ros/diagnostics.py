# SPDX-License-Identifier: Apache-2.0
"""/diagnostics in the shape of ROS diagnostic_updater (no wheel of it exists for these Python
ROS wheels): an `Updater` owns the publisher, the period and the hardware id; each task fills a
`DiagnosticStatusWrapper` (`task(stat) -> stat`); `update()` publishes when the period has
passed, `force_update()` at once (on a change of verdict). Status names carry the node's fully
qualified name: '/ns/squeak_predictor: squeak prediction'. The array is published (and handed
to the node for recording) as the CDR bytes of `bag.cdr.encode_diagnostic_array`.

The squeak-prediction status is decided rclpy-free by `LivePredictor.status`, the measurement
status (with listening on) by `live.listen.Listener.status`; the recording status by
`recording_status` below, from the recorder and the crash recovery.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile

from ..bag.cdr import DiagnosticStatusData, encode_diagnostic_array
from ..live.status import Level, Status

if TYPE_CHECKING:
    from ..bag.crash_recovery import CrashRecovery
    from ..bag.recorder import Recorder

TOPIC = "/diagnostics"
PREDICTION_TASK = "squeak prediction"
RECORDING_TASK = "recording"
MEASUREMENT_TASK = "measurement"  # with listen.enabled: heard against predicted

# Key names of the recording status.
KEY_BAG = "bag"
KEY_FILES = "files"
KEY_MESSAGES = "messages"
KEY_LOST = "lost"
KEY_ACTIVE = "active"  # "true" while recording (what `leadscrew-squeak record status` reads)
KEY_FILE = "file"  # the file being written ('' when not recording)
KEY_DDS_REJECTED = "dds_lost_rejected"  # + topic: why its DDS message-lost counts are ignored
KEY_CUT_OFF_BAGS = "cut_off_bags"
# What the log line and the status say when a recording stopped on its own
RESUME_HINT = (
    "record.enabled set to false; resume with `~/record true` (std_srvs/SetBool "
    "data: true) or by setting record.enabled to true"
)


def key_lost_on(topic: str) -> str:
    """Key of the count of input messages lost on one topic."""
    return f"{KEY_LOST} {topic}"


def key_dds_rejected_on(topic: str) -> str:
    """Key of why the DDS message-lost counts of one topic are ignored (present only then)."""
    return f"{KEY_DDS_REJECTED} {topic}"


@dataclass
class DiagnosticStatusWrapper:
    """One status as a task fills it (diagnostic_updater's DiagnosticStatusWrapper)."""

    name: str = ""
    hardware_id: str = ""
    level: Level = Level.OK
    message: str = ""
    values: dict[str, str] = field(default_factory=dict)

    def summary(self, level: Level, message: str) -> None:
        """Set the level and message of the status."""
        self.level, self.message = Level(level), message

    def merge_summary(self, level: Level, message: str) -> None:
        """Raise the level to `level` if higher; append `message` ('; ')."""
        self.level = max(self.level, Level(level))
        self.message = "; ".join(m for m in (self.message, message) if m)

    def add(self, key: str, value: object) -> None:
        """Add the key-value pair (`value` as text)."""
        self.values[key] = str(value)

    def to_data(self) -> DiagnosticStatusData:
        """The status as `bag.cdr` encodes it."""
        return DiagnosticStatusData(
            int(self.level), self.name, self.message, self.hardware_id, tuple(self.values.items())
        )


Task = Callable[[DiagnosticStatusWrapper], DiagnosticStatusWrapper]


class Updater:
    """Publishes one DiagnosticArray with a status per task, in the order the tasks were
    added. `publish(publisher, data, stamp_ns)` (optional) publishes the CDR payload `data`
    stamped `stamp_ns` [ns] instead of `publisher.publish(data)` (the node also latches and
    records its outputs)."""

    def __init__(
        self,
        node: Node,
        qos: QoSProfile,
        period_s: float = 1.0,
        hardware_id: str = "",
        clock: Callable[[], float] = time.monotonic,
        publish: Callable[[Publisher, bytes, int], None] | None = None,
        **publisher_kwargs: Any,
    ):
        self.node, self.period_s, self.hardware_id = node, period_s, hardware_id
        self.publisher = node.create_publisher(DiagnosticArray, TOPIC, qos, **publisher_kwargs)
        self._clock = clock
        self._publish = publish or (lambda publisher, data, stamp_ns: publisher.publish(data))
        self._tasks: list[tuple[str, Task]] = []
        self._last = -float("inf")  # clock time of the last publication
        self.published = 0

    def add(self, name: str, task: Task) -> None:
        """Add a task that fills the status `name`."""
        self._tasks.append((name, task))

    def update(self) -> bool:
        """Publish if `period_s` passed since the last publication; True if it did."""
        if self._clock() - self._last < self.period_s:
            return False
        self.force_update()
        return True

    def force_update(self) -> None:
        """Run every task and publish now."""
        prefix = self.node.get_fully_qualified_name()
        stamp_ns = self.node.get_clock().now().nanoseconds
        status = tuple(
            task(DiagnosticStatusWrapper(f"{prefix}: {name}", self.hardware_id)).to_data()
            for name, task in self._tasks
        )
        self._publish(self.publisher, encode_diagnostic_array(stamp_ns, status), stamp_ns)
        self._last = self._clock()
        self.published += 1


def status_task(status: Callable[[], Status]) -> Task:
    """A task that reports a `Status` (e.g. `LivePredictor.status`'s verdict)."""

    def run(stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        s = status()
        stat.summary(s.level, s.message)
        for key, value in s.values.items():
            stat.add(key, value)
        return stat

    return run


def recording_status(
    stat: DiagnosticStatusWrapper, recorder: Recorder, crash: CrashRecovery
) -> DiagnosticStatusWrapper:
    """ERROR when recording failed or a file was lost under the recorder (never OK while
    data went nowhere), WARN when input messages were lost or bags of an earlier run are cut
    off, else OK; the counts as key-values (and why a topic's DDS loss counts are ignored)."""
    r = recorder
    if r.error:
        stat.summary(Level.ERROR, f"{r.error}; {RESUME_HINT}")
    else:
        stat.summary(Level.OK, f"recording to {r.path}" if r.active else "not recording")
    if r.incident:
        stat.merge_summary(Level.ERROR, r.incident)
    stat.add(KEY_BAG, r.bag or "")
    stat.add(KEY_FILES, len(r.files))
    stat.add(KEY_MESSAGES, r.messages)
    stat.add(KEY_LOST, r.lost)
    stat.add(KEY_ACTIVE, str(r.active).lower())
    stat.add(KEY_FILE, r.path or "")
    losses = {t: loss for t, loss in list(r.losses.items()) if loss.lost}
    for topic, loss in r.losses.items():
        stat.add(key_lost_on(topic), loss.lost)
        if loss.dds_rejected:
            stat.add(key_dds_rejected_on(topic), loss.dds_rejected)
    if losses:
        stat.merge_summary(
            Level.WARN,
            f"{r.lost} input message(s) lost before recording ("
            + ", ".join(f"{t} {loss.lost}" for t, loss in losses.items())
            + ")",
        )
    if crash.message:
        stat.merge_summary(crash.level, crash.message)
        stat.add(KEY_CUT_OFF_BAGS, " ".join(str(b) for b in crash.pending))
    return stat
