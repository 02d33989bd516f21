# SPDX-License-Identifier: Apache-2.0
"""squeak_predictor as a managed (lifecycle) node, driven through the standard lifecycle
services (lifecycle_msgs ChangeState and GetState on `<node>/change_state`, `<node>/get_state`)
from a client node, as a lifecycle manager drives it: every transition, what each state
publishes and records, a configure that fails on a bad parameter, `squeak_node
--no-autostart`, and the guard's topics in the recording. Launch-free (harness.squeak's
in-process node, one process for the executable)."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
import uuid
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from lifecycle_msgs.msg import Transition
from mcap.reader import make_reader
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from std_msgs.msg import Bool, Float64, String

from harness.processes import node_command, output, stop, wait_initialised
from harness.ros import COLLECT, LifecycleClient
from harness.squeak import LOAD, SQUEAK, STABLE, SqueakWorld, at
from leadscrew_ros.bag import messages, msgdefs
from leadscrew_ros.bag.logfile import is_complete, log_files, read_log
from leadscrew_ros.live.status import INACTIVE, KEY_LIFECYCLE_STATE
from leadscrew_ros.model import ParameterError, ScrewParameters
from leadscrew_ros.ros.node import GUARD_CLASSES, NODE_NAME, usage

ABSENCE_S = 1.0  # how long nothing must come out after inputs a node must not take


def lifecycle(ros: SqueakWorld) -> LifecycleClient:
    return LifecycleClient(ros, ros.probe, f"{ros.ns}/{NODE_NAME}")


def recording_params(directory: Path) -> dict:
    return {
        "record.enabled": True,
        "record.directory": str(directory),
        "record.flush_period_s": 0.05,
    }


def outputs_published(ros: SqueakWorld) -> int:
    """Messages received on the prediction topics so far (not /diagnostics)."""
    return sum(n for topic, n in ros.count.items() if topic != "/diagnostics")


def inputs_not_taken(ros: SqueakWorld, node, speed: float) -> None:
    """Send an operating point while the node is not active; once an echo subscriber of this
    test has it (so the node's subscription had it too), nothing may come of it."""
    echo: list[float] = []
    sub = ros.probe.create_subscription(Float64, "motor_speed", lambda m: echo.append(m.data), 10)
    published = outputs_published(ros)
    taken = node.live.inputs.speed_rad_s
    ros.send("axial_load", LOAD)
    ros.send("motor_speed", speed)
    ros.spin_until(lambda: speed in echo, what="the test's own echo of motor_speed")
    ros.spin_for(ABSENCE_S)
    ros.probe.destroy_subscription(sub)
    assert outputs_published(ros) == published
    assert node.live.inputs.speed_rad_s == taken


def inactive_status(ros: SqueakWorld) -> DiagnosticStatus:
    return ros.status(lambda s: s.level == DiagnosticStatus.STALE and s.message == INACTIVE)


def complete_bag(bag: Path) -> int:
    """Check the bag's one file is finished (summary, index, footer) and that rosbags and the
    mcap reader take it; its message count."""
    [path] = log_files(bag)
    assert is_complete(path)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.chunk_indexes
    with RosbagsReader(bag) as reader:
        assert reader.message_count == summary.statistics.message_count > 0
    return summary.statistics.message_count


def entities(node) -> dict[str, set[int]]:
    """The node's rclpy entities by kind (ids of the Python objects)."""
    return {
        kind: {id(e) for e in getattr(node, kind)}
        for kind in ("subscriptions", "publishers", "timers", "services", "clients")
    }


def test_every_transition_through_the_lifecycle_services(ros, tmp_path):
    node = ros.start(False, **recording_params(tmp_path), **{"listen.enabled": True})
    unconfigured = entities(node)
    lc = lifecycle(ros)
    assert lc.state() == "unconfigured"
    risk = f"{ros.ns}/{messages.RISK}"
    assert ros.probe.count_publishers(risk) == 0

    # configure: the outputs exist, silent; /diagnostics says inactive; inputs not taken
    assert lc.change(Transition.TRANSITION_CONFIGURE)
    assert lc.state() == "inactive"
    ros.spin_until(lambda: ros.probe.count_publishers(risk) == 1, what="squeak/risk publisher")
    status = inactive_status(ros)
    assert {kv.key: kv.value for kv in status.values}[KEY_LIFECYCLE_STATE] == "inactive"
    inputs_not_taken(ros, node, SQUEAK)
    assert node.recorder.bag is None  # nothing recorded while inactive

    # activate: predictions for inputs, recording
    assert lc.change(Transition.TRANSITION_ACTIVATE)
    assert lc.state() == "active"
    at(ros, SQUEAK)
    assert node.recorder.active
    first_bag = node.recorder.bag
    ros.spin_until(lambda: node.recorder.count(risk) > 0, what="squeak/risk recorded")

    # deactivate: publishing stops, the file is finished
    assert lc.change(Transition.TRANSITION_DEACTIVATE)
    assert lc.state() == "inactive"
    assert not node.recorder.active
    recorded = complete_bag(first_bag)
    inactive_status(ros)
    inputs_not_taken(ros, node, STABLE)
    assert complete_bag(first_bag) == recorded

    # activate again: a new recording; the node takes inputs again
    assert lc.change(Transition.TRANSITION_ACTIVATE)
    at(ros, STABLE)
    assert node.recorder.active and node.recorder.bag != first_bag
    second_bag = node.recorder.bag

    # deactivate and clean up: everything configure made is gone
    assert lc.change(Transition.TRANSITION_DEACTIVATE)
    assert lc.change(Transition.TRANSITION_CLEANUP)
    assert lc.state() == "unconfigured"
    assert entities(node) == unconfigured
    ros.spin_until(lambda: ros.probe.count_publishers(risk) == 0, what="no squeak/risk publisher")
    complete_bag(second_bag)

    # configure again, with a parameter changed while unconfigured
    [result] = node.set_parameters([Parameter("warn_probability", value=0.2)])
    assert result.successful, result.reason
    assert lc.change(Transition.TRANSITION_CONFIGURE)
    assert node.live.settings.warn_probability == 0.2
    assert lc.change(Transition.TRANSITION_ACTIVATE)
    at(ros, SQUEAK)
    third_bag = node.recorder.bag
    assert third_bag not in (first_bag, second_bag)

    # shutdown from active: finalized, the recording finished, the outputs gone
    assert lc.change("shutdown")
    assert lc.state() == "finalized"
    assert entities(node) == unconfigured
    complete_bag(third_bag)
    ros.spin_until(lambda: ros.probe.count_publishers(risk) == 0, what="no squeak/risk publisher")


@pytest.mark.parametrize("transition", ["shutdown", Transition.TRANSITION_CONFIGURE])
def test_shutdown_from_unconfigured_and_inactive(ros, transition):
    node = ros.start(False)
    unconfigured = entities(node)
    lc = lifecycle(ros)
    if transition != "shutdown":
        assert lc.change(transition)
        assert entities(node) != unconfigured
    assert lc.change("shutdown")
    assert lc.state() == "finalized"
    assert entities(node) == unconfigured


def test_a_timer_expiry_taken_before_shutdown_does_nothing_after_it(ros, tmp_path):
    """The executor may take a timer's expiry in the same wait as the shutdown request and
    run it after the transition destroyed the publishers (seen under load: the housekeeping
    published /diagnostics on a destroyed publisher, and the timer callback raised). The
    callbacks taken before, run after the shutdown, do nothing and raise nothing."""
    from rclpy.timer import Timer

    node = ros.start(False, **recording_params(tmp_path))
    lc = lifecycle(ros)
    assert lc.change("configure") and lc.change("activate")
    at(ros, SQUEAK)
    taken = [e.callback for e in node._owned if isinstance(e, Timer)]
    assert len(taken) == 2  # the housekeeping and the rate limit
    assert lc.change("shutdown")
    for callback in taken:
        callback()


@pytest.mark.parametrize("state", ["unconfigured", "inactive", "active", "finalized"])
def test_destroy_node_from_any_state_leaves_a_complete_recording(ros, tmp_path, state):
    node = ros.start(False, **recording_params(tmp_path))
    steps = {
        "unconfigured": [],
        "inactive": ["configure"],
        "active": ["configure", "activate"],
        "finalized": ["configure", "activate", "shutdown"],
    }[state]
    lc = lifecycle(ros)
    for step in steps:
        assert lc.change(step)
    if "activate" in steps and state == "active":
        at(ros, SQUEAK)
    ros.remove(node)
    bags = list(tmp_path.iterdir())
    assert len(bags) == ("activate" in steps)
    for bag in bags:
        complete_bag(bag)


def test_a_bad_parameter_fails_configure_with_one_line_and_the_node_stays_unconfigured(ros, capfd):
    node = ros.start(False, nut_position_m=0.25)  # z_o + b > L: only the model says so
    lc = lifecycle(ros)
    capfd.readouterr()
    assert not lc.change(Transition.TRANSITION_CONFIGURE)
    assert lc.state() == "unconfigured"
    lines = [line for line in capfd.readouterr().err.splitlines() if "configure failed" in line]
    assert len(lines) == 1, lines
    assert "z_o + b <= L" in lines[0] and "the node stays unconfigured" in lines[0]
    assert isinstance(node.failure, ParameterError)
    assert ros.probe.count_publishers(f"{ros.ns}/{messages.RISK}") == 0
    # a good value (the default), then the same node configures and runs
    nut = ScrewParameters().nut_position_m
    [result] = node.set_parameters([Parameter("nut_position_m", value=nut)])
    assert result.successful, result.reason
    assert lc.change(Transition.TRANSITION_CONFIGURE)
    assert lc.change(Transition.TRANSITION_ACTIVATE)
    at(ros, SQUEAK)


def test_with_autostart_a_bad_parameter_raises_as_an_unmanaged_node_did(ros):
    with pytest.raises(ParameterError, match=r"z_o \+ b <= L"):
        ros.start(nut_position_m=0.25)


def test_a_start_asked_of_the_record_service_while_inactive_waits_for_activation(ros, tmp_path):
    from std_srvs.srv import SetBool

    node = ros.start(False, **{"record.directory": str(tmp_path)})
    lc = lifecycle(ros)
    assert lc.change("configure")
    client = ros.probe.create_client(SetBool, f"{ros.ns}/{NODE_NAME}/record")
    ros.spin_until(client.service_is_ready, 10.0, "the ~/record service")
    future = client.call_async(SetBool.Request(data=True))
    ros.spin_until(future.done, 10.0, "the ~/record answer")
    answer = future.result()
    assert not answer.success and "inactive" in answer.message
    assert node.get_parameter("record.enabled").value and not node.recorder.active
    assert lc.change("activate")
    assert node.recorder.active


def test_guard_topics_published_in_the_namespace_are_recorded_as_sent(ros, tmp_path):
    node = ros.start(**recording_params(tmp_path))
    at(ros, SQUEAK)
    sent = {
        messages.SPEED_COMMAND: [Float64(data=v) for v in (10.0, 20.0, -5.5)],
        messages.SPEED_COMMAND_GUARDED: [Float64(data=v) for v in (10.0, 12.5, -5.5)],
        messages.GUARD_ACTIVE: [Bool(data=v) for v in (False, True, False)],
        messages.GUARD_REASON: [String(data=v) for v in ("", "band 11-55 rad/s: held", "")],
    }
    for topic, msgs in sent.items():
        pub = ros.probe.create_publisher(GUARD_CLASSES[topic], topic, COLLECT)
        ros.wait_matched(pub)  # the recording's own subscription
        for msg in msgs:
            pub.publish(msg)
    full = {topic: f"{ros.ns}/{topic}" for topic in sent}
    ros.spin_until(
        lambda: all(node.recorder.count(full[t]) == len(m) for t, m in sent.items()),
        what="every guard message recorded",
    )
    assert node.live.inputs.speed_rad_s == SQUEAK  # recorded, never taken as an input
    [result] = node.set_parameters([Parameter("record.enabled", value=False)])
    assert result.successful
    bag = node.recorder.bag
    complete_bag(bag)
    [path] = log_files(bag)
    for topic, msgs in sent.items():
        cls = GUARD_CLASSES[topic]
        got = [deserialize_message(m.data, cls) for m in read_log(path, {full[topic]})]
        assert got == msgs, topic
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    schemas = {
        summary.channels[c].topic: summary.schemas[summary.channels[c].schema_id]
        for c in summary.channels
    }
    for topic, type_name in messages.GUARD_TYPES.items():
        schema = schemas[full[topic]]
        assert schema.name == type_name and schema.encoding == "ros2msg"
        assert schema.data.decode() == msgdefs.definition(type_name)
    with RosbagsReader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert {full[t]: counts[full[t]] for t in sent} == {full[t]: 3 for t in sent}


def test_help_names_the_lifecycle_options_and_the_guard_topics():
    text = usage()
    assert "--no-autostart" in text and "--autostart" in text
    for topic in messages.GUARD_TYPES:
        assert topic in text


def test_squeak_node_no_autostart_starts_unconfigured_and_runs_once_activated(
    tmp_path, make_ros_world
):
    ns = f"/t{uuid.uuid4().hex}"
    err = open(tmp_path / "node.stderr", "w+")
    proc = subprocess.Popen(
        [*node_command(), "--no-autostart", "--ros-args", "-r", f"__ns:={ns}"],
        stdout=subprocess.DEVNULL,
        stderr=err,
        env=dict(os.environ),
    )
    proc.files = [err, err]
    try:
        wait_initialised([proc])
        ros = make_ros_world(ns=ns, executor="events")
        probe = ros.make_node("probe")
        risk: list[float] = []
        probe.create_subscription(Float64, messages.RISK, lambda m: risk.append(m.data), COLLECT)
        lc = LifecycleClient(ros, probe, f"{ns}/{NODE_NAME}")
        assert lc.state() == "unconfigured"
        assert probe.count_publishers(f"{ns}/{messages.RISK}") == 0
        assert lc.change("configure") and lc.change("activate")
        pubs = [probe.create_publisher(Float64, t, 10) for t in ("motor_speed", "axial_load")]
        for pub in pubs:
            ros.wait_matched(pub)

        def answered() -> bool:
            """Send an operating point; True once the node answered one (it may not yet have
            matched our writers when ours have matched its readers)."""
            for pub, value in zip(pubs, (SQUEAK, LOAD), strict=True):
                pub.publish(Float64(data=value))
            return bool(risk)

        ros.spin_until(answered, 30.0, "squeak/risk from the activated node process")
        assert risk[-1] > 0.99
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
        stderr = output(proc)[1]
        assert "Traceback" not in stderr
        assert stderr.splitlines()[-1] == f"{NODE_NAME}: stopped by SIGTERM"
    finally:
        stop(proc, grace_s=5.0)


def test_autostart_options_are_taken_out_and_the_last_wins():
    from leadscrew_ros.ros.managed import autostart_option

    assert autostart_option([]) == (True, [])
    assert autostart_option(["--no-autostart"]) == (False, [])
    assert autostart_option(["--no-autostart", "-x", "--autostart"]) == (True, ["-x"])


def test_the_threads_of_a_configured_node_end_on_cleanup(ros, tmp_path):
    """Every thread a configured node starts (listening, input recording, safe-speed search)
    ends on cleanup."""
    before = set(threading.enumerate())
    node = ros.start(False, **{"listen.enabled": True}, **recording_params(tmp_path))
    lc = lifecycle(ros)
    assert lc.change("configure") and lc.change("activate")
    at(ros, SQUEAK)
    assert set(threading.enumerate()) - before  # listening, input recording
    assert lc.change("deactivate") and lc.change("cleanup")
    ros.spin_until(
        lambda: not {t for t in set(threading.enumerate()) - before if t.is_alive()},
        what="the node's threads ending",
    )
    assert node.failure is None


def test_the_node_leaves_the_graph_when_its_context_shuts_down(make_ros_world):
    """rclpy's lifecycle state machine holds the node's handle: unless destroyed with the node,
    the node stayed in the graph of other processes (`watch` never saw it go)."""
    world = SqueakWorld()
    try:
        world.start(False)
        observer = make_ros_world().make_node("observer")

        def present() -> bool:
            return (NODE_NAME, world.ns) in observer.get_node_names_and_namespaces()

        world.spin_until(present, what="the node in the graph")
    finally:
        world.close()
    deadline = time.monotonic() + 30.0
    while present():
        assert time.monotonic() < deadline, "the node is still in the graph"
        time.sleep(0.05)
