# SPDX-License-Identifier: Apache-2.0
"""Several seats side by side: the shipped parameter file applies in any namespace (through
rcl's own `--params-file` handling), nodes in /seat_left and /seat_right publish distinct
diagnostic status names and record distinct bags, and `squeak_node --help` prints usage."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import yaml
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.parameter import Parameter

from harness.processes import node_command
from harness.ros import COLLECT, RosWorld
from leadscrew_ros.ros.node import NODE_NAME, PROG, SqueakPredictorNode
from leadscrew_ros.ros.parameters import PARAMETER_NAMES

CONFIG = Path(__file__).resolve().parents[1] / "config" / "leadscrew.yaml"


def node_with_ros_args(args: list[str]) -> dict:
    """SqueakPredictorNode on a context initialised with `args` (as from the command line):
    its namespace and parameter values."""
    with RosWorld(args=["squeak_node", "--ros-args", *args]) as world:
        node = world.add(SqueakPredictorNode(context=world.ctx))
        return {
            "namespace": node.get_namespace(),
            **{p.name: p.value for p in node.get_parameters(PARAMETER_NAMES)},
            "radius_m": node.get_parameter("radius_m").value,
        }


def test_the_shipped_file_applies_to_a_namespaced_node(tmp_path):
    """The shipped file keyed `/**:` reaches a node in /seat_left: a copy with non-default
    values changes them; the same values keyed `squeak_predictor:` (the old file) do not."""
    changed = {
        "max_rate_hz": 50.0,
        "hardware_id": "seat_left_screw",
        "radius_m": 0.006,
        "record": {"split_duration_s": 30.0},
    }
    doc = yaml.safe_load(CONFIG.read_text())
    [key] = doc
    assert key == "/**"
    params = doc[key]["ros__parameters"]
    params.update({k: v for k, v in changed.items() if k != "record"})
    params["record"].update(changed["record"])
    copy = tmp_path / "seat.yaml"
    copy.write_text(yaml.safe_dump(doc))
    ns = ["-r", "__ns:=/seat_left"]
    values = node_with_ros_args([*ns, "--params-file", str(copy)])
    assert values["namespace"] == "/seat_left"
    assert values["max_rate_hz"] == 50.0 and values["hardware_id"] == "seat_left_screw"
    assert values["radius_m"] == 0.006 and values["record.split_duration_s"] == 30.0
    shipped = node_with_ros_args([*ns, "--params-file", str(CONFIG)])
    assert shipped["hardware_id"] == "leadscrew" and shipped["max_rate_hz"] == 100.0
    old = tmp_path / "old.yaml"
    old.write_text(yaml.safe_dump({NODE_NAME: doc[key]}))
    assert node_with_ros_args([*ns, "--params-file", str(old)])["max_rate_hz"] == 100.0


def test_two_seats_have_distinct_status_names_and_bags(tmp_path, ros_world):
    names = set()
    probe = ros_world.make_node("probe", namespace="/")
    probe.create_subscription(
        DiagnosticArray, "/diagnostics", lambda m: names.update(s.name for s in m.status), COLLECT
    )
    nodes = [
        ros_world.add(
            SqueakPredictorNode(
                context=ros_world.ctx,
                namespace=seat,
                parameter_overrides=[
                    Parameter("record.enabled", value=True),
                    Parameter("record.directory", value=str(tmp_path)),
                ],
            )
        )
        for seat in ("/seat_left", "/seat_right")
    ]
    want = {
        f"/seat_{side}/{NODE_NAME}: {what}"
        for side in ("left", "right")
        for what in ("squeak prediction", "recording")
    }
    ros_world.spin_until(lambda: want <= names, 20.0, "the status names of both seats")
    left, right = (n.recorder.bag for n in nodes)
    assert (
        left.name.startswith("seat_left_squeak_")
        and right.name.startswith("seat_right_squeak_")
        and left.parent == right.parent == tmp_path
    )
    for node in nodes:  # each bag finished before it is checked
        ros_world.remove(node)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([left.name, right.name])
    for bag in (left, right):
        assert (bag / "metadata.yaml").is_file()


def test_help_prints_usage_and_exits_without_starting_a_node():
    for flag in ("--help", "-h"):
        proc = subprocess.run(
            [*node_command(), flag],
            capture_output=True,
            text=True,
            timeout=60,
            env=dict(os.environ),
        )
        assert proc.returncode == 0, proc.stderr
        out = proc.stdout
        assert out.startswith("usage: squeak_node") and "--ros-args" in out
        for text in (
            "motor_speed",
            "axial_load",
            "nut_position",
            "joint_states",
            "squeak/risk (Float64) [1]: P(squeak)",
            "squeak/margin",
            "squeak/safe_speed",
            "/diagnostics",
            "~/record",
            "radius_m [m] = 0.005",
            "max_rate_hz [Hz] = 100, 0.1..10000",
            "scatter.mu_kinetic [1] = 0.05, 0..1",
            "scatter.samples [1] = 1024",
            "record.directory = '.'",
            "record.auto_recover = False",
            "--params-file config/leadscrew.yaml",
        ):
            assert text in out, text
        assert not proc.stderr
    proc = subprocess.run(
        [*node_command(), "--bogus"],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ),
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        f"{PROG}: error: unrecognized arguments: --bogus (ROS "
        "arguments go after --ros-args; see --help)"
    )
