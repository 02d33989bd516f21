# SPDX-License-Identifier: Apache-2.0
"""Every long-running ROS command (`squeak_node`, `demo`, `simulate`, `replay --publish`) ends
the same way on SIGINT and on SIGTERM (`ros_env.StopSignals.exit_status`): exit status 0 and
the one line `<program>: stopped by SIGINT|SIGTERM` as the last line of stderr, no traceback.
Each runs as a process of its own on this test's private domain over loopback DDS."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from harness.processes import CLI, domain, node_command, output, start, stop, wait_initialised
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.ros.node import NODE_NAME

PROGRAMS = {
    "node": NODE_NAME,
    "demo": "leadscrew-squeak",
    "simulate": "leadscrew-squeak",
    "replay --publish": "leadscrew-squeak",
}


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    return write_log(DutyCycle(duration_s=5.0), tmp_path_factory.mktemp("bag"))


def argv(command: str, bag: Path) -> list[str]:
    return {
        "node": node_command(),
        "demo": CLI + ["demo", "--duration", "10", "--no-record"],
        "simulate": CLI + ["simulate"],  # waits for a subscriber: forever
        "replay --publish": CLI + ["replay", str(bag), "--publish", "--loop", "--no-wait"],
    }[command]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)
@pytest.mark.parametrize("command", list(PROGRAMS))
def test_long_running_commands_stop_with_exit_0_and_one_line(command, sig, bag, tmp_path):
    proc = None
    try:
        proc = start(argv(command, bag), domain(7), tmp_path, "cmd")
        wait_initialised([proc])  # rclpy is up: the handlers are in place
        time.sleep(0.5)  # and it runs (spins, publishes)
        assert proc.poll() is None, output(proc)
        proc.send_signal(sig)
        code = proc.wait(timeout=30)
        out, err = output(proc)
    finally:
        stop(proc)
    print(f"stdout:\n{out}\nstderr:\n{err}")  # shown in full on failure
    assert code == 0, (code, out, err)
    assert "Traceback" not in out + err
    assert err.splitlines()[-1] == f"{PROGRAMS[command]}: stopped by {sig.name}"
    assert "stopped by" not in out
