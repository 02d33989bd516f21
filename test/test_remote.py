# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak watch`, `record` and `params` against a squeak_predictor, launch-free: the
node in this test process on its own Context and executor (`ros` fixture), spun on a
background thread while the command runs in-process on a Context of its own, on the same
ROS_DOMAIN_ID, as a user's terminal would beside a running node."""

from __future__ import annotations

import io
import os
import signal
import time
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from rcl_interfaces.msg import ParameterType

from harness.processes import CLI, domain, output, start, stop, wait_initialised
from harness.ros import Spinner, unique_ns
from harness.squeak import SQUEAK, SqueakWorld, at
from leadscrew_ros.cli import main as cli
from leadscrew_ros.live.status import Level
from leadscrew_ros.ros.parameters import PARAMETERS
from leadscrew_ros.ros.remote import format_value, normalise_namespace, parse_value
from leadscrew_ros.ros.watch import CLEAR, LABEL_WIDTH, ROWS, run_watch

REPO = Path(__file__).resolve().parents[1]
WAIT_S = 60.0  # generous: discovery took up to 3 s with the machine's load at 6 on 2 cores
# A verdict that stays as it is while the commands run (no STALE after the default 1 s)
STEADY = {"stale_timeout_s": 3600.0}


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = cli(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def until(condition, what: str, timeout: float = WAIT_S):
    """Poll `condition()` (no spinning: the node's executor runs on its thread) until it
    returns something true; that value."""
    deadline = time.monotonic() + timeout
    while not (value := condition()):
        assert time.monotonic() < deadline, f"timeout after {timeout} s waiting for {what}"
        time.sleep(0.05)
    return value


@pytest.fixture
def live(ros):
    """Start the predictor with `live(**params)`, at the squeaking point; from then on its
    executor spins on a background thread (until the test ends)."""
    spinners = []

    def start_node(**params):
        ros.start(**{**STEADY, **params})
        at(ros, SQUEAK)
        ros.spinner = Spinner(ros.executor)
        spinners.append(ros.spinner)
        return ros

    yield start_node
    for spinner in spinners:
        spinner.stop()


def status_line(status) -> str:
    """A diagnostic status as the view shows it."""
    task = status.name.split(": ", 1)[1]
    return f"{Level(status.level[0]).name:<5} {task}: {status.message}"


# ----------------------------------------------------------------------------- watch
def test_watch_once_shows_the_nodes_inputs_outputs_and_statuses(live, capsys):
    ros = live()
    code, out, err = run(capsys, "watch", "--namespace", ros.ns, "--once", "--timeout", "60")
    print(out, err)
    assert code == 0, err
    assert "\x1b" not in out  # not a terminal: plain text
    node = ros.node
    p, live_predictor = node.live.prediction, node.live
    assert p.squeak_modes, "the test point squeaks"
    assert (
        f"squeak_node {ros.ns}/squeak_predictor (ROS_DOMAIN_ID {os.environ['ROS_DOMAIN_ID']}" in out
    )
    assert f"speed {SQUEAK:g} rad/s, load {live_predictor.inputs.load_n:g} N" in out
    assert f"P(squeak)   {p.probability:.3f}   active: yes" in out
    assert (
        "unstable    " + ", ".join(f"{m.label} {m.frequency_hz:.1f} Hz" for m in p.squeak_modes)
        in out
    )
    assert f"safe speed  {live_predictor.safe_speed_rad_s:.2f} rad/s" in out
    statuses = ros.latest["/diagnostics"].status  # what the node published last
    assert len(statuses) == 2
    for status in statuses:
        assert status_line(status) in out
    assert "recording   off" in out
    assert "listening   off (listen.enabled is false)" in out


def test_watch_once_shows_what_a_listening_node_hears(live, capsys):
    ros = live(**{"listen.enabled": True})
    code, out, err = run(capsys, "watch", "--namespace", ros.ns, "--once", "--timeout", "60")
    assert code == 0, err
    statuses = ros.latest["/diagnostics"].status
    [measurement] = [s for s in statuses if s.name.endswith(": measurement")]
    assert status_line(measurement) in out
    assert f"listening   no squeak heard; {measurement.message}" in out


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("tty", [True, False], ids=["terminal", "pipe"])
def test_watch_redraws_in_place_on_a_terminal_and_appends_otherwise(live, tty):
    ros = live()
    out = Terminal() if tty else io.StringIO()
    assert run_watch(ros.ns, timeout_s=10.0, out=out) == 0
    text = out.getvalue()
    views = text.split(CLEAR)[1:] if tty else text.split("\n\n")
    assert views, text
    assert (CLEAR in text) == tty
    head = f"squeak_node {ros.ns}/squeak_predictor"
    probability = f"P(squeak)   {ros.node.live.prediction.probability:.3f}"
    for view in views:  # every view whole: the header first, the prediction in it
        assert view.startswith(head) and probability in view, view
    if not tty:  # appended only when it changed
        bodies = [view.split("\n", 1)[1] for view in views]
        assert all(a != b for a, b in zip(bodies, bodies[1:], strict=False)), text


def test_watch_marks_a_node_that_went_away_and_keeps_its_last_outputs(tmp_path):
    """`watch` in a process of its own on this test's domain, its output a file (plain views
    appended); the node in a world of its own, closed as a node process ends: its participant
    leaves the graph (destroying the node alone, its context still up, did not show there)."""
    world, proc, spinner, closed = SqueakWorld(), None, None, False
    try:
        world.start(**STEADY)
        at(world, SQUEAK)
        probability = f"P(squeak)   {world.node.live.prediction.probability:.3f}"
        spinner = Spinner(world.executor)
        argv = CLI + ["watch", "--namespace", world.ns]
        proc = start(argv, int(os.environ["ROS_DOMAIN_ID"]), tmp_path, "watch")
        until(lambda: probability in output(proc)[0], "the first view", 120.0)
        spinner.stop()
        world.close()
        closed = True
        until(lambda: "   NOT FOUND since " in output(proc)[0], "the node marked gone")
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=30)
        out, err = output(proc)
    finally:
        if spinner is not None:
            spinner.stop()
        if not closed:
            world.close()
        stop(proc)
    last = out.split("\n\n")[-1]
    assert "NOT FOUND since" in last.splitlines()[0] and probability in last, last
    assert code == 130 and err.splitlines()[-1] == "leadscrew-squeak: interrupted", (code, err)


def test_watch_says_when_no_node_is_found_and_how_to_start_one(capsys):
    ns = unique_ns()
    code, out, err = run(capsys, "watch", "--namespace", ns, "--once")
    assert code == 2 and out == ""
    last = err.splitlines()[-1]
    assert last.startswith(
        f"leadscrew-squeak: error: no squeak_node found in namespace {ns} "
        f"(ROS_DOMAIN_ID {os.environ['ROS_DOMAIN_ID']}); start one with: "
        f"squeak_node --ros-args -r __ns:={ns}"
    ), err
    # said after the discovery wait, before giving up
    assert err.splitlines()[0].endswith("still looking (up to 5 s)"), err


def test_watch_waits_for_a_node_until_ctrl_c_then_exits_130_with_one_line(tmp_path):
    proc = None
    try:
        proc = start(CLI + ["watch", "--namespace", unique_ns()], domain(3), tmp_path, "watch")
        wait_initialised([proc])
        until(lambda: "still looking" in output(proc)[1], "the no-node line", 120.0)
        assert proc.poll() is None, output(proc)  # keeps waiting
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=30)
        out, err = output(proc)
    finally:
        stop(proc)
    assert code == 130, (code, out, err)
    assert "Traceback" not in err
    assert err.splitlines()[-1] == "leadscrew-squeak: interrupted"


# ----------------------------------------------------------------------------- record
def test_record_on_status_off(live, capsys, tmp_path):
    ros = live(**{"record.directory": str(tmp_path)})
    code, out, err = run(capsys, "record", "on", "--namespace", ros.ns)
    assert code == 0, err
    target = f"{ros.ns}/squeak_predictor recording"
    assert out.startswith(f"{target} on: ") and len(out.splitlines()) == 1, out
    file = Path(out.removeprefix(f"{target} on: ").strip())
    assert file.parent.parent == tmp_path and file.suffix == ".mcap"

    def status() -> tuple[str, int]:
        code, out, err = run(capsys, "record", "status", "--namespace", ros.ns)
        assert code == 0, err
        return out.strip(), int(out.rsplit("(", 1)[1].split()[0]) if " on: " in out else -1

    # the latched status says 'on' within a housekeeping period of the service call
    line, messages = until(lambda: (s := status())[0].startswith(f"{target} on:") and s, "on")
    assert line.startswith(f"{target} on: {file} (")
    assert file.exists()
    size = file.stat().st_size
    # the node records its own /diagnostics every second and flushes every 0.5 s
    until(lambda: file.stat().st_size > size, f"{file} to grow")
    until(lambda: status()[1] > messages, "more messages in the status")

    code, out, err = run(capsys, "record", "off", "--namespace", ros.ns)
    assert code == 0, err
    assert out == f"{target} off (stopped; last bag: {file.parent})\n"
    until(lambda: status()[0] == f"{target} off (last bag: {file.parent})", "off")
    assert not ros.node.recorder.active


def test_record_without_a_node_is_one_line_and_exit_2(capsys):
    ns = unique_ns()
    for action in ("on", "status"):
        code, out, err = run(capsys, "record", action, "--namespace", ns)
        assert code == 2 and out == ""
        assert len(err.splitlines()) == 1
        assert err.startswith(f"leadscrew-squeak: error: no squeak_node found in namespace {ns}")


# ----------------------------------------------------------------------------- params
def test_params_lists_every_parameter_with_value_unit_and_range(live, capsys):
    ros = live()
    code, out, err = run(capsys, "params", "--namespace", ros.ns)
    assert code == 0, err
    lines = {line.split(" = ", 1)[0]: line for line in out.splitlines()}
    # ours and rclpy's own (use_sim_time, ...)
    assert set(lines) == set(ros.node.list_parameters([], 0).names) > {s.name for s in PARAMETERS}
    for spec in PARAMETERS:
        line, md = lines[spec.name], spec.md
        value = ros.node.get_parameter(spec.name).value
        assert line.startswith(f"{spec.name} = {format_value(value)}"), line
        assert (f" [{md['unit']}] " in line) == bool(md["unit"]), line
        assert ("read-only" in line) == md["read_only"], line
        if md["lo"] is not None and not (md["lo_open"] or md["hi_open"]):
            assert f"({format_value(md['lo'])}..{format_value(md['hi'])}" in line, line
        assert line.endswith(f": {md['description']}"), line

    code, out, err = run(capsys, "params", "get", "mu_kinetic", "--namespace", ros.ns)
    assert code == 0, err
    assert out == lines["mu_kinetic"] + "\n"


def test_params_set_changes_the_node_or_says_why_not(live, capsys):
    ros = live()
    node = ros.node

    def params(*argv: str) -> tuple[int, str, str]:
        return run(capsys, "params", *argv, "--namespace", ros.ns)

    old = node.get_parameter("mu_kinetic").value
    code, out, err = params("set", "mu_kinetic", "0.25")
    assert code == 0, err
    assert out == f"mu_kinetic = 0.25 (was {format_value(old)})\n"
    assert node.get_parameter("mu_kinetic").value == 0.25
    # an integer for a double parameter is taken as the double (ROS refuses an int there)
    code, out, err = params("set", "max_rate_hz", "5")
    assert code == 0 and node.get_parameter("max_rate_hz").value == 5.0, err

    refused = [
        # outside the descriptor's range: rclpy's reason
        (("modal_damping", "5"), "out of range"),
        # the node's own check of the set as a whole
        (("nut_position_m", "0.5"), "z_o + b <= L"),
        (("hardware_id", "x"), "read-only"),
    ]
    for (name, value), reason in refused:
        before = node.get_parameter(name).value
        code, out, err = params("set", name, value)
        assert code == 2 and out == "" and len(err.splitlines()) == 1, (code, out, err)
        assert err.startswith(
            f"leadscrew-squeak: error: {ros.ns}/squeak_predictor refused {name} = {value}: "
        ), err
        assert reason in err, err
        assert node.get_parameter(name).value == before

    code, out, err = params("set", "record.enabled", "maybe")
    assert (code, out) == (2, "")
    assert err == "leadscrew-squeak: error: record.enabled: 'maybe' is not a bool (true or false)\n"
    for argv in (("get", "mu_kinetc"), ("set", "mu_kinetc", "0.2")):
        code, out, err = params(*argv)
        assert (code, out) == (2, ""), err
        assert err == (
            f"leadscrew-squeak: error: {ros.ns}/squeak_predictor has no parameter 'mu_kinetc' "
            "(did you mean mu_kinetic, scatter.mu_kinetic?)\n"
        )
    code, out, err = params("set", "mu_kinetic")
    assert code == 2 and "usage: params set NAME VALUE" in err


# ----------------------------------------------------------------------------- values
TYPES = [
    ParameterType.PARAMETER_BOOL,
    ParameterType.PARAMETER_INTEGER,
    ParameterType.PARAMETER_DOUBLE,
    ParameterType.PARAMETER_STRING,
]


@given(st.text(max_size=20), st.sampled_from(TYPES))
def test_a_value_is_parsed_to_its_type_or_refused_in_one_line(text, parameter_type):
    try:
        value = parse_value(text, parameter_type)
    except ValueError as exc:
        assert len(str(exc).splitlines()) == 1 and repr(text) in str(exc)
        return
    expected = {
        ParameterType.PARAMETER_BOOL: bool,
        ParameterType.PARAMETER_INTEGER: int,
        ParameterType.PARAMETER_DOUBLE: float,
        ParameterType.PARAMETER_STRING: str,
    }[parameter_type]
    assert type(value) is expected
    if expected is float:
        assert value == float(text) or value != value  # nan
    if expected is int:
        assert value == int(text)


@given(st.text(max_size=30))
def test_a_namespace_is_normalised_or_refused_in_one_line(text):
    try:
        ns = normalise_namespace(text)
    except ValueError as exc:
        assert len(str(exc).splitlines()) == 1
        return
    assert ns.startswith("/") and (ns == "/" or not ns.endswith("/"))


# ----------------------------------------------------------------------------- the page
def test_the_watch_page_holds_a_capture_of_the_current_view():
    """doc/user/watch.md's capture (tools/watch_capture.py) shows the view as `view_lines`
    writes it now: every row, in order, in the node the page starts."""
    page = (REPO / "doc" / "user" / "watch.md").read_text(encoding="utf-8")
    block = page.split("% watch_capture: begin\n", 1)[1].split("% watch_capture: end\n", 1)[0]
    commands = block.split("\n$ leadscrew-squeak ")
    [watch] = [c for c in commands if c.startswith("watch ")]
    lines = watch.splitlines()[1:]
    assert lines[0].startswith("squeak_node /seat_left/squeak_predictor (ROS_DOMAIN_ID ")
    labels = [line[:LABEL_WIDTH].strip() for line in lines[1:] if line.strip()]
    assert [label for label in labels if label] == list(ROWS), watch
    for name in ("record on", "record status", "params get", "params set", "record off"):
        assert any(c.startswith(name) for c in commands), name
