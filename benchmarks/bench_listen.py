# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the node's listening: CPU of the `squeak_predictor` process with a 48 kHz
microphone, listening on against off.

    .venv/bin/python benchmarks/bench_listen.py [--seconds 20] [--chunk-s 0.1] [--json OUT]

The node runs as a child process (`python -c 'node.main()'`, the node's own executor); a probe
in this process publishes what a bench would: motor_speed and axial_load at 100 Hz (a slow sine
through the squeak band's upper edge, as benchmarks/bench_node.py) and, in both runs, the
simulated microphone of `model.acoustics.synthesis.microphone` (motor orders of that speed,
noise, a squeak tone for half of the time) as std_msgs/Float32MultiArray chunks of `--chunk-s`
at the pace of their sound. With listening off nothing subscribes to the microphone, so the
difference is what listening costs: the callback, the analysis thread, the heard outputs and
the measurement status. CPU is the child's utime + stime over the run, in % of one core
(target: listening adds at most 10 %). DDS on loopback, a private ROS_DOMAIN_ID.
"""

from __future__ import annotations

import argparse
import array
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = str(101 + (os.getpid() * 7) % 100)
os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="bench_listen_log_"))

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from std_msgs.msg import Float32MultiArray, Float64  # noqa: E402

from leadscrew_ros.model.acoustics.synthesis import microphone  # noqa: E402
from leadscrew_ros.ros.node import make_executor  # noqa: E402

RATE_HZ = 48000
INPUT_RATE_HZ = 100.0
LOAD_N = 200.0
TARGET_PCT = 10.0
CHILD = "import sys; from leadscrew_ros.ros import node; sys.exit(node.main())"


def speed(t: float) -> float:
    """40 +- 30 rad/s, period 5 s (bench_node's burst speed)."""
    return 40.0 + 30.0 * math.sin(2 * math.pi * t / 5.0)


def signal_of(seconds: float) -> np.ndarray:
    """The microphone: orders of `speed`, noise, a 2651 Hz squeak in the second quarter and
    the fourth."""
    t = np.arange(0.0, seconds + 0.01, 0.01)
    squeak = np.where((t % (seconds / 2)) >= seconds / 4, 2651.0, np.nan)
    return microphone(t, [speed(x) for x in t], squeak, 0.05, RATE_HZ, seed=1)


def cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as fh:
        f = fh.read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


def run(listen: bool, audio: np.ndarray, seconds: float, chunk_s: float) -> dict:
    env = dict(os.environ)
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, "--ros-args", "-p", f"listen.enabled:={str(listen).lower()}"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT,
    )
    ctx = Context()
    rclpy.init(context=ctx)
    probe = Node("bench_listen_probe", context=ctx)
    ex = make_executor(ctx)
    ex.add_node(probe)
    try:
        speed_pub = probe.create_publisher(Float64, "motor_speed", qos_profile_sensor_data)
        load_pub = probe.create_publisher(Float64, "axial_load", qos_profile_sensor_data)
        mic_pub = probe.create_publisher(Float32MultiArray, "microphone", 10)
        deadline = time.monotonic() + 30.0
        while speed_pub.get_subscription_count() == 0 or (
            listen and mic_pub.get_subscription_count() == 0
        ):
            if time.monotonic() > deadline:
                raise RuntimeError("the node did not subscribe")
            ex.spin_once(timeout_sec=0.05)
        time.sleep(1.0)  # start-up over
        step = int(chunk_s * RATE_HZ)
        c0, t0 = cpu_s(proc.pid), time.monotonic()
        p0 = time.process_time()
        sent_inputs = sent_chunks = 0
        while (now := time.monotonic() - t0) < seconds:
            while sent_inputs / INPUT_RATE_HZ <= now:
                speed_pub.publish(Float64(data=speed(sent_inputs / INPUT_RATE_HZ)))
                load_pub.publish(Float64(data=LOAD_N))
                sent_inputs += 1
            while (sent_chunks + 1) * step <= now * RATE_HZ:
                x = audio[sent_chunks * step : (sent_chunks + 1) * step]
                mic_pub.publish(Float32MultiArray(data=array.array("f", x.tobytes())))
                sent_chunks += 1
            ex.spin_once(timeout_sec=0.002)
        wall = time.monotonic() - t0
        used = cpu_s(proc.pid) - c0
        return dict(
            listen=listen,
            wall_s=wall,
            node_cpu_pct=100 * used / wall,
            probe_cpu_pct=100 * (time.process_time() - p0) / wall,
            chunks=sent_chunks,
            inputs=sent_inputs,
        )
    finally:
        ex.shutdown()
        probe.destroy_node()
        rclpy.try_shutdown(context=ctx)
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="length of each run [s]")
    ap.add_argument("--chunk-s", type=float, default=0.1, help="microphone chunk length [s]")
    ap.add_argument("--rounds", type=int, default=1, help="off/on pairs, interleaved")
    ap.add_argument("--json", metavar="OUT", help="also write the numbers here")
    args = ap.parse_args(argv)
    audio = signal_of(args.seconds + 1.0)
    results = []
    for _ in range(args.rounds):
        for listen in (False, True):
            results.append(run(listen, audio, args.seconds, args.chunk_s))
    off = [r["node_cpu_pct"] for r in results if not r["listen"]]
    on = [r["node_cpu_pct"] for r in results if r["listen"]]
    added = float(np.median(on) - np.median(off))
    print(
        f"node CPU, 100 Hz inputs + 48 kHz microphone in {args.chunk_s:g} s chunks, "
        f"{args.seconds:g} s x {args.rounds} round(s), load average "
        f"{os.getloadavg()[0]:.2f}:"
    )
    print("| listening | node CPU [% of one core] (median) | runs |")
    print("|---|---|---|")
    print(f"| off | {np.median(off):.1f} | {', '.join(f'{x:.1f}' for x in off)} |")
    print(f"| on | {np.median(on):.1f} | {', '.join(f'{x:.1f}' for x in on)} |")
    print(
        f"listening adds {added:.1f} % of one core (target <= {TARGET_PCT:g} %): "
        f"{'met' if added <= TARGET_PCT else 'NOT met'}"
    )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(results=results, added_pct=added), fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
