# SPDX-License-Identifier: Apache-2.0
"""Live replay (`replay LOG --publish`): a recorded log republished over loopback DDS.

Launch-free: `publish_log` runs in a background thread (own rclpy Context) or in a child process
(signals), while a collector on a Context of its own spins in the test's thread. The test log
(`Recorder`, two split files) holds 2 s of inputs at 50 Hz, a suffix-named input, look-alikes
that must not be replayed by default, and some of the node's own outputs.
"""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from io import StringIO
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from mcap.writer import Writer
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String

from harness.cdr_reference import write_message
from harness.processes import stop
from harness.ros import RosWorld, unique_ns
from harness.rosbag2_bags import SERVICE_EVENT, drive_messages, write_bag
from leadscrew_ros.bag import msgdefs
from leadscrew_ros.bag.logfile import LogError, log_files, read_log
from leadscrew_ros.bag.logsource import open_log
from leadscrew_ros.bag.recorder import Recorder, RecordSettings
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.ros import replay_live
from leadscrew_ros.ros.node import SqueakPredictorNode
from leadscrew_ros.ros.replay_live import publish_log

T0 = 1_700_000_000_000_000_000  # log time of the first message [ns]
STEP_NS, STEPS = 20_000_000, 100  # 50 Hz for 2 s
SPAN_S = (STEPS - 1) * STEP_NS / 1e9  # 1.98 s from the first to the last message
INPUTS = ["/motor_speed", "/axial_load", "/joint_states", "/robot/nut_position"]
TYPES = {
    "/motor_speed": Float64,
    "/axial_load": Float64,
    "/joint_states": JointState,
    "/robot/nut_position": Float64,
    "/replay/motor_speed": Float64,
    "/other/motor_speed": String,
    "/squeak/risk": Float64,
    "/diagnostics": DiagnosticArray,
}
# every message of a test: reliable, deep (the replay's reliable writer retransmits what a
# reader missed while matching); volatile, unlike harness.ros.COLLECT: only what is replayed now
COLLECT = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


def speed(i: int) -> float:
    """Through the squeak band (~0.8..55 rad/s) to a stable speed."""
    return 10.0 + i


def load(i: int) -> float:
    """Steps beyond the node's load deadband (1 N), so that it recomputes at the last one."""
    return 150.0 + 2.0 * i


def record(directory: Path, steps: int = STEPS, split_s: float = 1.0) -> list[Path]:
    rec = Recorder(RecordSettings(directory=str(directory), split_duration_s=split_s))
    assert rec.start(T0), rec.error
    for i in range(steps):
        t = T0 + i * STEP_NS
        write_message(rec, "/motor_speed", Float64(data=speed(i)), t)
        write_message(rec, "/axial_load", Float64(data=load(i)), t)
        joint = JointState(name=["screw"], position=[0.01 * i], velocity=[speed(i)])
        joint.header.stamp.sec, joint.header.stamp.nanosec = divmod(t, 1_000_000_000)
        write_message(rec, "/joint_states", joint, t)
        write_message(rec, "/robot/nut_position", Float64(data=0.05 + 1e-4 * i), t)
        write_message(rec, "/replay/motor_speed", Float64(data=-1.0), t)  # not an input
        write_message(rec, "/other/motor_speed", String(data="x"), t)  # wrong type
        if i % 5 == 0:
            write_message(rec, "/squeak/risk", Float64(data=0.5), t)
            write_message(
                rec, "/diagnostics", DiagnosticArray(status=[DiagnosticStatus(name="n")]), t
            )
        rec.tick(t)
    rec.stop()
    assert not rec.error, rec.error
    return log_files(rec.bag)


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> list[Path]:
    files = record(tmp_path_factory.mktemp("log"))
    assert len(files) == 2  # split by duration: replayed across files
    return files


def expected(files: list[Path], topic: str, after_ns: int = T0) -> list:
    """The log's messages on `topic` (from `after_ns` on), deserialized, in log order."""
    return [
        deserialize_message(m.data, TYPES[topic])
        for f in files
        for m in read_log(f, {topic})
        if m.log_time_ns >= after_ns
    ]


class Collector(RosWorld):
    """A subscriber node on a Context of its own: (arrival time, message) per topic."""

    def __init__(self, topics: dict[str, type]):
        super().__init__()
        self.node = self.make_node("collector", namespace="/", start_parameter_services=False)
        self.got: dict[str, list[tuple[float, object]]] = {t: [] for t in topics}
        for topic, msg_type in topics.items():
            self.node.create_subscription(
                msg_type,
                topic,
                lambda m, t=topic: self.got[t].append((time.monotonic(), m)),
                COLLECT,
            )

    def messages(self, topic: str) -> list:
        return [m for _, m in self.got[topic]]


@pytest.fixture
def collector():
    made: list[Collector] = []

    def make(topics: dict[str, type]) -> Collector:
        made.append(Collector(topics))
        return made[-1]

    yield make
    for c in made:
        c.close()


class Replay(threading.Thread):
    """publish_log in a background thread: `result` (messages published) or `error`."""

    def __init__(self, files: list[Path], **kwargs):
        super().__init__(daemon=True)
        self.files, self.kwargs = files, {"progress": False, **kwargs}
        self.result: int | None = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.result = publish_log(self.files, **self.kwargs)
        except BaseException as exc:  # reported by the test's thread
            self.error = exc


def settle(c: Collector, quiet_s: float = 0.3, timeout: float = 10.0) -> None:
    """Let the last messages of a stream in: spin until none has come for `quiet_s` (on a
    loaded machine they lag behind the publisher's end by more than a fixed wait)."""
    deadline = time.monotonic() + timeout
    received = -1
    while received != (received := sum(len(v) for v in c.got.values())):
        if time.monotonic() > deadline:
            return
        c.spin_for(quiet_s)


def replay(c: Collector, files: list[Path], timeout: float = 15.0, **kwargs) -> Replay:
    """Run a replay to its end while the collector spins; then let the last messages in (until
    none has come for 0.3 s)."""
    r = Replay(files, **kwargs)
    r.start()
    c.spin_until(lambda: not r.is_alive(), timeout, "the replay to end")
    r.join()
    settle(c)
    if r.error is not None:
        raise r.error
    return r


def ns() -> str:
    return unique_ns(length=12)


# ----------------------------------------------------------------------------- publishing
def test_default_selection_republishes_the_inputs_unchanged_and_in_order(log, collector):
    c = collector(TYPES)  # listens to every topic of the log
    r = replay(c, log, rate=20.0)
    for topic in INPUTS:  # incl. /robot/nut_position (a suffix match)
        assert c.messages(topic) == expected(log, topic), topic
    for topic in set(TYPES) - set(INPUTS):  # look-alikes and the node's own outputs
        assert c.got[topic] == [], topic
    assert r.result == len(INPUTS) * STEPS


def test_a_db3_bag_is_republished_as_an_mcap_one(tmp_path, collector):
    """rosbag2 sqlite3 storage (legacy type names, `nut_position` stored without its leading
    slash, a service event that is not an input): the inputs, unchanged, in stored order."""
    bag = write_bag(tmp_path / "bag", "sqlite3", 5, splits=2, legacy_types=True, steps=20)
    written = drive_messages(20, legacy_types=True)
    topics = {"/motor_speed": Float64, "/nut_position": Float64, SERVICE_EVENT[0]: Float64}
    c = collector(topics)
    r = replay(c, open_log(bag.path).files, rate=20.0)
    for topic in ("/motor_speed", "/nut_position"):
        assert [m.data for m in c.messages(topic)] == [
            deserialize_message(m.data, Float64).data
            for m in written
            if "/" + m.topic.lstrip("/") == topic
        ]
    assert c.got[SERVICE_EVENT[0]] == [] and r.result == 3 * 20  # with /axial_load


@pytest.mark.parametrize("rate", [2.0, 8.0])
def test_timing_follows_the_log_divided_by_rate(log, collector, rate, monkeypatch):
    """The schedule, taken in the replay's thread (free of delivery latency): due times at the
    log's spacing / rate from one start (no drift, deterministic), each message published at or
    after its due time (deterministic), and typically on time (a generous bound: busy machine).
    """
    dues, published = [], []
    wait_until, publish = replay_live._Player._wait_until, Publisher.publish
    monkeypatch.setattr(
        replay_live._Player,
        "_wait_until",
        lambda self, due: (dues.append(due), wait_until(self, due))[1],
    )
    monkeypatch.setattr(
        Publisher,
        "publish",
        lambda self, msg: (
            self.topic_name == "/motor_speed" and published.append(time.monotonic()),
            publish(self, msg),
        )[1],
    )
    c = collector({"/motor_speed": Float64})
    r = replay(c, log, rate=rate, topics=["/motor_speed"])
    assert c.messages("/motor_speed") == expected(log, "/motor_speed")
    assert len(published) == len(dues) == STEPS == r.result
    step_s = STEP_NS / 1e9 / rate
    assert [d - dues[0] for d in dues] == pytest.approx(
        [i * step_s for i in range(STEPS)], abs=1e-6
    )
    late = [t - d for t, d in zip(published, dues, strict=True)]
    assert min(late) >= 0.0
    assert sorted(late)[len(late) // 2] < 0.05, late


def test_start_offset_skips_the_beginning(log, collector):
    c = collector({"/motor_speed": Float64, "/axial_load": Float64})
    r = replay(c, log, rate=10.0, start_offset_s=1.5, topics=["/motor_speed", "axial_load"])
    after = T0 + 1_500_000_000
    assert c.messages("/motor_speed") == expected(log, "/motor_speed", after)
    assert c.messages("/axial_load") == expected(log, "/axial_load", after)
    assert r.result == 2 * 25  # samples 75..99
    assert c.messages("/motor_speed")[0].data == speed(75)


def test_topic_filter_and_remap(log, collector):
    space = ns()
    c = collector(
        {
            f"{space}/speed": Float64,
            "/squeak/risk": Float64,
            "/motor_speed": Float64,
            "/axial_load": Float64,
        }
    )
    r = replay(
        c,
        log,
        rate=20.0,
        topics=["/motor_speed", "/squeak/risk"],
        remap={"/motor_speed": f"{space}/speed", "squeak/risk": "squeak/risk"},
    )
    assert c.messages(f"{space}/speed") == expected(log, "/motor_speed")
    assert c.messages("/squeak/risk") == expected(log, "/squeak/risk")  # chosen explicitly
    assert c.got["/motor_speed"] == [] and c.got["/axial_load"] == []
    assert r.result == STEPS + STEPS // 5


def test_without_subscriber_it_publishes_after_the_wait_with_a_status_line(
    log, monkeypatch, capsys
):
    class Tty(StringIO):
        def isatty(self) -> bool:
            return True

    stderr = Tty()
    monkeypatch.setattr(sys, "stderr", stderr)
    t0 = time.monotonic()
    published = publish_log(
        log,
        rate=4.0,
        topics=["/motor_speed"],
        remap={"/motor_speed": f"{ns()}/nobody"},
        wait_for_subscriber_s=0.3,
    )
    assert published == STEPS and time.monotonic() - t0 < 0.3 + SPAN_S / 4 + 2.0
    out = capsys.readouterr().out.splitlines()
    assert (
        out[0].startswith(
            f"replaying {log[0].parent} (2 files): 1.980 s of log on /motor_speed -> /t"
        )
        and "at rate 4" in out[0]
    )
    assert out[1:] == [
        "waiting up to 0.3 s for a subscriber ...",
        "no subscriber after 0.3 s: publishing anyway",
        out[-1],
    ]
    assert out[-1].startswith(f"replay done: {STEPS} messages in 0.")
    status = stderr.getvalue().split("\r")
    shown = [s for s in status if s.startswith("replay ")]
    assert 1 <= len(shown) <= 4 and shown[-1].split(", ")[0].endswith("/2.0 s")
    assert "messages" in shown[-1] and status[-1] == ""  # the line is cleared
    # not a terminal: no status line; no wait at all (the simulator's --no-wait)
    monkeypatch.setattr(sys, "stderr", StringIO())
    assert (
        publish_log(
            log,
            rate=50.0,
            topics=["/motor_speed"],
            wait_for_subscriber_s=0.0,
            remap={"/motor_speed": f"{ns()}/nobody"},
        )
        == STEPS
    )
    assert sys.stderr.getvalue() == ""
    assert "waiting" not in capsys.readouterr().out


def test_a_subscriber_of_another_type_stops_the_replay_naming_both_types(log, collector):
    """DDS never matches a Float64 publisher with a String subscriber: instead of waiting for
    a subscriber and publishing to nobody, the replay names both types (from the ROS graph)
    and publishes nothing."""
    space = ns()
    c = collector({f"{space}/motor_speed": String})
    r = Replay(
        log,
        topics=["/motor_speed"],
        remap={"/motor_speed": f"{space}/motor_speed"},
        wait_for_subscriber_s=60.0,  # far longer than discovery: the graph check ends it
    )
    r.start()
    c.spin_until(lambda: not r.is_alive(), 90.0, "the replay to refuse")
    r.join()
    assert isinstance(r.error, ValueError), r.error
    problem = str(r.error)
    assert problem.startswith(
        f"{space}/motor_speed: the log's /motor_speed is std_msgs/msg/Float64"
    )
    assert problem.endswith(
        "takes std_msgs/msg/String; nothing published (choose --topics, or "
        "--remap /motor_speed:=ANOTHER)"
    )
    assert "\n" not in problem
    assert r.result is None and c.messages(f"{space}/motor_speed") == []


def test_end_to_end_the_predictor_node_answers_a_replayed_log(log, collector):
    """The real node in-process, its inputs fed from the log; its risk follows the log."""
    space = ns()
    c = collector({f"{space}/squeak/risk": Float64})
    node = c.add(
        SqueakPredictorNode(
            context=c.ctx,
            namespace=space,
            parameter_overrides=[Parameter("hardware_id", value=space)],
        )
    )
    replay(
        c,
        log,
        rate=4.0,
        topics=["/motor_speed", "/axial_load"],
        remap={"/motor_speed": f"{space}/motor_speed", "/axial_load": f"{space}/axial_load"},
    )
    final = SqueakModel().predict(speed(STEPS - 1), load(STEPS - 1))
    risks = c.got[f"{space}/squeak/risk"]
    c.spin_until(
        lambda: risks and risks[-1][1].data == final.probability,
        3.0,
        "the P(squeak) of the last operating point",
    )
    values = [m.data for _, m in risks]
    assert len(values) > 20 and all(math.isfinite(v) and 0 <= v <= 1 for v in values)
    assert max(values) > 0.99 and final.probability < 0.01  # through the band and out
    assert node.live.inputs.speed_rad_s == speed(STEPS - 1)


# ----------------------------------------------------------------------------- signals
CHILD = """
import sys
from leadscrew_ros.bag.logfile import log_files
from leadscrew_ros.ros.replay_live import publish_log
n = publish_log(log_files(sys.argv[1]), rate=float(sys.argv[2]), loop=sys.argv[3] == "loop",
                topics=["/motor_speed"], remap={"/motor_speed": sys.argv[4]})
print(f"RETURNED {n}")
"""


def child(log: list[Path], rate: float, mode: str, topic: str, tmp_path: Path):
    err = open(tmp_path / "stderr", "w+")
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(log[0].parent), str(rate), mode, topic],
        stdout=subprocess.PIPE,
        stderr=err,
        text=True,
        env=dict(os.environ),
    )
    return proc, err


def finish(proc: subprocess.Popen, err) -> tuple[str, str]:
    """The child's output once it exited; a child that does not exit is SIGKILLed and the
    Fast DDS shared memory it left is cleaned (`fastdds shm clean` leaves live processes'
    segments alone)."""
    try:
        out, _ = proc.communicate(timeout=10)
    finally:
        stop(proc)
    err.seek(0)
    stderr = err.read()
    err.close()
    return out, stderr


def test_loop_repeats_until_sigint_then_exits_cleanly(log, collector, tmp_path):
    topic = f"{ns()}/speed"
    c = collector({topic: Float64})
    proc, err = child(log, 10.0, "loop", topic, tmp_path)
    c.spin_until(
        lambda: len(c.got[topic]) >= 2 * STEPS + 10 or proc.poll() is not None, 60.0, "two passes"
    )
    proc.send_signal(signal.SIGINT)
    out, stderr = finish(proc, err)
    settle(c)
    assert proc.returncode == 0 and "Traceback" not in stderr, (out, stderr)
    got = c.messages(topic)
    passes = len(got) // STEPS
    assert passes >= 2 and got == (expected(log, "/motor_speed") * (passes + 1))[: len(got)]
    assert out.splitlines()[-2] == (
        f"replay stopped: {len(got)} messages published ({passes} passes)"
    )
    assert out.splitlines()[-1] == f"RETURNED {len(got)}"
    assert stderr.splitlines()[-1] == "leadscrew-squeak: stopped by SIGINT"


def test_sigterm_stops_a_replay_cleanly_before_its_end(log, collector, tmp_path):
    topic = f"{ns()}/speed"
    c = collector({topic: Float64})
    proc, err = child(log, 0.5, "once", topic, tmp_path)  # 4 s of replay
    c.spin_until(
        lambda: len(c.got[topic]) >= 5 or proc.poll() is not None, 60.0, "the first messages"
    )
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, stderr = finish(proc, err)
    # a stall, not a speed: fewer than all messages (below) shows it stopped before its end;
    # the exit (rclpy shutdown, coverage) took 2.35 s on a loaded machine
    assert time.monotonic() - t0 < 15.0
    settle(c)
    assert proc.returncode == 0 and "Traceback" not in stderr, (out, stderr)  # asked: success
    lines = out.splitlines()
    n = len(c.got[topic])
    assert 5 <= n < STEPS
    assert lines[-2:] == [f"replay stopped: {n} messages published", f"RETURNED {n}"]
    assert stderr.splitlines()[-1] == "leadscrew-squeak: stopped by SIGTERM"


# ----------------------------------------------------------------------------- errors
@pytest.fixture
def nothing_starts(monkeypatch):
    """Errors must come before rclpy starts (so before anything is published)."""

    def refuse(*args, **kwargs):
        raise AssertionError("rclpy.init called")

    monkeypatch.setattr(rclpy, "init", refuse)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"rate": 0.0}, "rate must be a finite number > 0"),
        ({"rate": -1.0}, "rate must be"),
        ({"rate": math.nan}, "rate must be"),
        ({"rate": math.inf}, "rate must be"),
        ({"start_offset_s": -0.1}, "start offset must be a finite number >= 0"),
        ({"start_offset_s": math.nan}, "start offset must be"),
        ({"start_offset_s": 1.98}, r"not less than the log's duration \(1.980 s\)"),
        ({"topics": ["/motor_speed", "/nope"]}, "topic /nope not in the log"),
        ({"remap": {"/nope": "/x"}}, "remapped topic /nope not in the log"),
        ({"remap": {"/motor_speed": "bad name"}}, "remap target 'bad name' is not a valid ROS"),
        ({"remap": {"/motor_speed": "/axial_load"}}, "would both be published on /axial_load"),
        ({"wait_for_subscriber_s": -1.0}, "subscriber wait"),
    ],
)
def test_bad_arguments_raise_value_error_before_anything_starts(log, nothing_starts, kwargs, match):
    with pytest.raises(ValueError, match=match):
        publish_log(log, **kwargs)


def test_no_files_and_a_zero_length_loop_are_bad_arguments(tmp_path, nothing_starts):
    with pytest.raises(ValueError, match="no log files"):
        publish_log([])
    single = record(tmp_path, steps=1)
    with pytest.raises(ValueError, match="cannot loop a log whose messages all have the same"):
        publish_log(single, loop=True)


def foreign_mcap(
    path: Path,
    profile: str = "ros2",
    type_name: str = "std_msgs/msg/Float64",
    payload: bytes = b"\x00\x01\x00\x00",
) -> Path:
    """An MCAP with one /motor_speed message, written by hand."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile=profile, library="test")
        schema = w.register_schema(
            type_name, "ros2msg", msgdefs.definition("std_msgs/msg/Float64").encode()
        )
        channel = w.register_channel("/motor_speed", "cdr", schema)
        w.add_message(channel, T0, payload, T0)
        w.finish()
    return path


@pytest.mark.parametrize(
    "damage, match",
    [
        ("truncated second file", "_1.mcap: truncated: no footer"),
        ("garbage", r"garbage.mcap: not an MCAP file \(bad magic\)"),
        ("empty", "empty.mcap: empty file"),
        ("missing", "(?i)missing.mcap: no such file"),
        ("foreign profile", "foreign MCAP: profile ''"),
        ("bad payload", "message 0 on /motor_speed is not a valid std_msgs/msg/Float64"),
        ("unknown type", "type 'nosuch_msgs/msg/Thing', which is not an installed"),
        ("only outputs", "no predictor input topics"),
        (
            "type change",
            "other_0.mcap: topic /motor_speed is std_msgs/msg/Float32 here, "
            "std_msgs/msg/Float64 in an earlier file",
        ),
    ],
)
def test_unreadable_logs_raise_log_error_before_anything_starts(
    log, tmp_path, nothing_starts, damage, match
):
    files = [tmp_path / f.name for f in log]
    for src, dst in zip(log, files, strict=True):
        shutil.copy(src, dst)
    if damage == "truncated second file":
        with open(files[1], "r+b") as f:
            f.truncate(f.seek(0, os.SEEK_END) // 2)
    elif damage == "garbage":
        files = [tmp_path / "garbage.mcap"]
        files[0].write_bytes(b"not a log at all" * 10)
    elif damage == "empty":
        files = [tmp_path / "empty.mcap"]
        files[0].touch()
    elif damage == "missing":
        files.insert(1, tmp_path / "missing.mcap")
    elif damage == "foreign profile":
        files = [foreign_mcap(tmp_path / "f.mcap", profile="")]
    elif damage == "bad payload":
        files = [foreign_mcap(tmp_path / "f.mcap")]
    elif damage == "unknown type":
        files = [foreign_mcap(tmp_path / "f.mcap", type_name="nosuch_msgs/msg/Thing")]
    elif damage == "type change":  # a split file from somewhere else
        files.append(
            foreign_mcap(
                tmp_path / "other_0.mcap",
                type_name="std_msgs/msg/Float32",
                payload=serialize_message(Float64(data=1.0)),
            )
        )
    elif damage == "only outputs":
        rec = Recorder(RecordSettings(directory=str(tmp_path)))
        rec.start(T0)
        write_message(rec, "/squeak/risk", Float64(data=0.1), T0)
        rec.stop()
        files = log_files(rec.bag)
    with pytest.raises(LogError, match=match) as exc:
        publish_log(files)
    assert "\n" not in str(exc.value)


# ----------------------------------------------------------------------------- ROS arguments
def test_ros_args_namespace_moves_the_inputs_into_it_and_rcl_remaps_apply(log, collector):
    """`--ros-args -r __ns:=/seat_right`: every input is published in the namespace, out of the
    one it was recorded in (/robot/nut_position too); an rcl remap applies on top, and our
    remap's relative target resolves in the namespace."""
    seat = ns()
    topics = {f"{seat}/{name}": TYPES[f"/{name}"] for name in ("axial_load", "joint_states")}
    topics.update(
        {
            f"{seat}/nut_position": Float64,
            f"{seat}/speed": Float64,
            "/motor_speed": Float64,
            f"{seat}/motor_speed": Float64,
        }
    )
    c = collector(topics)
    r = replay(
        c,
        log,
        rate=20.0,
        remap={"/motor_speed": "speed"},
        ros_args=[
            "--ros-args",
            "-r",
            f"__ns:={seat}",
            "-r",
            f"{seat}/axial_load:={seat}/load_remapped",
        ],
    )
    assert c.messages(f"{seat}/speed") == expected(log, "/motor_speed")
    assert c.messages(f"{seat}/nut_position") == expected(log, "/robot/nut_position")
    assert c.messages(f"{seat}/joint_states") == expected(log, "/joint_states")
    assert c.got[f"{seat}/axial_load"] == []  # remapped by rcl
    assert c.got["/motor_speed"] == [] and c.got[f"{seat}/motor_speed"] == []
    assert r.result == len(INPUTS) * STEPS


@pytest.mark.parametrize(
    "ros_args, problem",
    [
        (["--ros-args", "-r", "__ns:=seat"], "Couldn't parse remap rule: '-r __ns:=seat'"),
        (["--ros-args", "--bogus"], "unknown ROS arguments ['--bogus']"),
    ],
)
def test_bad_ros_args_are_one_line(log, capfd, ros_args, problem):
    with pytest.raises(ValueError) as exc:
        publish_log(log, ros_args=ros_args, wait_for_subscriber_s=0.0)
    assert str(exc.value).startswith("--ros-args: ") and problem in str(exc.value)
    assert "\n" not in str(exc.value)
    out, err = capfd.readouterr()
    assert "[ERROR]" not in err and "[WARN]" not in err  # rcl's own lines dropped


def test_cli_remap_is_ours_not_a_deprecated_rcl_rule(log, tmp_path):
    """rcl used to read the process's argv and warn about `/motor_speed:=/x` as a deprecated
    remap rule; --ros-args after `replay --publish` reach rcl, the rest does not."""
    seat = ns()
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "leadscrew_ros.cli",
            "replay",
            str(log[0].parent),
            "--publish",
            "--no-wait",
            "--rate",
            "50",
            "--topics",
            "/motor_speed",
            "--remap",
            f"/motor_speed:={seat}/x",
            "--ros-args",
            "-r",
            f"__ns:={seat}",
            "--log-level",
            "warn",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ),
    )
    assert run.returncode == 0, run.stderr
    assert run.stderr == "", run.stderr  # no rcl warning, no traceback
    assert f"/motor_speed -> {seat}/x" in run.stdout
    assert f"replay done: {STEPS} messages" in run.stdout
