# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak replay` streams: its peak memory does not grow with the log.

Two single-file logs, one 6x longer than the other: the duty cycle's inputs at a low rate (few
predictions, so the test stays short) beside a bulky topic that replay only copies (16 kB of
incompressible bytes at 10 Hz), so that the file size dominates: a reader that keeps what it
read resident (a memory map does) adds the whole file to the peak. Each replay runs in a fresh
process exactly as the console script runs it; the peak is that process's VmHWM.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from rclpy.serialization import serialize_message
from std_msgs.msg import UInt8MultiArray

from leadscrew_ros.bag.cdr import FLOAT64, encode_float64
from leadscrew_ros.bag.recorder import Recorder, RecordSettings
from leadscrew_ros.bag.synthetic import LOAD_TOPIC, SPEED_TOPIC, DutyCycle, samples

BULK_TOPIC, BULK_TYPE = "/camera/raw", "std_msgs/msg/UInt8MultiArray"
BULK_BYTES, BULK_HZ = 16384, 10
SHORT_S, LONG_S = 60.0, 360.0
CHILD = """
import json, sys
from leadscrew_ros.cli import main
code = main(sys.argv[1:])
status = dict(line.split(":", 1) for line in open("/proc/self/status"))
print(json.dumps(dict(code=code, peak_kb=int(status["VmHWM"].split()[0]))))
"""


def bulky_log(directory: Path, duration_s: float) -> Path:
    """One MCAP file: speed and load at 20 Hz (a 12 s stroke every 30 s) and the bulky topic."""
    cycle = DutyCycle(duration_s=duration_s, rate_hz=20.0, rest_s=18.0)
    s = samples(cycle)
    rec = Recorder(
        RecordSettings(directory=str(directory), split_size_mb=0.0, split_duration_s=0.0)
    )
    assert rec.start(cycle.start_ns)
    rng = np.random.default_rng(0)
    bulk_every = int(cycle.rate_hz / BULK_HZ)
    times = cycle.start_ns + np.round(s.time_s * 1e9).astype(np.int64)
    for i, (now, speed, load) in enumerate(
        zip(times.tolist(), s.speed_rad_s.tolist(), s.load_n.tolist(), strict=True)
    ):
        rec.write_serialized(SPEED_TOPIC, FLOAT64, encode_float64(speed), now)
        rec.write_serialized(LOAD_TOPIC, FLOAT64, encode_float64(load), now + 100_000)
        if i % bulk_every == 0:
            data = rng.integers(0, 256, BULK_BYTES, dtype=np.uint8).tobytes()
            rec.write_serialized(
                BULK_TOPIC, BULK_TYPE, serialize_message(UInt8MultiArray(data=data)), now + 200_000
            )
        rec.tick(now)
    rec.stop()
    assert not rec.error, rec.error
    return rec.bag


def peak_kb(bag: Path, out: Path) -> int:
    """Peak resident memory [kB] of `leadscrew-squeak replay BAG --no-report` in a fresh
    process (the test environment: the venv's python, this checkout on the path)."""
    out.mkdir()  # the child runs there: `-c` puts its cwd first on the module path
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            CHILD,
            "replay",
            str(bag),
            "--out",
            str(out),
            "--no-report",
            "--quiet",
            "--workers",
            "0",
        ],
        env=dict(os.environ),
        cwd=out,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    res = json.loads(done.stdout.splitlines()[-1])
    assert res["code"] == 0, done.stderr[-2000:]
    return res["peak_kb"]


def test_replay_peak_memory_does_not_grow_with_the_log(tmp_path):
    short, long = (
        bulky_log(tmp_path / name, d) for name, d in (("short", SHORT_S), ("long", LONG_S))
    )
    size = sum(f.stat().st_size for f in long.glob("*.mcap"))
    assert size > 50e6  # enough to show if the reader kept it
    small, big = (peak_kb(bag, tmp_path / f"out_{bag.parent.name}") for bag in (short, long))
    assert big / small <= 1.2, f"peak RSS {small / 1024:.0f} MB -> {big / 1024:.0f} MB"
