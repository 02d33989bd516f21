# SPDX-License-Identifier: Apache-2.0
"""Any robot's log (issue 29, field paths): speed, load and nut position as a number at a field
path of any message type the log has a definition for, times a scale (`--speed-field`,
`--speed-scale`, ...; `bag.fieldpath`), with header stamps as sample times; the same options in
`review` and `calibrate`. Logs are written by rosbags' rosbag2 writer (its typestore's
definitions, stored in the log as rosbag2 does), and compared with their std_msgs/Float64 twins.
"""

from __future__ import annotations

import importlib
import json
from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosbags.typesys import get_types_from_msg

from harness.logs import EXACT, TYPESTORE, cli, decoded, run_replay
from leadscrew_ros.bag import fieldpath, logmeta
from leadscrew_ros.bag.fieldpath import FieldPathError, compile_path, installed
from leadscrew_ros.bag.schema import CdrError, parse
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.review.timeline import InputSettings

T0 = 1_700_000_000_000_000_000
RPM = 0.10472  # rad/s per rpm, the scale of the worked example
T = TYPESTORE.types
# control_msgs/JointTrajectoryControllerState (Jazzy), its fields up to `output`: control_msgs is
# no common_interfaces package, so neither the wheels nor rosbags' typestore have it
CONTROLLER_STATE = "control_msgs/msg/JointTrajectoryControllerState"
CONTROLLER_STATE_MSG = """\
std_msgs/Header header
string[] joint_names
trajectory_msgs/JointTrajectoryPoint reference
trajectory_msgs/JointTrajectoryPoint feedback
trajectory_msgs/JointTrajectoryPoint error
trajectory_msgs/JointTrajectoryPoint output
"""
TYPESTORE.register(get_types_from_msg(CONTROLLER_STATE_MSG, CONTROLLER_STATE))


def _header(t_ns: int):
    return T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](*divmod(t_ns, 10**9)), "f")


def _ser(msg, type_name: str) -> bytes:
    return bytes(TYPESTORE.serialize_cdr(msg, type_name))


def odometry(speed_field_value: float, stamp_ns: int):
    v3 = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/Twist"](v3(0.0, 0.0, 0.0), v3(0.0, 0.0, speed_field_value))
    pose = T["geometry_msgs/msg/Pose"](
        T["geometry_msgs/msg/Point"](1.0, 2.0, 3.0),
        T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
    )
    return T["nav_msgs/msg/Odometry"](
        _header(stamp_ns),
        "base_link",
        T["geometry_msgs/msg/PoseWithCovariance"](pose, np.arange(36.0)),
        T["geometry_msgs/msg/TwistWithCovariance"](twist, np.zeros(36)),
    )


def wrench(force_z: float, stamp_ns: int):
    v3 = T["geometry_msgs/msg/Vector3"]
    return T["geometry_msgs/msg/WrenchStamped"](
        _header(stamp_ns), T["geometry_msgs/msg/Wrench"](v3(1.0, 2.0, force_z), v3(0.0, 0.0, 0.0))
    )


def controller_state(velocities: list[float], stamp_ns: int):
    point = T["trajectory_msgs/msg/JointTrajectoryPoint"]
    duration = T["builtin_interfaces/msg/Duration"](0, 0)

    def p(v):
        return point(np.zeros(len(v)), np.array(v, float), np.zeros(0), np.zeros(0), duration)

    return T[CONTROLLER_STATE](
        _header(stamp_ns), ["lift", "screw"], p([0.0, 0.0]), p(velocities), p([0.0]), p([0.0])
    )


def write_bag(path, rows):
    """rows: (topic, type, message, log time ns), written in this order."""
    with RosbagsWriter(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for topic, type_name, msg, t in rows:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, type_name, typestore=TYPESTORE)
            w.write(conns[topic], t, _ser(msg, type_name))
    return path


def one_odometry_bag(path):
    """A load and one Odometry message on /odom: enough for the option checks."""
    rows = [
        ("/axial_load", "std_msgs/msg/Float64", f64(200.0), T0),
        ("/odom", "nav_msgs/msg/Odometry", odometry(20.0, T0), T0 + 1),
    ]
    return write_bag(path, rows)


def f64(value: float):
    return T["std_msgs/msg/Float64"](value)


def stroke(samples: int = 60, rate_hz: float = 20.0):
    """(log time, speed [rad/s], load [N]) of a stroke through the squeak band."""
    profile = StrokeProfile(duration_s=samples / rate_hz)
    out = []
    for k in range(samples):
        s = profile.state(k / rate_hz)
        out.append((T0 + int(k * 1e9 / rate_hz), s.speed_rad_s, s.load_n))
    return out


def risks(result):
    return [(m[1], m[5].data) for m in decoded(result.annotated, ["/replay/squeak/risk"])]


def twin(path, points):
    """The std_msgs/Float64 log of the same speeds and loads at the same log times."""
    rows = []
    for t, speed, load in points:
        rows += [("/motor_speed", "std_msgs/msg/Float64", f64(speed), t)]
        rows += [("/axial_load", "std_msgs/msg/Float64", f64(load), t + 1000)]
    return write_bag(path, rows)


def assert_same_predictions(a, b):
    ra, rb = risks(a), risks(b)
    assert len(ra) == len(rb) == a.predictions > 5
    assert [t for t, _ in ra] == [t for t, _ in rb]
    assert np.allclose([p for _, p in ra], [p for _, p in rb], rtol=1e-9, atol=1e-12)
    assert a.recomputes == b.recomputes and a.episode_count == b.episode_count


# ----------------------------------------------------------------------------- replay
def test_odometry_speed_in_rpm_and_float32_load_replay_as_their_float64_twin(tmp_path, capsys):
    points = stroke()
    rows = []
    for t, speed, load in points:
        rows += [("/odom", "nav_msgs/msg/Odometry", odometry(speed / RPM, t), t)]
        rows += [("/axial_load", "std_msgs/msg/Float32", T["std_msgs/msg/Float32"](load), t + 1000)]
    log = write_bag(tmp_path / "odom", rows)
    code, out, err = cli(
        capsys,
        "replay",
        log,
        "--out",
        tmp_path / "out",
        "--no-report",
        "--quiet",
        "--speed-topic",
        "/odom",
        "--speed-field",
        "twist.twist.angular.z",
        "--speed-scale",
        RPM,
        "--workers",
        0,
    )
    assert code == 0, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["input_messages"] == {"/odom": len(points), "/axial_load": len(points)}
    assert summary["rejected_inputs"] == {} and summary["predictions"] > 5
    # the twin: the speeds as scaled by the replay, the loads as float32 holds them
    exact = [(t, RPM * (speed / RPM), float(np.float32(load))) for t, speed, load in points]
    inputs = dict(speed_topic="/odom", speed_field="twist.twist.angular.z", speed_scale=RPM)
    a = run_replay(log, tmp_path / "a", **inputs)
    b = run_replay(twin(tmp_path / "twin", exact), tmp_path / "b")
    assert_same_predictions(a, b)
    assert summary["predictions"] == a.predictions
    # the replay's own record keeps the path and scale (a calibration reads them back)
    own = logmeta.read(a.annotated, logmeta.REPLAY_RECORD_NAME)
    assert own.node["speed_field"] == "twist.twist.angular.z"
    assert float(own.node["speed_scale"]) == RPM


def test_wrench_load_and_an_array_element_speed(tmp_path):
    """Load at wrench.force.z of a WrenchStamped, speed at velocity[2] of a JointState of three
    joints and at feedback.velocities[1] of a trajectory controller's state."""
    points = stroke(40)
    js = T["sensor_msgs/msg/JointState"]
    rows, state_rows = [], []
    for t, speed, load in points:
        msg = js(
            _header(t), ["a", "b", "screw"], np.zeros(3), np.array([7.0, -3.0, speed]), np.zeros(0)
        )
        rows += [("/drive/joints", "sensor_msgs/msg/JointState", msg, t)]
        rows += [("/drive/wrench", "geometry_msgs/msg/WrenchStamped", wrench(load, t), t + 1000)]
        state_rows += [("/ctrl/state", CONTROLLER_STATE, controller_state([9.0, speed], t), t)]
        state_rows += [rows[-1]]
    load = dict(load_topic="/drive/wrench", load_field="wrench.force.z")
    a = run_replay(
        write_bag(tmp_path / "joints", rows),
        tmp_path / "a",
        speed_topic="/drive/joints",
        speed_field="velocity[2]",
        **load,
    )
    c = run_replay(
        write_bag(tmp_path / "ctrl", state_rows),
        tmp_path / "c",
        speed_topic="/ctrl/state",
        speed_field="feedback.velocities[1]",
        **load,
    )
    b = run_replay(twin(tmp_path / "twin", points), tmp_path / "b")
    assert_same_predictions(a, b)
    assert_same_predictions(c, b)
    assert a.timeline.stamped == {"/drive/joints", "/drive/wrench"}


def test_a_message_whose_array_is_too_short_is_rejected_and_the_last_value_kept(tmp_path):
    js = T["sensor_msgs/msg/JointState"]
    rows = [("/axial_load", "std_msgs/msg/Float64", f64(200.0), T0)]
    for k, velocity in enumerate([[1.0, 2.0, 20.0], [1.0, 2.0], [1.0, 2.0, 21.0]]):
        t = T0 + (k + 1) * 10**9
        names = ["a", "b", "c"][: len(velocity)]
        msg = js(_header(t), names, np.zeros(0), np.array(velocity), np.zeros(0))
        rows.append(("/s", "sensor_msgs/msg/JointState", msg, t))
    r = run_replay(
        write_bag(tmp_path / "short", rows),
        tmp_path / "out",
        speed_topic="/s",
        speed_field="velocity[2]",
        **EXACT,
    )
    assert dict(r.rejected) == {"speed field velocity[2] not in the message": 1}
    assert r.timeline.speed == 21.0 and r.predictions == 2


def test_header_stamps_order_the_samples_of_their_topic(tmp_path):
    """A later log time with an older stamp is stale; an earlier log time with a newer stamp is
    taken (a stamped sample delivered late); a zero stamp falls back to the log time."""
    s = 10**9
    odom = "nav_msgs/msg/Odometry"
    rows = [
        ("/axial_load", "std_msgs/msg/Float64", f64(200.0), T0),
        ("/odom", odom, odometry(20.0, T0 + 10 * s), T0 + 1 * s),
        ("/odom", odom, odometry(21.0, T0 + 12 * s), T0 + 2 * s),
        ("/odom", odom, odometry(99.0, T0 + 11 * s), T0 + 3 * s),  # stale by its stamp
        ("/odom", odom, odometry(22.0, T0 + 13 * s), T0 + 3 * s // 2),  # log time back: taken
        ("/odom", odom, odometry(23.0, T0 + 13 * s), T0 + 4 * s),  # same stamp
    ]
    inputs = dict(speed_topic="/odom", speed_field="twist.twist.angular.z", **EXACT)
    r = run_replay(write_bag(tmp_path / "stamps", rows), tmp_path / "out", **inputs)
    assert dict(r.timeline.backwards) == {"/odom": 1}
    assert r.timeline.backwards_max_s == pytest.approx(1.0, abs=1e-9)
    assert dict(r.timeline.duplicates) == {"/odom": 1}
    assert r.timeline.speed == 23.0 and r.predictions == 4
    text = (tmp_path / "out" / "summary.txt").read_text()
    assert "warning: header stamp goes backwards 1 time(s) on /odom (up to 1 s)" in text
    assert "warning: header stamp repeats 1 time(s) on /odom" in text
    # unstamped (zero) messages are ordered by their log times: the same log as above is
    # taken in file order but for the one message whose log time goes back
    rows = [
        (tp, ty, odometry(m.twist.twist.angular.z, 0), t) if ty == odom else (tp, ty, m, t)
        for tp, ty, m, t in rows
    ]
    r = run_replay(write_bag(tmp_path / "zero", rows), tmp_path / "zero_out", **inputs)
    assert dict(r.timeline.backwards) == {"/odom": 1} and not r.timeline.duplicates
    assert r.timeline.speed == 23.0 and r.predictions == 4


@pytest.mark.parametrize(
    "options, line",
    [
        (
            ["--speed-field", "twist.twist.angular.w"],
            "--speed-field twist.twist.angular.w: nav_msgs/msg/Odometry has no field 'w' in "
            "twist.twist.angular (fields: x, y, z) (topic /odom)",
        ),
        (
            ["--speed-field", "header.frame_id"],
            "--speed-field header.frame_id: nav_msgs/msg/Odometry: header.frame_id is a "
            "string, not a number (topic /odom)",
        ),
        (
            ["--speed-field", "twist.covariance"],
            "twist.covariance is an array (float64[36]): index it, e.g. twist.covariance[0]",
        ),
        (["--speed-field", "twist..z"], "--speed-field: 'twist..z' is not a field path"),
        (
            ["--speed-field", "twist.twist.angular.z", "--speed-scale", "0"],
            "--speed-scale must not",
        ),
    ],
)
def test_a_wrong_path_is_one_line_and_exit_2(tmp_path, capsys, options, line):
    log = one_odometry_bag(tmp_path / "bag")
    code, out, err = cli(
        capsys,
        "replay",
        log,
        "--out",
        tmp_path / "out",
        "--quiet",
        "--speed-topic",
        "/odom",
        *options,
    )
    assert code == 2 and out == "" and len(err.splitlines()) == 1, err
    assert err.startswith("leadscrew-squeak: error: ") and line in err, err
    assert "Traceback" not in err


# ----------------------------------------------------------------------------- bag.fieldpath
def test_paths_are_checked_against_the_definition():
    odom = installed("nav_msgs/msg/Odometry")
    assert compile_path(odom, "pose.covariance[35]").steps[-1].index == 35
    with pytest.raises(FieldPathError, match=r"has 36 elements, index 36 is beyond them"):
        compile_path(odom, "pose.covariance[36]")
    with pytest.raises(FieldPathError, match=r"twist.twist is a geometry_msgs/msg/Twist, not a"):
        compile_path(odom, "twist.twist")
    with pytest.raises(FieldPathError, match=r"header.stamp.sec is an int32, it has no fields"):
        compile_path(odom, "header.stamp.sec.x")
    with pytest.raises(FieldPathError, match=r"no installed definition of foo_msgs/msg/Bar"):
        installed("foo_msgs/msg/Bar")
    # integers of any width are numbers: std_msgs Int8 .. UInt64
    for kind in ("Int8", "UInt16", "Int32", "UInt64", "Float32"):
        name = f"std_msgs/msg/{kind}"
        payload = _ser(T[name](7), name)
        assert compile_path(installed(name), "data").read(payload) == 7.0
    with pytest.raises(FieldPathError, match=r"data is a bool, not a number"):
        compile_path(installed("std_msgs/msg/Bool"), "data")


def test_the_cdr_reader_and_the_object_getter_agree():
    """A path through an array of messages and a string before it, both byte orders."""
    msg = controller_state([4.5, -2.25], T0 + 123)
    payload = _ser(msg, CONTROLLER_STATE)
    schema = parse(TYPESTORE.generate_msgdef(CONTROLLER_STATE, ros_version=2)[0], CONTROLLER_STATE)
    for path, value in (("feedback.velocities[1]", -2.25), ("header.stamp.nanosec", 123)):
        fp = compile_path(schema, path)
        assert fp.read(payload) == fp.getter()(msg) == value
    big = bytes(TYPESTORE.serialize_cdr(msg, CONTROLLER_STATE, little_endian=False))
    assert compile_path(schema, "feedback.velocities[1]").read(big) == -2.25
    with pytest.raises(CdrError):
        compile_path(schema, "feedback.velocities[1]").read(payload[:60])


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet="abcdefghijklmnopqrstuvwxyz_.[]0123456789 ", max_size=30))
def test_any_path_text_is_a_number_path_or_one_line(text):
    odom = installed("nav_msgs/msg/Odometry")
    try:
        fp = compile_path(odom, text)
    except FieldPathError as exc:
        assert "\n" not in str(exc) and str(exc)
    else:
        assert fp.steps[-1].field.type in fieldpath.NUMBERS


# ----------------------------------------------------------------------------- review, calibrate
OPTIONS = [
    "--speed-topic",
    "/odom",
    "--speed-field",
    "twist.twist.angular.z",
    "--speed-scale",
    str(RPM),
    "--load-field",
    "wrench.force.z",
    "--nut-scale",
    "0.001",
]
EXPECTED = dict(
    speed_topic="/odom",
    speed_field="twist.twist.angular.z",
    speed_scale=RPM,
    load_field="wrench.force.z",
    nut_scale=0.001,
)


@contextmanager
def _no_cluster(*_args, **_kwargs):
    yield None


def test_review_and_calibrate_take_the_field_options(tmp_path, capsys, monkeypatch):
    from leadscrew_ros.review import fleet

    gather = importlib.import_module("leadscrew_ros.review.calibration.gather")  # the module

    log = write_bag(tmp_path / "logs" / "bag", [("/a", "std_msgs/msg/Float64", f64(1.0), T0)])
    seen = {}

    def stop(what):
        def capture(logs, out, settings, *args, **kwargs):
            seen[what] = settings
            raise fleet.ClusterError("stopped by the test")

        return capture

    monkeypatch.setattr(fleet, "cluster", _no_cluster)
    monkeypatch.setattr(fleet, "review_logs", stop("review"))
    monkeypatch.setattr(gather, "gather", stop("calibrate"))
    code, _, err = cli(capsys, "review", tmp_path / "logs", "--out", tmp_path / "r", *OPTIONS)
    assert code == 2 and "stopped by the test" in err
    code, _, err = cli(capsys, "calibrate", log, "--out", tmp_path / "c", *OPTIONS)
    assert code == 2 and "stopped by the test" in err
    assert seen["review"].inputs == seen["calibrate"].inputs == InputSettings(**EXPECTED)
    # --use-log-params: a recording's node parameters inputs.<input>.field / .scale
    node = {"inputs.speed.field": "twist.twist.angular.z", "inputs.speed.scale": RPM}
    meta = logmeta.LogMetadata({}, {}, {**node, "inputs.speed.type": "nav_msgs/msg/Odometry"})
    settings = fleet.FleetSettings(use_log_params=True)
    _, inputs = settings.model_for(meta, log)
    assert (inputs.speed_field, inputs.speed_scale) == ("twist.twist.angular.z", RPM)


def test_params_file_inputs_reach_the_replay(tmp_path, capsys):
    params = tmp_path / "p.yaml"
    params.write_text(
        "/**:\n  ros__parameters:\n    inputs:\n      speed:\n"
        "        type: nav_msgs/msg/Odometry\n        field: twist.twist.angular.w\n"
    )
    log = one_odometry_bag(tmp_path / "bag")
    code, _, err = cli(
        capsys,
        "replay",
        log,
        "--out",
        tmp_path / "o",
        "--params-file",
        params,
        "--speed-topic",
        "/odom",
    )
    assert code == 2 and "--speed-field twist.twist.angular.w: nav_msgs/msg/Odometry has no" in err


# ----------------------------------------------------------------------------- the node
def test_node_with_an_odometry_speed_predicts_as_with_float64():
    from nav_msgs.msg import Odometry
    from rclpy.parameter import Parameter

    from harness.squeak import LOAD, SQUEAK, SqueakWorld, at
    from leadscrew_ros.live.status import Level

    outputs = ("squeak/risk", "squeak/margin", "squeak/modes")
    with SqueakWorld() as ros:  # the std_msgs/Float64 node
        ros.start()
        at(ros, SQUEAK)
        expected = {t: ros.latest[t] for t in outputs}
    with SqueakWorld() as ros:
        params = {
            "inputs.speed.type": "nav_msgs/msg/Odometry",
            "inputs.speed.field": "twist.twist.angular.z",
            "inputs.speed.scale": RPM,
        }
        node = ros.start(**params)
        pub = ros.probe.create_publisher(Odometry, "motor_speed", 10)
        ros.wait_matched(pub, 10.0)
        msg = Odometry()
        msg.header.stamp.sec, msg.twist.twist.angular.z = 5, SQUEAK / RPM  # rpm
        pub.publish(msg)
        ros.send("axial_load", LOAD)
        modes = list(expected["squeak/modes"].data)
        ros.wait_for("squeak/modes", lambda m: list(m.data) == pytest.approx(modes, rel=1e-9))
        for topic in ("squeak/risk", "squeak/margin"):
            ros.wait_for(
                topic, lambda m, t=topic: m.data == pytest.approx(expected[t].data, rel=1e-9)
            )
        speed = node.live.inputs.speed_rad_s
        assert speed == pytest.approx(SQUEAK, rel=1e-12)
        # a sample stamped before the last one taken is stale; a later one is taken
        topic = f"{ros.ns}/motor_speed"
        msg.header.stamp.sec, msg.twist.twist.angular.z = 4, 100.0 / RPM
        node._on_field(topic, msg, kind="speed")
        assert node.live.inputs.speed_rad_s == speed
        msg.header.stamp.sec = 6
        node._on_field(topic, msg, kind="speed")
        assert node.live.inputs.speed_rad_s == pytest.approx(100.0, rel=1e-12)
        # a path that does not fit the type: the set is rejected with the one line
        [result] = node.set_parameters(
            [Parameter("inputs.speed.field", value="twist.twist.angular.w")]
        )
        assert not result.successful
        assert result.reason == (
            "inputs.speed.field twist.twist.angular.w: nav_msgs/msg/Odometry has no field 'w' "
            "in twist.twist.angular (fields: x, y, z)"
        )
        assert node.get_parameter("inputs.speed.field").value == "twist.twist.angular.z"
        [result] = node.set_parameters(
            [Parameter("inputs.speed.field", value="pose.pose.position.x")]
        )
        assert result.successful
        msg.header.stamp.sec, msg.pose.pose.position.x = 7, 30.0 / RPM
        node._on_field(topic, msg, kind="speed")
        assert node.live.inputs.speed_rad_s == pytest.approx(30.0, rel=1e-12)
        # the stamps taken so far outlive a parameter change: an older one stays stale
        [result] = node.set_parameters([Parameter("inputs.speed.scale", value=RPM)])
        assert result.successful
        msg.header.stamp.sec, msg.pose.pose.position.x = 6, 50.0 / RPM
        node._on_field(topic, msg, kind="speed")
        assert node.live.inputs.speed_rad_s == pytest.approx(30.0, rel=1e-12)
        # the type is read-only (it is the subscription's)
        [result] = node.set_parameters(
            [Parameter("inputs.speed.type", value="std_msgs/msg/Float64")]
        )
        assert not result.successful and "read-only" in result.reason
    with SqueakWorld() as ros:  # an element beyond a message's array: an ERROR diagnostic
        from sensor_msgs.msg import JointState

        node = ros.start(
            **{
                "inputs.speed.type": "sensor_msgs/msg/JointState",
                "inputs.speed.field": "velocity[2]",
            }
        )
        node._on_field(f"{ros.ns}/motor_speed", JointState(velocity=[1.0, 2.0]), kind="speed")
        status = ros.status(lambda s: s.message.startswith("invalid input"))
        assert status.level == bytes([Level.ERROR])
        assert "speed field velocity[2]" in status.message and "\n" not in status.message
        with pytest.raises(
            Exception,
            match=r"inputs.speed.type nav_msgs/msg/Odometri: nav_msgs "
            r"has no message type Odometri",
        ):
            ros.start(**{"inputs.speed.type": "nav_msgs/msg/Odometri"})
