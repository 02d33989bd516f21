# SPDX-License-Identifier: Apache-2.0
"""Child processes of the tests: the node and the CLI, started with the venv's python and the
parent's environment (the ROS wheels' bootstrapper needs both, see the shared notes), and a
cleanup that always leaves nothing running and no Fast DDS shared memory behind."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CLI = [sys.executable, "-m", "leadscrew_ros.cli"]


def node_command() -> list[str]:
    """squeak_node as installed (the console script), else the module."""
    script = Path(sys.executable).with_name("squeak_node")
    return [str(script)] if script.exists() else [sys.executable, "-m", "leadscrew_ros.ros.node"]


def domain(offset: int) -> int:
    """A ROS_DOMAIN_ID of this test process for children (201..230: clear of conftest's
    per-process domains 1..200)."""
    return 201 + (os.getpid() + offset) % 30


def env_for(domain_id: int) -> dict:
    return dict(
        os.environ,
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        PYTHONUNBUFFERED="1",
    )


def start(argv, domain_id, tmp_path, name, new_session: bool = False) -> subprocess.Popen:
    """`argv` in the repository on `domain_id`, stdout and stderr to files read by `output`;
    `new_session`: in a process group of its own with its children (what a terminal's Ctrl-C
    reaches: `os.killpg`)."""
    out, err = (open(tmp_path / f"{name}.{s}", "w+") for s in ("out", "err"))
    proc = subprocess.Popen(
        argv,
        cwd=REPO,
        env=env_for(domain_id),
        stdout=out,
        stderr=err,
        text=True,
        start_new_session=new_session,
    )
    proc.files = (out, err)
    return proc


def output(proc) -> tuple[str, str]:
    """What a process from `start` wrote so far: (stdout, stderr)."""
    texts = []
    for f in proc.files:
        f.flush()
        f.seek(0)
        texts.append(f.read())
    return texts[0], texts[1]


def stop(*procs, grace_s: float = 0.0) -> None:
    """Cleanup: anything still running gets SIGTERM and `grace_s` seconds if asked, then
    SIGKILL; files of `start` are closed; Fast DDS shared memory a killed process left is
    cleaned (only zombie segments: `fastdds shm clean` leaves live processes alone)."""
    killed = False
    for proc in procs:
        if proc is None:
            continue
        if proc.poll() is None and grace_s > 0:
            proc.terminate()
            try:
                proc.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                pass
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
            killed = True
        for f in getattr(proc, "files", ()):
            f.close()
    if killed:
        tool = Path(sys.prefix) / "tools" / "fastdds" / "fastdds.py"
        if tool.exists():
            subprocess.run(
                [sys.executable, str(tool), "shm", "clean"], capture_output=True, timeout=30
            )


def wait_initialised(procs: list[subprocess.Popen], timeout: float = 60.0) -> None:
    """Wait until each process has run rclpy.init (its log file exists in ROS_LOG_DIR); a
    child's imports took over 10 s with the machine's load at 9 on 2 cores."""
    log_dir, deadline = Path(os.environ["ROS_LOG_DIR"]), time.monotonic() + timeout
    for proc in procs:
        while not any(log_dir.glob(f"*_{proc.pid}_*.log")):
            assert proc.poll() is None, f"process exited early ({proc.returncode})"
            assert time.monotonic() < deadline, "process did not initialise rclpy"
            time.sleep(0.01)
