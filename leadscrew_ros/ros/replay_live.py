# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak replay LOG --publish`: republish a recorded log's inputs live, so that a
running squeak_predictor node (or anything else) behaves as it did in the field.

The recorded CDR payloads are published unchanged, with the log's inter-message timing divided
by `rate`, on a monotonic schedule that does not drift (each message waits for its own due time,
computed from the start; late messages go at once and do not shift the rest).

Memory stays bounded by one chunk, whatever the log's size: the whole selection is first read
once, strictly (every file complete, every selected payload deserializable as its type), and
then streamed file by file a second time while publishing. Nothing is published from a log
that fails the first pass.

ROS arguments (`--ros-args -r __ns:=/seat_right -r OLD:=NEW ...`) configure the replay node as
any ROS executable's: in a namespace other than the root the log's inputs are published in it,
out of the namespace they were recorded in (`/seat_left/motor_speed` -> `/seat_right/
motor_speed`); rcl's remaps apply on top of that and of `remap`.
"""

from __future__ import annotations

import importlib
import math
import os
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from rclpy.duration import Duration
from rclpy.exceptions import InvalidTopicNameException
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rclpy.validate_full_topic_name import validate_full_topic_name

from ..bag.logfile import LogError, LogInfo, LogMessage, Topic
from ..bag.logsource import file_messages
from ..review.timeline import INPUTS, resolve
from ..review.timeline import is_input as _is_input  # the offline replay's rule, shared
from .env import StopSignals, close, confine_to_localhost, init_context

NODE_NAME = "log_replay"
# Reliable + transient local is at least what any subscriber can request, so every subscriber
# matches (the predictor's best-effort inputs as well as a reliable, latched recorder). The depth
# bounds what a slow reliable reader can still catch up on, and what a late latched one receives.
QOS = QoSProfile(
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)
WAIT_FOR_SUBSCRIBER_S = 5.0  # cross-process discovery can take one announcement period (3 s)
MATCH_GRACE_S = 0.5  # after the first match, this long for the other topics to match
SETTLE_S = 0.2  # the subscriber's side of the match (best effort drops until then)
ACK_TIMEOUT_S = 1.0  # at the end: reliable readers acknowledge the last messages
SLICE_S = 0.05  # longest sleep without looking at the stop flag
STATUS_PERIOD_S = 0.25


@dataclass(frozen=True)
class _Plan:
    """What to publish, checked against the whole log."""

    files: list[Path]
    outputs: dict[str, str]  # log topic -> topic it is published on
    classes: dict[str, type]  # log topic -> message class
    topics: dict[str, Topic]  # every topic of the log
    origin_ns: int  # log start + start offset: schedule time 0
    end_ns: int  # last message of the log (any topic)

    @property
    def span_ns(self) -> int:
        return self.end_ns - self.origin_ns


def publish_log(
    paths: list[Path],
    *,
    rate: float = 1.0,
    loop: bool = False,
    start_offset_s: float = 0.0,
    topics: list[str] | None = None,
    remap: dict[str, str] | None = None,
    progress: bool = True,
    wait_for_subscriber_s: float = WAIT_FOR_SUBSCRIBER_S,
    ros_args: Sequence[str] = (),
) -> int:
    """Publish the log's messages (`paths`: its files in order) in real time / `rate`.

    Selection: `topics` (exactly those), or by default the predictor's input topics in the log
    (`/motor_speed`, `/axial_load`, `/nut_position`, `/joint_states`, or a topic of the input's
    type whose name ends so, e.g. `/robot/motor_speed`; never `/squeak/*`, `/replay/*`).
    `remap` maps log topics to the topics to publish on (a relative target in the node's
    namespace). `ros_args` (`--ros-args ...`) go to rcl: namespace (the inputs move into it),
    remaps, logging; never the process's argv. Publishing starts when a subscriber matched,
    or after `wait_for_subscriber_s`.

    Parameters
    ----------
    paths : list of Path
        The log's files, in order (MCAP or rosbag2 sqlite3 .db3: `LogSource.files`).
    rate : float
        Speed-up of the log's time (1: real time).
    loop : bool
        Repeat until SIGINT/SIGTERM.
    start_offset_s : float
        Skip that much of the log from its first message [s].
    topics : list of str, optional
        Publish exactly these; default: the predictor's input topics in the log.
    remap : dict of str to str, optional
        Log topic -> topic to publish on.
    progress : bool
        A progress line on stderr.
    wait_for_subscriber_s : float
        The longest wait for a subscriber [s] (0: at once, the simulator's --no-wait).
    ros_args : sequence of str
        `--ros-args ...` for rcl.

    Returns
    -------
    int
        The number of messages published, also when stopped by SIGINT/SIGTERM (looped or
        before its end: `StopSignals.exit_status` writes its line on stderr).

    Raises
    ------
    ValueError
        Bad arguments (ROS ones included), before anything is published.
    LogError
        An unreadable log, before anything is published.
    """
    paths = [Path(p) for p in paths]
    _check_arguments(paths, rate, start_offset_s, remap, wait_for_subscriber_s)
    plan = _plan(paths, start_offset_s, topics, remap or {})
    if loop and plan.span_ns == 0:
        raise ValueError("cannot loop a log whose messages all have the same time")
    confine_to_localhost()
    with StopSignals() as stop:
        ctx = init_context(ros_args)
        node, player = None, None
        try:
            node = Node(NODE_NAME, context=ctx, start_parameter_services=False)
            plan = replace(
                plan, outputs=_outputs(plan.topics, plan.classes, remap or {}, node.get_namespace())
            )
            pubs = {
                t: node.create_publisher(plan.classes[t], out, QOS)
                for t, out in plan.outputs.items()
            }
            _announce(plan, pubs, rate, loop)
            _wait_for_subscriber(node, plan, pubs, wait_for_subscriber_s, stop)
            status = _Status(progress and sys.stderr.isatty(), plan.span_ns / 1e9, rate, loop)
            player = _Player(plan, pubs, rate, loop, stop, status)
            player.run()
            for pub in pubs.values():
                pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
        finally:
            close(ctx, None, [node] if node is not None else [])
    published = player.published if player is not None else 0
    if player is not None and player.finished:
        print(f"replay done: {published} messages in {player.elapsed_s:.2f} s", flush=True)
        return published
    passes = f" ({player.passes} passes)" if player is not None and loop else ""
    print(f"replay stopped: {published} messages published{passes}", flush=True)
    stop.exit_status()
    return published


# ----------------------------------------------------------------------------- checks
def _check_arguments(
    paths: list[Path],
    rate: float,
    start_offset_s: float,
    remap: dict[str, str] | None,
    wait_s: float,
) -> None:
    if not paths:
        raise ValueError("no log files given")
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a finite number > 0, got {rate!r}")
    if not (
        isinstance(start_offset_s, (int, float))
        and math.isfinite(start_offset_s)
        and start_offset_s >= 0
    ):
        raise ValueError(f"start offset must be a finite number >= 0 s, got {start_offset_s!r}")
    if not (math.isfinite(wait_s) and wait_s >= 0):
        raise ValueError(f"subscriber wait must be a finite number >= 0 s, got {wait_s!r}")
    for target in (remap or {}).values():
        _topic_name(target, "remap target")


def _in_namespace(topic: Topic, namespace: str) -> str:
    """Where the replay node in `namespace` publishes a log topic: in the root namespace under
    its recorded name; elsewhere an input moves out of the namespace it was recorded in
    (`/seat_left/motor_speed` -> `<namespace>/motor_speed`), any other topic goes under it."""
    if namespace == "/":
        return topic.name
    recorded = topic.name.rsplit("/", 1)[0] if _is_input(topic) else ""
    return namespace.rstrip("/") + topic.name[len(recorded) :]


def _topic_name(name: str, what: str) -> str:
    """`name` as an absolute ROS topic name (a relative one is relative to the root namespace,
    where the replay node lives); ValueError if it is not a valid name."""
    full = name if name.startswith("/") else "/" + name
    try:
        validate_full_topic_name(full)
    except InvalidTopicNameException as exc:  # a multi-line message with a caret
        problem = str(exc).splitlines()[0].removeprefix("Invalid topic name: ").rstrip(":")
        raise ValueError(f"{what} {name!r} is not a valid ROS topic name: {problem}") from None
    return full


def _plan(
    paths: list[Path], start_offset_s: float, topics: list[str] | None, remap: dict[str, str]
) -> _Plan:
    wanted = None if topics is None else {_topic_name(t, "topic") for t in topics}

    def selected(topic: Topic) -> bool:
        return _is_input(topic) if wanted is None else topic.name in wanted

    scan = _scan(paths, selected)
    log = paths[0] if len(paths) == 1 else paths[0].parent
    if scan.first_ns is None:
        raise LogError(log, "the log holds no messages")
    its_topics = f"(its topics: {', '.join(sorted(scan.topics))})"
    missing = sorted((wanted or set()) - scan.topics.keys())
    if missing:
        raise ValueError(f"topic {', '.join(missing)} not in the log {its_topics}")
    unknown = sorted({_topic_name(k, "remapped topic") for k in remap} - scan.topics.keys())
    if unknown:
        raise ValueError(f"remapped topic {', '.join(unknown)} not in the log {its_topics}")
    if wanted is not None and not scan.classes:
        raise ValueError(f"no messages on {', '.join(sorted(wanted))} in the log")
    if not scan.classes:
        raise LogError(
            log,
            f"no predictor input topics ({', '.join('/' + n for n in INPUTS)})"
            f" in the log {its_topics}; choose topics to publish",
        )
    duration_s = (scan.last_ns - scan.first_ns) / 1e9
    if start_offset_s and start_offset_s >= duration_s:
        raise ValueError(
            f"start offset {start_offset_s:g} s is not less than the log's "
            f"duration ({duration_s:.3f} s)"
        )
    origin_ns = scan.first_ns + round(start_offset_s * 1e9)
    if scan.last_selected_ns < origin_ns:
        raise ValueError(
            f"start offset {start_offset_s:g} s skips every message to publish "
            f"(the last is at {(scan.last_selected_ns - scan.first_ns) / 1e9:.3f} s)"
        )
    return _Plan(
        list(paths),
        _outputs(scan.topics, scan.classes, remap),
        scan.classes,
        scan.topics,
        origin_ns,
        scan.last_ns,
    )


def _outputs(
    topics: dict[str, Topic], classes: dict[str, type], remap: dict[str, str], namespace: str = "/"
) -> dict[str, str]:
    """Log topic -> published topic, for a node in `namespace`; one log topic per published
    topic."""
    full = {
        _topic_name(k, "remapped topic"): _topic_name(resolve(v, namespace), "remap target")
        for k, v in remap.items()
    }
    outputs = {t: full.get(t) or _in_namespace(topics[t], namespace) for t in classes}
    sources: dict[str, str] = {}
    for t, out in outputs.items():
        _topic_name(out, "topic")  # a foreign log's name may not be valid ROS
        if out in sources:
            raise ValueError(f"{sources[out]} and {t} would both be published on {out}")
        sources[out] = t
    return outputs


@dataclass
class _Scan:
    topics: dict[str, Topic] = field(default_factory=dict)  # every topic of the log
    classes: dict[str, type] = field(default_factory=dict)  # selected topics with messages
    first_ns: int | None = None  # log times of any message
    last_ns: int = 0
    last_selected_ns: int = 0  # of a selected message


def _scan(paths: list[Path], selected: Callable[[Topic], bool]) -> _Scan:
    """Read every file strictly; check each selected payload against its type."""
    scan, rejected = _Scan(), set()
    for path in paths:
        info = LogInfo(path)
        for m in file_messages(path, info=info):
            name, t = m.topic.name, m.log_time_ns
            if name not in scan.classes and name not in rejected:
                if selected(m.topic):
                    scan.classes[name] = _message_class(path, m.topic)
                else:
                    rejected.add(name)
            if name in scan.classes:
                _check_payload(path, m, scan.classes[name])
                scan.last_selected_ns = max(scan.last_selected_ns, t)
            scan.first_ns = t if scan.first_ns is None else min(scan.first_ns, t)
            scan.last_ns = max(scan.last_ns, t)
        for name, topic in info.topics.items():
            if scan.topics.setdefault(name, topic).type_name != topic.type_name:
                raise LogError(
                    path,
                    f"topic {name} is {topic.type_name} here, "
                    f"{scan.topics[name].type_name} in an earlier file",
                )
    return scan


def _message_class(path: Path, topic: Topic) -> type:
    """The installed rclpy class of the topic's 'pkg/msg/Type'."""
    pkg, kind, name = (topic.type_name.split("/") + ["", ""])[:3]
    try:
        if kind != "msg" or not name:
            raise ImportError
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError, ValueError):
        raise LogError(
            path,
            f"topic {topic.name} has type {topic.type_name!r}, which is not "
            f"an installed ROS 2 message type",
        ) from None


def _check_payload(path: Path, m: LogMessage, cls: type) -> None:
    """A payload that does not deserialize as its type is never sent to a subscriber."""
    try:
        deserialize_message(m.data, cls)
    except Exception as exc:  # rclpy raises RMWError / RuntimeError
        raise LogError(
            path,
            f"message {m.sequence} on {m.topic.name} is not a valid {m.topic.type_name}: {exc}",
        ) from None


# ----------------------------------------------------------------------------- publishing
def _announce(plan: _Plan, pubs: dict[str, Publisher], rate: float, loop: bool) -> None:
    """One line: what is published where (as rcl resolved the names, its remaps included)."""
    names = ", ".join(t if p.topic_name == t else f"{t} -> {p.topic_name}" for t, p in pubs.items())
    files = plan.files
    where = files[0] if len(files) == 1 else f"{files[0].parent} ({len(files)} files)"
    print(
        f"replaying {where}: {plan.span_ns / 1e9:.3f} s of log on {names} at rate {rate:g}"
        f"{', looped' if loop else ''} (ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')})",
        flush=True,
    )


def _check_subscriber_types(node: Node, plan: _Plan, pubs: dict[str, Publisher]) -> None:
    """ValueError if a subscriber in the ROS graph takes another type on a topic to publish
    (DDS never matches them: it would wait for a subscriber, then publish to nobody)."""
    for t, pub in pubs.items():
        ours = plan.topics[t].type_name
        for sub in node.get_subscriptions_info_by_topic(pub.topic_name):
            if sub.topic_type != ours:
                # discovery may show the endpoint before its node's name
                known = not sub.node_name.startswith("_NODE_NAME_UNKNOWN")
                who = f" {sub.node_namespace.rstrip('/')}/{sub.node_name}" if known else ""
                raise ValueError(
                    f"{pub.topic_name}: the log's {t} is {ours}, but its subscriber{who} "
                    f"takes {sub.topic_type}; nothing published (choose --topics, or "
                    f"--remap {t}:=ANOTHER)"
                )


def _wait_for_subscriber(
    node: Node, plan: _Plan, pubs: dict[str, Publisher], timeout_s: float, stop: StopSignals
) -> None:
    """Until every publisher has a subscriber, or MATCH_GRACE_S after the first one matched,
    or `timeout_s` passed (then publish anyway: a subscriber may still come); ValueError as
    soon as the graph shows a subscriber of another type (`_check_subscriber_types`)."""
    _check_subscriber_types(node, plan, pubs)
    if timeout_s <= 0:
        return
    print(f"waiting up to {timeout_s:g} s for a subscriber ...", flush=True)
    deadline, first = time.monotonic() + timeout_s, None
    while not stop.signum:
        now = time.monotonic()
        _check_subscriber_types(node, plan, pubs)
        matched = [p.get_subscription_count() > 0 for p in pubs.values()]
        if any(matched) and first is None:
            first = now
        if all(matched) or (first is not None and now - first >= MATCH_GRACE_S):
            time.sleep(SETTLE_S)
            return
        if now >= deadline:
            if first is None:
                print(f"no subscriber after {timeout_s:g} s: publishing anyway", flush=True)
            return
        time.sleep(0.01)


class _Status:
    """One status line on stderr (log time done / total, messages), a few times per second."""

    def __init__(self, enabled: bool, total_s: float, rate: float, loop: bool):
        self.enabled, self.total_s, self.rate, self.loop = enabled, total_s, rate, loop
        self.next_at, self.width = 0.0, 0

    def show(self, elapsed_s: float, published: int, passes: int) -> None:
        now = time.monotonic()
        if not self.enabled or now < self.next_at:
            return
        self.next_at = now + STATUS_PERIOD_S
        log_s = min(elapsed_s * self.rate - passes * self.total_s, self.total_s)
        line = f"replay {max(log_s, 0.0):.1f}/{self.total_s:.1f} s, {published} messages" + (
            f", pass {passes + 1}" if self.loop else ""
        )
        line = line[: shutil.get_terminal_size().columns - 1]
        print("\r" + line.ljust(self.width), end="", file=sys.stderr, flush=True)
        self.width = len(line)

    def clear(self) -> None:
        if self.width:
            print("\r" + " " * self.width + "\r", end="", file=sys.stderr, flush=True)
            self.width = 0


class _Player:
    """Streams the plan's files and publishes each message at its due time."""

    def __init__(
        self,
        plan: _Plan,
        pubs: dict[str, Publisher],
        rate: float,
        loop: bool,
        stop: StopSignals,
        status: _Status,
    ):
        self.plan, self.pubs, self.rate, self.loop = plan, pubs, rate, loop
        self.stop, self.status = stop, status
        self.published = self.passes = 0
        self.finished = False
        self.started = self.ended = time.monotonic()

    @property
    def elapsed_s(self) -> float:
        return self.ended - self.started

    def run(self) -> None:
        self.started = time.monotonic()
        try:
            while self._play_once():
                self.passes += 1
                if not self.loop:
                    self.finished = True
                    return
        finally:
            self.ended = time.monotonic()
            self.status.clear()

    def _play_once(self) -> bool:
        """One pass over the log; False when stopped before its end."""
        plan, base_ns = self.plan, self.passes * self.plan.span_ns
        for path in plan.files:
            for m in file_messages(path, set(plan.outputs)):
                if m.log_time_ns < plan.origin_ns:
                    continue  # before the start offset
                due = self.started + (base_ns + m.log_time_ns - plan.origin_ns) / 1e9 / self.rate
                if not self._wait_until(due):
                    return False
                self.pubs[m.topic.name].publish(m.data)
                self.published += 1
        return True

    def _wait_until(self, due: float) -> bool:
        """Sleep until `due` (monotonic), in slices that notice a stop; False when stopped."""
        while not self.stop.signum:
            self.status.show(time.monotonic() - self.started, self.published, self.passes)
            left = due - time.monotonic()
            if left <= 0:
                return True
            time.sleep(min(left, SLICE_S))
        return False
