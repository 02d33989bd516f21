# SPDX-License-Identifier: Apache-2.0
"""The demo (`leadscrew-squeak demo`) and the simulator driving a separately started node, as
subprocesses with the venv's python and the parent's environment (loopback discovery), each on a
ROS_DOMAIN_ID of its own (201..230: clear of conftest's per-process domains 1..200)."""

import json
import re
import signal
import sys
import time
from pathlib import Path

import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64

from harness.processes import CLI, domain, output, start, stop
from leadscrew_ros.bag.cdr import encode_diagnostic_array
from leadscrew_ros.bag.logfile import inspect, log_files, read_log
from leadscrew_ros.bag.recorder import LOST_BY_TOPIC_KEY
from leadscrew_ros.live.recompute import LivePredictor
from leadscrew_ros.live.status import KEY_VALIDITY, Level
from leadscrew_ros.model import SqueakModel, Validity
from leadscrew_ros.ros.demo import SqueakMonitor, SqueakRecord, status_line
from leadscrew_ros.ros.diagnostics import DiagnosticStatusWrapper, status_task
from leadscrew_ros.ros.node import LATCHED


def summary_values(out: str) -> dict:
    squeak = re.search(r"time in squeak: +([\d.]+) s \(([\d.]+) % of the stroke\)", out)
    freqs = re.search(r"squeak frequencies: (.*)", out)
    speeds = re.search(r"squeak speeds: +([\d.]+) - ([\d.]+) rad/s", out)
    probability = re.search(r"max P\(squeak\): +([\d.]+)", out)
    margin = re.search(r"min margin: +([-+][\d.]+|none) \(least damping ratio", out)
    predictions = re.search(r"predictions: +(\d+)", out)
    assert squeak and freqs and speeds and probability and margin and predictions, out
    return {
        "squeak_s": float(squeak[1]),
        "squeak_pct": float(squeak[2]),
        "frequencies": [
            (m[1], float(m[2])) for m in re.finditer(r"(\w+) ([\d.]+)(?:-[\d.]+)? Hz", freqs[1])
        ],
        "speeds": (float(speeds[1]), float(speeds[2])),
        "max_probability": float(probability[1]),
        "min_margin": None if margin[1] == "none" else float(margin[1]),
        "predictions": int(predictions[1]),
    }


# ----------------------------------------------------------------------------- demo
def test_demo_runs_a_stroke_and_summarises_it(tmp_path):
    proc = None
    try:
        t0 = time.monotonic()
        proc = start(
            CLI + ["demo", "--duration", "3", "--record-dir", str(tmp_path / "rec")],
            domain(0),
            tmp_path,
            "demo",
        )
        code = proc.wait(timeout=60)
        elapsed = time.monotonic() - t0
        out, err = output(proc)
    finally:
        stop(proc)
    assert code == 0, (out, err)
    assert "Traceback" not in out + err and err == "", err
    assert elapsed < 30
    assert f"ROS_DOMAIN_ID={domain(0)}, discovery LOCALHOST" in out
    # Status lines at 4 Hz of wall-clock time (their content depends on timing: only the form
    # is checked; what was predicted is checked on the recording below).
    status = [line for line in out.splitlines() if line.startswith("t ")]
    assert len(status) >= 8 and "\r" not in out  # plain lines: no TTY
    assert all(
        re.fullmatch(
            r"t +\d+\.\d s (.* rad/s .* N nut .* m|\s*waiting for the predictor)"
            r" \| (no prediction.*|(quiet|SQUEAK) at nominal, +P\(squeak\) \d\.\d\d"
            r" (OK|WARN|ERROR|STALE) *( margin ([-+]\d\.\d{4}|none))?( safe .*)?( \| .*)?)",
            line,
        )
        for line in status
    ), status
    assert any(
        re.search(r"\| SQUEAK at nominal, P\(squeak\) 1\.00 \w+ +margin -0\.\d{4}", line)
        for line in status
    ), status
    v = summary_values(out)
    # About 40 % of the stroke squeaks (the model along the profile says the same).
    assert 0.5 < v["squeak_s"] < 2.5 and v["squeak_pct"] > 15
    model = float(re.search(r"the model along the profile: ([\d.]+) s", out)[1])
    assert abs(v["squeak_s"] - model) < 0.5
    assert ("B1y", pytest.approx(224.3, abs=3)) in [(k, f) for k, f in v["frequencies"]]
    # deep in the band P(squeak) is ~1 and the least damping ratio clearly negative
    assert v["max_probability"] >= 0.99 and v["predictions"] > 30
    assert v["min_margin"] < -0.01
    lo, hi = v["speeds"]
    assert 0.5 <= lo < 5 and 30 < hi < 75  # the band, not the 120 rad/s peak
    # ... and the recording it names holds the stroke's inputs and every prediction
    line = re.search(r"recording: +(\S+) \(1 file, \d+ kB, (\d+) messages .* complete\)", out)
    assert line, out
    counts = inspect(log_files(line[1])[0]).counts
    assert sum(counts.values()) == int(line[2])
    # every sample the simulator published (~300: 3 s at 100 Hz, fewer on a busy machine) is
    # recorded or counted lost; in one process nothing is lost
    published = int(re.search(r"simulator: +(\d+) samples published", out)[1])
    assert published > 100
    meta = yaml.safe_load((Path(line[1]) / "metadata.yaml").read_text())
    lost = json.loads(meta["rosbag2_bagfile_information"]["custom_data"][LOST_BY_TOPIC_KEY])
    for topic in ("/motor_speed", "/axial_load", "/nut_position"):
        assert counts[topic] + lost[topic]["lost"] == published, (topic, counts, lost)
        assert lost[topic]["lost"] == 0
    assert counts["/squeak/risk"] == v["predictions"]
    # beyond the band: every P(squeak) published at > 100 rad/s is below 0.5 (P is 0 there)
    at_speed = None
    high = []
    for m in read_log(line[1]):
        data = (
            deserialize_message(m.data, Float64).data
            if m.topic.name in ("/motor_speed", "/squeak/risk")
            else None
        )
        if m.topic.name == "/motor_speed":
            at_speed = data
        elif m.topic.name == "/squeak/risk" and at_speed is not None and at_speed > 100:
            high.append(data)
    assert high and max(high) < 0.5, high


def test_demo_stops_cleanly_on_sigterm(tmp_path):
    proc = None
    try:
        proc = start(
            CLI + ["demo", "--duration", "10", "--record-dir", str(tmp_path / "rec")],
            domain(1),
            tmp_path,
            "demo",
        )
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and proc.poll() is None:
            if re.search(r"^t +\d.*P\(squeak\)", output(proc)[0], re.M):  # predictions flow
                break
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=20)
        out, err = output(proc)
    finally:
        stop(proc)
    assert code == 0, (out, err)  # a requested shutdown is a success
    assert "Traceback" not in out + err
    assert err.strip() == "leadscrew-squeak: stopped by SIGTERM"
    assert "interrupted after" in out
    summary_values(out)  # a summary all the same
    assert re.search(r"recording: .* messages .* complete\)", out), out  # closed cleanly


# ----------------------------------------------------------------------------- simulate + node
class RiskProbe(Node):
    def __init__(self, **kwargs):
        super().__init__("risk_probe", **kwargs)
        self.risks, self.diagnostics = [], 0
        qos = QoSProfile(depth=100, reliability=LATCHED.reliability, durability=LATCHED.durability)
        self.create_subscription(Float64, "squeak/risk", lambda m: self.risks.append(m.data), qos)
        self.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, qos)

    def _on_diagnostics(self, msg):
        self.diagnostics += 1


def test_simulate_drives_a_separately_started_node(tmp_path, make_ros_world):
    """Fast DDS tells a newcomer about an older participant only at the older one's next
    periodic announcement (every ~3 s), so the order matters: the node first, then the probe
    until it receives the node's latched diagnostics (the node will reach the probe from then
    on), then the simulator, which waits for the node's subscription before its stroke."""
    dom = domain(2)
    node = sim = None
    world = make_ros_world(domain_id=dom)
    try:
        probe = world.add(RiskProbe(context=world.ctx))
        node = start([sys.executable, "-m", "leadscrew_ros.ros.node"], dom, tmp_path, "node")
        world.spin_until(
            lambda: probe.diagnostics or node.poll() is not None,
            30,
            "the node's latched diagnostics",
        )
        assert node.poll() is None and probe.risks == [], output(node)
        sim = start(
            CLI + ["simulate", "--duration", "3", "--joint-name", "screw"], dom, tmp_path, "sim"
        )
        world.spin_until(lambda: sim.poll() is not None, 60, "the simulator to finish")
        sim_code = sim.returncode
        world.spin_for(0.5)  # the last predictions
        assert node.poll() is None, output(node)
        node.send_signal(signal.SIGTERM)
        node_code = node.wait(timeout=20)
        node_out, node_err = output(node)
        sim_out, sim_err = output(sim)
    finally:
        stop(node, sim)
    assert sim_code == 0, (sim_out, sim_err)
    assert "waiting for a subscriber on /motor_speed" in sim_out and "stroke done" in sim_out
    assert f"ROS_DOMAIN_ID={dom}" in sim_out and "joint_states" in sim_out
    assert "Traceback" not in sim_err
    assert max(probe.risks) > 0.99, probe.risks  # squeak predicted at some point
    assert min(probe.risks) < 0.5, probe.risks  # and not at the peak
    assert node_code == 0, (node_out, node_err)
    assert "Traceback" not in node_err


@pytest.mark.parametrize(
    "speed, words",
    [(0.1, "speed below min_speed_rad_s"), (5000.0, "speed at or above the first critical")],
)
def test_the_monitor_takes_validity_from_its_key_not_from_the_message(speed, words, ros_world):
    """The status line says why there is no prediction from the validity key of /diagnostics;
    the wording of the status message plays no part."""
    lp = LivePredictor(SqueakModel())
    lp.set_speed(speed, 0.0)
    lp.set_load(200.0, 0.0)
    lp.update(0.0)
    stat = status_task(lambda: lp.status(0.0))(DiagnosticStatusWrapper())
    assert stat.values[KEY_VALIDITY] != Validity.OK.name
    stat.message = "no prediction: reworded"
    monitor = ros_world.add(SqueakMonitor(context=ros_world.ctx))
    monitor._on_diagnostics(
        deserialize_message(encode_diagnostic_array(0, (stat.to_data(),)), DiagnosticArray)
    )
    r = monitor.record
    assert not r.valid and r.validity is Validity[stat.values[KEY_VALIDITY]]
    assert r.validity.label.startswith(words)
    assert status_line(1.0, None, r).endswith(f"| no prediction ({r.validity.label})")


def test_the_status_line_says_what_its_verdict_refers_to():
    """'ok' next to P(squeak) 0.41 read as a contradiction of the WARN level: the verdict is
    the nominal parameters', P(squeak) carries the level the diagnostics gave it."""
    r = SqueakRecord(probability=0.41, margin=0.0012, safe_speed=47.5, valid=True, level=Level.WARN)
    line = status_line(3.0, None, r)
    assert re.search(r"\| quiet at nominal, +P\(squeak\) 0\.41 WARN +margin \+0\.0012 safe", line)
    assert " ok " not in line


def test_demo_with_a_microphone_says_heard_against_predicted(tmp_path):
    proc = None
    try:
        proc = start(
            CLI + ["demo", "--duration", "3", "--microphone", "--no-record"],
            domain(5),
            tmp_path,
            "demo_mic",
        )
        code = proc.wait(timeout=60)
        out, err = output(proc)
    finally:
        stop(proc)
    assert code == 0 and err == "", (out, err)
    heard = re.search(
        r"  heard vs predicted: heard squeak ([\d.]+) s \((.*)\); predicted "
        r"([\d.]+) s; agreement (\d+) % of frames$",
        out,
        re.MULTILINE,
    )
    assert heard, out
    # The tone is where the node's model squeaks, so the two mostly agree (timing: loosely)
    assert float(heard[1]) > 0.3 and float(heard[3]) > 0.3 and int(heard[4]) >= 70
    assert re.search(r"B\dy \d+ Hz", heard[2]), heard[2]


def test_demo_guard_meets_the_target_on_the_demo_stroke(tmp_path):
    """`demo --guard`: the demo stroke without and with the squeak guard node in the loop;
    issue 33's target: <= 0.3 s in squeak for <= 10 % longer stroke time; the picture and the
    CSV in the output directory."""
    from leadscrew_ros.ros.demo import GUARD_CSV, GUARD_PNG

    proc = None
    try:
        proc = start(
            CLI + ["demo", "--guard", "--record-dir", str(tmp_path / "out")],
            domain(7),
            tmp_path,
            "demo_guard",
        )
        code = proc.wait(timeout=400)
        out, err = output(proc)
    finally:
        stop(proc)
    assert code == 0 and err == "", (out, err)
    rows = {
        m[1].strip(): (float(m[2]), float(m[3]))
        for m in re.finditer(r"^  ([a-zA-Z(][^\d]*?) +([\d.]+) +([\d.]+)$", out, re.MULTILINE)
    }
    raw_squeak, guarded_squeak = rows["time in squeak [s]"]
    raw_stroke, guarded_stroke = rows["stroke time [s]"]
    assert raw_squeak > 2.0, out  # the demo stroke squeaks without the guard
    assert guarded_squeak <= 0.3, out
    assert guarded_stroke <= 1.10 * raw_stroke, out
    assert rows["peak P(squeak)"][0] > 0.5, out
    assert (tmp_path / "out" / GUARD_PNG).stat().st_size > 10_000
    assert (tmp_path / "out" / GUARD_CSV).read_text().startswith("time_s,speed_rad_s")
