# SPDX-License-Identifier: Apache-2.0
"""Offline replay of the logs real robots leave (issue 8): namespaced inputs, JointState-only
logs with a nominal load, rosbag2 sqlite3 (.db3) storage, empty topics, log times that go
backwards or repeat, a nut that travels, values just past a limit, and memory that does not
grow with the log.

Bags are written by rosbags' rosbag2 writer (MCAP and sqlite3 storage), by the mcap writer and
by our synthetic-log recorder.
"""

import gc
import json
import sqlite3
import tracemalloc

import numpy as np
import pytest
from mcap.writer import Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter

from harness.logs import EXACT, TYPESTORE, cli, decoded, f64, run_replay, write_mcap
from leadscrew_ros.bag import msgdefs
from leadscrew_ros.bag.synthetic import DutyCycle, samples, write_log
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.review import replay as replay_module
from leadscrew_ros.review import report, timeline
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.timeline import InputSettings
from leadscrew_ros.ros import replay_live

T0 = 1_700_000_000_000_000_000


def stroke_bag(
    path, namespaces=("",), load=True, storage=StoragePlugin.MCAP, samples=80, rate_hz=20.0
):
    """A stroke on `<ns>/joint_states` (one joint) and, if `load`, `<ns>/axial_load`, for each
    namespace, written by rosbags' rosbag2 writer."""
    t = TYPESTORE.types
    profile = StrokeProfile(duration_s=samples / rate_hz)
    with RosbagsWriter(path, version=9, storage_plugin=storage) as w:
        conns = [
            (
                w.add_connection(
                    f"{ns}/joint_states", "sensor_msgs/msg/JointState", typestore=TYPESTORE
                ),
                w.add_connection(f"{ns}/axial_load", "std_msgs/msg/Float64", typestore=TYPESTORE)
                if load
                else None,
            )
            for ns in namespaces
        ]
        for k in range(samples):
            s = profile.state(k / rate_hz)
            now = T0 + int(k * 1e9 / rate_hz)
            header = t["std_msgs/msg/Header"](
                t["builtin_interfaces/msg/Time"](*divmod(now, 1_000_000_000)), ""
            )
            js = t["sensor_msgs/msg/JointState"](
                header,
                ["screw"],
                np.array([s.screw_angle_rad]),
                np.array([s.speed_rad_s]),
                np.zeros(0),
            )
            for j, (js_conn, load_conn) in enumerate(conns):
                w.write(js_conn, now + j, TYPESTORE.serialize_cdr(js, js_conn.msgtype))
                if load_conn is not None:
                    w.write(
                        load_conn,
                        now + 1000 + j,
                        TYPESTORE.serialize_cdr(
                            t["std_msgs/msg/Float64"](s.load_n), load_conn.msgtype
                        ),
                    )
    return path


def risks(annotated, topic="/replay/squeak/risk"):
    return [(m[1], m[5].data) for m in decoded(annotated, topics=[topic])]


# ----------------------------------------------------------------------------- namespaces
def test_inputs_in_one_namespace_are_found_without_topic_options(tmp_path, capsys):
    log = stroke_bag(tmp_path / "bag", namespaces=("/seat_left",))
    code, out, err = cli(
        capsys, "replay", log, "--out", tmp_path / "out", "--no-report", "--joint-name", "screw"
    )
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["input_messages"] == {"/seat_left/joint_states": 80, "/seat_left/axial_load": 80}
    assert summary["namespace"] == "/seat_left" and summary["predictions"] > 20
    # predictions under /replay/<namespace>: beside the seat's own /seat_left/squeak/* if any
    annotated = tmp_path / "out" / "bag.annotated.mcap"
    assert len(risks(annotated, "/replay/seat_left/squeak/risk")) == summary["predictions"]


def test_inputs_in_several_namespaces_ask_for_one(tmp_path, capsys):
    log = stroke_bag(tmp_path / "bag", namespaces=("/seat_left", "/seat_right"), samples=40)
    code, out, err = cli(capsys, "replay", log, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and out == "" and len(err.splitlines()) == 1
    assert "several namespaces (/seat_left, /seat_right)" in err and "--namespace NS" in err
    code, out, err = cli(
        capsys,
        "replay",
        log,
        "--out",
        tmp_path / "out",
        "--quiet",
        "--no-report",
        "--namespace",
        "seat_right",
        "--joint-name",
        "screw",
    )
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert set(summary["input_messages"]) == {"/seat_right/joint_states", "/seat_right/axial_load"}
    # an absolute topic option is taken as it is, whatever the namespace
    r = run_replay(
        log,
        tmp_path / "abs",
        load_topic="/seat_left/axial_load",
        joint_states_topic="/seat_left/joint_states",
        joint_name="screw",
    )
    assert set(r.inputs) == {"/seat_left/joint_states", "/seat_left/axial_load"}


def test_offline_and_live_replay_share_the_input_rule():
    assert replay_live._is_input is timeline.is_input

    def topic(name, type_name):
        return timeline.Topic(name, type_name, "ros2msg", "", "cdr", {})

    topics = [
        topic("/motor_speed", "std_msgs/msg/Float32"),  # root: by name alone
        topic("/a/b/axial_load", "std_msgs/msg/Float64"),
        topic("/c/axial_load", "std_msgs/msg/String"),  # wrong type: not an input
        topic("/squeak/motor_speed", "std_msgs/msg/Float64"),  # the outputs' namespace
        topic("/d/velocity", "std_msgs/msg/Float64"),
    ]
    assert [t.name for t in topics if replay_live._is_input(t)] == [
        "/motor_speed",
        "/a/b/axial_load",
    ]
    assert timeline.input_namespaces(topics, InputSettings()) == ["/", "/a/b"]
    assert timeline.input_namespaces(
        topics, InputSettings(speed_topic="velocity", load_topic="/a/b/axial_load")
    ) == ["/d"]


# ----------------------------------------------------------------------------- nominal load
def test_joint_states_only_log_takes_a_nominal_load(tmp_path, capsys):
    log = stroke_bag(tmp_path / "bag", load=False)
    code, out, err = cli(
        capsys, "replay", log, "--out", tmp_path / "x", "--quiet", "--joint-name", "screw"
    )
    assert code == 2 and len(err.splitlines()) == 1
    assert "no axial load" in err and "--load N" in err
    # --load N is a load published once before the log: the same predictions as a log
    # with one load message at its start
    a = run_replay(log, tmp_path / "a", nominal_load_n=250.0, joint_name="screw", **EXACT)
    once = tmp_path / "once.mcap"
    messages = [
        (m[0], "sensor_msgs/msg/JointState", m[4], m[1]) for m in decoded(next(log.glob("*.mcap")))
    ]
    write_mcap(once, [f64("/axial_load", 250.0, T0 - 1)] + messages)
    b = run_replay(once, tmp_path / "b", joint_name="screw", **EXACT)
    assert a.predictions == b.predictions > 20
    assert risks(a.annotated) == risks(b.annotated)
    code, out, err = cli(
        capsys,
        "replay",
        log,
        "--out",
        tmp_path / "c",
        "--quiet",
        "--no-report",
        "--load",
        "250",
        "--joint-name",
        "screw",
    )
    assert code == 0, err


# ----------------------------------------------------------------------------- .db3
def test_sqlite3_bag_replays_like_its_mcap_twin(tmp_path, capsys):
    mcap_bag = stroke_bag(tmp_path / "mcap_bag")
    db3_bag = stroke_bag(tmp_path / "db3_bag", storage=StoragePlugin.SQLITE3)
    (db3,) = db3_bag.glob("*.db3")
    a = run_replay(mcap_bag, tmp_path / "a", joint_name="screw", **EXACT)
    b = run_replay(db3_bag, tmp_path / "b", joint_name="screw", **EXACT)
    assert b.files == [db3] and b.messages == a.messages == 160
    assert risks(a.annotated) == risks(b.annotated) and a.predictions > 20
    # the originals are copied with their definitions (as stored, or installed before Iron)
    with sqlite3.connect(db3) as con:
        con.execute("DROP TABLE IF EXISTS message_definitions")
    code, _, err = cli(
        capsys,
        "replay",
        db3,
        "--out",
        tmp_path / "c",
        "--quiet",
        "--no-report",
        "--joint-name",
        "screw",
    )
    assert code == 0, err
    from mcap.reader import make_reader

    with open(tmp_path / "c" / f"{db3.stem}.annotated.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    schemas = {
        c.topic: summary.schemas[c.schema_id].data.decode() for c in summary.channels.values()
    }
    assert schemas["/joint_states"] == msgdefs.definition("sensor_msgs/msg/JointState")


def test_a_broken_db3_file_is_a_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.db3"
    bad.write_bytes(b"SQLite format 2\0" + bytes(200))
    code, out, err = cli(capsys, "replay", bad, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and len(err.splitlines()) == 1
    assert f"{bad}: not a rosbag2 sqlite3 (.db3) file" in err


# ----------------------------------------------------------------------------- empty topics
def test_empty_input_topics_are_named(tmp_path, capsys):
    log = tmp_path / "empty.mcap"
    with open(log, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2")
        for topic in ("/motor_speed", "/axial_load"):
            schema = w.register_schema(
                "std_msgs/msg/Float64",
                "ros2msg",
                msgdefs.definition("std_msgs/msg/Float64").encode(),
            )
            channel = w.register_channel(topic, "cdr", schema)
            if topic == "/motor_speed":
                w.add_message(channel, T0, f64(topic, 3.0, T0)[2], T0)
        w.finish()
    code, out, err = cli(capsys, "replay", log, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and len(err.splitlines()) == 1
    assert "/axial_load exists in the log but has no messages" in err
    assert "its topics: /axial_load (empty), /motor_speed" in err


# ----------------------------------------------------------------------------- log time
def test_backwards_and_repeated_log_times_are_counted_and_never_drawn(tmp_path):
    s = 1_000_000_000
    log = write_mcap(
        tmp_path / "clock.mcap",
        [
            f64("/axial_load", 200.0, 0),
            f64("/motor_speed", 20.0, 1 * s),
            f64("/motor_speed", 21.0, 2 * s),
            f64("/motor_speed", 99.0, 1 * s // 2),  # stale
            f64("/motor_speed", 22.0, 3 * s),
            f64("/motor_speed", 23.0, 3 * s),  # repeated
            f64("/axial_load", 210.0, 4 * s),
        ],
        chunked=False,
    )
    r = run_replay(log, tmp_path / "out", **EXACT)
    assert dict(r.timeline.backwards) == {"/motor_speed": 1}
    assert dict(r.timeline.duplicates) == {"/motor_speed": 1}
    assert r.timeline.speed == 23.0 and r.predictions == 5
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["log_time"] == {
        "backwards": {"/motor_speed": 1},
        "backwards_max_s": 1.5,
        "duplicates": {"/motor_speed": 1},
    }
    assert len(summary["warnings"]) == 2
    text = (tmp_path / "out" / "summary.txt").read_text()
    assert "warning: log time goes backwards 1 time(s) on /motor_speed (up to 1.5 s)" in text
    assert "warning: log time repeats 1 time(s) on /motor_speed" in text
    t, lo, hi, _, _ = r.timeline.trace.series()
    assert np.nanmax(hi[:, 0]) == 23.0  # the stale 99 rad/s is not drawn
    assert np.all(np.diff(t) > 0)


def test_the_nut_is_drawn_only_when_measured(tmp_path):
    s = 1_000_000_000
    plain = write_mcap(
        tmp_path / "plain.mcap",
        [f64("/motor_speed", 20.0 + k, k * s) for k in range(5)] + [f64("/axial_load", 200.0, 1)],
    )
    r = run_replay(plain, tmp_path / "a")
    assert not r.timeline.nut_measured and np.isnan(r.timeline.trace.series()[1][:, 2]).all()
    fig = r.plot()
    assert [ax.get_ylabel() for ax in fig.axes] == [
        "speed [rad/s]",
        "axial load [N]",
        "P(squeak) [-]",
    ]
    assert "no nut input" in fig.axes[0].get_title()

    cycle = DutyCycle(duration_s=6.0, rate_hz=25.0, rest_s=1.0)
    r = run_replay(write_log(cycle, tmp_path / "bag"), tmp_path / "b", joint_name=cycle.joint_name)
    _, lo, hi, _, _ = r.timeline.trace.series()
    # from the first joint state on, no default 150 mm before it (a spike at the start)
    first = samples(cycle).nut_position_m[0]
    k = np.flatnonzero(np.isfinite(hi[:, 2]))[0]
    assert lo[k, 2] == pytest.approx(first, abs=1e-9) and hi[k, 2] < first + 1e-3 < 0.1
    assert "nut position [mm]" in [ax.get_ylabel() for ax in r.plot().axes]


def test_a_travelling_nut_is_mapped_per_band(tmp_path):
    assert len(report.nut_bands(np.array([0.1, 0.104]))) == 2  # one band
    assert len(report.nut_bands(np.linspace(0.02, 0.07, 9))) == 3  # 50 mm: two bands
    assert len(report.nut_bands(np.linspace(0.02, 0.22, 9))) == 5  # 200 mm: four
    cycle = DutyCycle(duration_s=30.0, rate_hz=20.0, rest_s=2.0)
    r = run_replay(
        write_log(cycle, tmp_path / "bag"), tmp_path / "out", joint_name=cycle.joint_name
    )
    nuts = r.plot_data.points.sample()[:, 2]
    assert nuts.max() - nuts.min() > 0.1
    paths = report.write_report(r, SqueakModel(), tmp_path / "out", report.QUICK)
    assert all(p.stat().st_size > 5000 for p in paths)


# ----------------------------------------------------------------------------- exact numbers
def test_rejected_values_print_past_their_limit(tmp_path):
    s = 1_000_000_000
    log = write_mcap(
        tmp_path / "limits.mcap",
        [
            f64("/motor_speed", 20.0, 0),
            f64("/axial_load", 1.0000001e7, s),
            f64("/nut_position", 0.2400001, 2 * s),
            f64("/axial_load", 200.0, 3 * s),
        ],
    )
    r = run_replay(log, tmp_path / "out")
    text = (tmp_path / "out" / "summary.txt").read_text()
    # the example is the node's own message (live.rules)
    assert (
        "1 x load beyond 1e+07 N (first: load = 1.0000001e+07 N exceeds the plausible "
        "magnitude 1e+07 N)"
    ) in text
    assert (
        "1 x nut position off the screw [0, 0.24] m (first: nut position 0.2400001 m is "
        "off the screw: allowed [0, 0.24] m (z_o + b <= L))"
    ) in text
    assert (
        json.loads((tmp_path / "out" / "summary.json").read_text())["rejected_examples"]
        == r.timeline.rejected_example
    )


# ----------------------------------------------------------------------------- memory
def test_replay_memory_does_not_grow_with_the_log(tmp_path, monkeypatch):
    """What a replay holds (its result included) hardly changes for a log four times longer, and
    its Python heap peak about the same (a maximum over more segments: a little higher). The
    nut stays put (one model); small segments and chunks so that both logs fill them. Peak
    RSS of long logs: benchmarks/bench_replay.py --rss."""
    monkeypatch.setattr(replay_module, "_SEGMENT_MESSAGES", 500)
    monkeypatch.setattr(replay_module, "_IN_FLIGHT_MESSAGES", 1000)
    monkeypatch.setattr(replay_module, "EPISODES_KEPT", 3)
    monkeypatch.setattr(replay_module, "_CHUNK_BYTES", 1 << 15)
    settings = ReplaySettings(
        InputSettings(joint_states_topic="/unused"), workers=0, progress=False
    )
    held, peaks = [], []
    for minutes in (0.5, 2):
        bag = write_log(
            DutyCycle(duration_s=60.0 * minutes, rate_hz=50.0, rest_s=3.0),
            tmp_path / f"bag{minutes}",
        )
        replay(bag, SqueakModel(), tmp_path / f"warm{minutes}", settings)  # caches filled
        tracemalloc.start()
        try:
            r = replay(bag, SqueakModel(), tmp_path / f"out{minutes}", settings)
            gc.collect()
            now, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        held.append(now)
        peaks.append(peak)
        episodes = json.loads((tmp_path / f"out{minutes}" / "episodes.json").read_text())
        assert len(r.episodes) == 3 < len(episodes) == r.episode_count
        assert r.time_in_squeak_s == pytest.approx(sum(e["duration_s"] for e in episodes))
        assert r.messages == 3 * 3000 * minutes
    # the old replay kept ~70 bytes per input message and more per prediction: +1 MB here
    assert held[1] < held[0] + 300_000, held
    assert peaks[1] < 1.3 * peaks[0], peaks
