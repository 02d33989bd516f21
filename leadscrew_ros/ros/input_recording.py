# SPDX-License-Identifier: Apache-2.0
"""Recording of the node's inputs from DDS readers of their own, on a thread of their own (also
of topics the node records without taking them, such as the guard's).

The model's subscriptions keep a short queue (the newest input is what matters) and wait while a
prediction is computed; a recording needs every message. So, while recording, each input topic
gets a second subscription: serialized bytes (`raw=True`, what rosbag2 stores, no
deserialize/serialize round trip), best effort (matches any publisher), KEEP_LAST with a deep
history (`RecordSettings.queue_depth`), in a hidden helper node spun by its own executor on a
separate thread, so that recording never waits for the model. Each wake-up takes everything
queued on the subscription. What still never arrives is counted per topic
(`recorder.TopicLoss`): gaps in the publishers' sequence numbers (message info) and DDS
message-lost events, whose counts are checked before they are believed (a count that is none is
logged once and ignored).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any, cast

from rclpy.event_handler import QoSMessageLostInfo, SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

from ..bag import msgdefs
from ..bag.recorder import Recorder, TopicLoss

_SPIN_TIMEOUT_S = 0.1
_MATCH_TIMEOUT_S = 2.0  # longest wait for the new subscriptions to match the publishers


@dataclass
class _Input:
    topic: str  # fully qualified
    msg_type: type
    type_name: str
    loss: TopicLoss
    subscription: Subscription | None = None  # set right after the entry is made

    @property
    def sub(self) -> Subscription:
        """`subscription`, made in `InputRecording.__init__`."""
        assert self.subscription is not None
        return self.subscription


class InputRecording:
    """Records `inputs` (fully qualified topic -> message class) into `recorder` from their
    own subscriptions until `stop`; log times come from `recorder.clock` (the node's clock)."""

    def __init__(self, node: Node, inputs: dict[str, type], recorder: Recorder):
        self._recorder = recorder
        self._logger = node.get_logger()
        # Hidden helper node: no global arguments (a `__node:=` remap or a params file is the
        # main node's), no rosout, no parameter services. Topics are absolute already.
        self._node = Node(
            f"_{node.get_name()}_recorder",
            namespace=node.get_namespace(),
            context=node.context,
            use_global_arguments=False,
            enable_rosout=False,
            start_parameter_services=False,
        )
        qos = QoSProfile(
            depth=recorder.settings.queue_depth,
            history=HistoryPolicy.KEEP_LAST,
            reliability=ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.VOLATILE,
        )
        self._inputs = []
        for topic, msg_type in inputs.items():
            entry = _Input(topic, msg_type, msgdefs.type_name(msg_type), recorder.losses[topic])
            events = SubscriptionEventCallbacks(
                message_lost=partial(self._dds_lost, entry),
                use_default_callbacks=False,
            )
            entry.subscription = self._node.create_subscription(
                msg_type,
                topic,
                # rclpy passes (data, message info) to a callback that takes two arguments; its
                # annotation allows only the one-argument kind.
                cast(
                    "Callable[[Any], None]",
                    lambda data, info, e=entry: self._received(e, data, info),
                ),
                qos,
                raw=True,
                event_callbacks=events,
            )
            self._inputs.append(entry)
        self._executor = SingleThreadedExecutor(context=node.context)
        self._executor.add_node(self._node)
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self._spin, daemon=True, name=f"{node.get_name()} input recording"
        )
        self._thread.start()
        self._wait_for_publishers(node)

    def _wait_for_publishers(self, node: Node) -> None:
        """Return once each recording subscription has matched the publishers the node knows
        on its topic (bounded): a message sent after recording started must reach the bag, and
        a new DDS reader matches asynchronously (the node's own subscriptions long have)."""
        deadline = time.monotonic() + _MATCH_TIMEOUT_S
        for e in self._inputs:
            while (
                e.sub.get_publisher_count() < node.count_publishers(e.topic)
                and time.monotonic() < deadline
            ):
                time.sleep(0.002)

    def stop(self) -> None:
        """End the thread, write what is still queued on the subscriptions (the thread may lag
        behind the model: an input whose prediction is in the bag must be there too), and
        remove the subscriptions."""
        self._stop.set()
        self._executor.wake()
        self._thread.join()
        for e in self._inputs:
            self._take_queued(e, until_stopped=False)
        self._executor.remove_node(self._node)
        self._executor.shutdown(timeout_sec=1.0)
        self._node.destroy_node()

    def _spin(self) -> None:
        try:
            while not self._stop.is_set():
                self._executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)
        except Exception:  # context shut down under us (process exit): nothing to do
            if not self._stop.is_set() and self._node.context.ok():
                raise

    def _received(self, e: _Input, data: bytes, info: dict) -> None:
        """Write this message and whatever else is queued on the subscription now."""
        self._write(e, data, info)
        self._take_queued(e, until_stopped=True)

    def _take_queued(self, e: _Input, until_stopped: bool) -> None:
        """Write every message queued on `e`'s subscription (`until_stopped`: or until `stop`
        is asked for, so that the thread ends promptly)."""
        sub = e.sub
        while not (until_stopped and self._stop.is_set()):
            with sub.handle:
                taken = sub.handle.take_message(e.msg_type, True)
            if taken is None:
                return
            self._write(e, *taken)

    def _write(self, e: _Input, data: bytes, info: dict) -> None:
        sub = e.sub
        e.loss.received(info.get("publication_sequence_number"), sub.get_publisher_count)
        self._recorder.write_serialized(
            e.topic, e.type_name, data, publish_time_ns=info.get("source_timestamp") or None
        )

    def _dds_lost(self, e: _Input, info: QoSMessageLostInfo) -> None:
        """Judge the event's count against what was taken: first the messages queued now (the
        one that revealed the loss among them), then `TopicLoss.dds_event`; a count that is
        none is said once."""
        self._take_queued(e, until_stopped=True)
        rejected = e.loss.dds_event(info.total_count, info.total_count_change)
        if rejected:
            self._logger.warning(f"{e.topic}: {rejected}")
