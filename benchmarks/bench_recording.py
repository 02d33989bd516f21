# SPDX-License-Identifier: Apache-2.0
"""Recording completeness: 3 input topics at 1 kHz from another process into a recording node.

A node process (`squeak_node`, record.enabled) records motor_speed, axial_load and
nut_position while a publisher process sends them at `--rate-hz` each for `--seconds`
(best effort, sensor-data QoS, busy-waiting schedule), framed by 0.5 s at 20 Hz before and after
so that the first and last messages are not lost to discovery or to a backlog. Each value
encodes its index, so the bag read back tells which messages it holds. Per condition (quiet
machine; `--hog`: one busy-looping process per spare core, i.e. the other core busy):

  completeness = recorded / sent, counting from the first recorded message of each topic;
  lost         = what the node counted as lost (metadata.yaml custom_data lost_messages);
  accounted    = recorded + lost == sent.

`--old-tree DIR` runs the same against another checkout (e.g. `git worktree add /tmp/old
f76cdbf`), whose node has no loss counts. Prints a Markdown table; `--json FILE` the raw
numbers. Usage:

    .venv/bin/python benchmarks/bench_recording.py                 # 10 s, quiet and hog
    .venv/bin/python benchmarks/bench_recording.py --old-tree /tmp/old
    .venv/bin/python benchmarks/bench_recording.py --seconds 3 --conditions quiet --json o.json
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
NS = "/bench_rec"
# topic -> (base, step): value = base + step * index, inside the model's validity
ENCODING = {"motor_speed": (10.0, 0.01), "axial_load": (200.0, 0.001), "nut_position": (0.05, 1e-6)}
FRAME_HZ, FRAME_S = 20.0, 0.5


def publish(seconds: float, rate_hz: float) -> dict:
    """Publisher process body: the three topics, framed burst; returns {topic: sent}."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from std_msgs.msg import Float64

    rclpy.init()
    node = Node("bench_publisher", namespace=NS)
    pubs = {t: node.create_publisher(Float64, t, qos_profile_sensor_data) for t in ENCODING}
    deadline = time.monotonic() + 30
    while not all(p.get_subscription_count() > 0 for p in pubs.values()):
        if time.monotonic() > deadline:
            raise SystemExit("bench publisher: the node never subscribed")
        time.sleep(0.01)
    time.sleep(1.0)  # the node's other readers match within the same round
    k = 0

    def phase(rate: float, duration: float) -> None:
        nonlocal k
        t0, n = time.monotonic(), int(round(rate * duration))
        for i in range(n):
            t = t0 + i / rate
            while time.monotonic() < t:
                pass
            for topic, pub in pubs.items():
                base, step = ENCODING[topic]
                pub.publish(Float64(data=base + step * k))
            k += 1

    phase(FRAME_HZ, FRAME_S)
    print("burst", file=sys.stderr, flush=True)
    phase(rate_hz, seconds)
    phase(FRAME_HZ, FRAME_S)
    time.sleep(0.5)
    node.destroy_node()
    rclpy.try_shutdown()
    return {f"{NS}/{t}": k for t in ENCODING}


def _wait_for_burst(workdir: Path, publisher: subprocess.Popen) -> None:
    """Until the publisher says (on stderr) that its burst starts."""
    line = publisher.stderr.readline()
    if "burst" not in line:
        raise RuntimeError(f"publisher: {line.strip()} {publisher.stderr.read()[-500:]}")


def count_bag(bag: Path) -> dict:
    """{topic: sorted recorded indexes} and the node's loss counts of a bag directory."""
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64

    from leadscrew_ros.bag.logfile import read_log

    indexes: dict[str, list[int]] = {f"{NS}/{t}": [] for t in ENCODING}
    for m in read_log(bag):
        if m.topic.name in indexes:
            base, step = ENCODING[m.topic.name.rsplit("/", 1)[1]]
            value = deserialize_message(m.data, Float64).data
            indexes[m.topic.name].append(round((value - base) / step))
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    custom = meta.get("custom_data") or {}
    by_topic = json.loads(custom.get("lost_messages_by_topic", "null") or "null")
    lost = None if by_topic is None else {t: by_topic.get(t, {}).get("lost", 0) for t in indexes}
    return {"indexes": {t: sorted(v) for t, v in indexes.items()}, "lost": lost}


def run(
    seconds: float,
    rate_hz: float,
    hog: bool,
    tree: Path,
    workdir: Path,
    queue_depth: int | None = None,
    pause_s: float = 0.0,
) -> dict:
    """One measurement: node process from `tree`, publisher process, optional hog; with
    `pause_s`, the node process is stopped (SIGSTOP) that long in the middle of the burst, so
    that messages are certainly lost (with a small `queue_depth`) and must be counted."""
    bags = workdir / "bags"
    env = dict(os.environ, PYTHONPATH=str(tree), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 101))
    env.setdefault("ROS_LOG_DIR", str(workdir / "log"))
    bags.mkdir(parents=True)
    node = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "leadscrew_ros.ros.node",
            "--ros-args",
            "-r",
            f"__ns:={NS}",
            "-p",
            "record.enabled:=true",
            "-p",
            f"record.directory:={bags}",
            *(["-p", f"record.queue_depth:={queue_depth}"] if queue_depth else []),
        ],
        cwd=tree,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=open(workdir / "node.err", "w"),
    )
    hogs = (
        [
            subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(max(1, (os.cpu_count() or 2) - 1))
        ]
        if hog
        else []
    )
    try:
        publisher = subprocess.Popen(
            [sys.executable, __file__, "--publish", str(seconds), str(rate_hz)],
            env=dict(env, PYTHONPATH=str(REPO)),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        if pause_s:
            # discovery (<= 30 s) + 1 s + the 0.5 s lead-in + half the burst: well inside it
            _wait_for_burst(workdir, publisher)
            time.sleep(seconds / 2)
            node.send_signal(signal.SIGSTOP)
            time.sleep(pause_s)
            node.send_signal(signal.SIGCONT)
        stdout, stderr = publisher.communicate(timeout=seconds + 90)
        out = subprocess.CompletedProcess(publisher.args, publisher.returncode, stdout, stderr)
        if out.returncode != 0:
            raise RuntimeError(f"publisher failed: {out.stderr.strip()[-500:]}")
        sent_total = json.loads(out.stdout.strip().splitlines()[-1])
    finally:
        for h in hogs:
            h.kill()
            h.wait()
        node.send_signal(signal.SIGTERM)
        node.wait(timeout=60)
    [bag] = [p for p in bags.iterdir() if p.is_dir()]
    counted = count_bag(bag)
    result = {"hog": hog, "topics": {}}
    for topic, idx in counted["indexes"].items():
        first = idx[0] if idx else sent_total[topic]
        sent = sent_total[topic] - first
        lost = None if counted["lost"] is None else counted["lost"][topic]
        result["topics"][topic] = {
            "sent": sent,
            "recorded": len(idx),
            "lost": lost,
            "duplicates": len(idx) - len(set(idx)),
        }
    t = result["topics"].values()
    result["sent"] = sum(x["sent"] for x in t)
    result["recorded"] = sum(x["recorded"] for x in t)
    result["lost"] = None if counted["lost"] is None else sum(x["lost"] for x in t)
    result["completeness"] = result["recorded"] / result["sent"] if result["sent"] else 0.0
    return result


def table(results: dict) -> str:
    rows = [
        "| code | machine | sent | recorded | completeness | counted lost | "
        "recorded + lost == sent |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in results.items():
        code, cond = name.split(":")
        lost = "–" if r["lost"] is None else str(r["lost"])
        ok = (
            "–"
            if r["lost"] is None
            else (
                "yes"
                if r["recorded"] + r["lost"] == r["sent"]
                else f"no ({r['recorded'] + r['lost']})"
            )
        )
        rows.append(
            f"| {code} | {cond} | {r['sent']} | {r['recorded']} | "
            f"{100 * r['completeness']:.2f} % | {lost} | {ok} |"
        )
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--rate-hz", type=float, default=1000.0)
    p.add_argument("--conditions", default="quiet,hog", help="quiet, hog or both (comma)")
    p.add_argument("--old-tree", type=Path, help="also measure this checkout's node")
    p.add_argument("--queue-depth", type=int, help="record.queue_depth of the new node")
    p.add_argument(
        "--pause-s",
        type=float,
        default=0.0,
        help="SIGSTOP the node this long mid-burst (forces losses to count)",
    )
    p.add_argument("--json", type=Path, help="write the raw numbers here")
    p.add_argument(
        "--publish", nargs=2, type=float, metavar=("SECONDS", "RATE_HZ"), help=argparse.SUPPRESS
    )  # publisher process mode
    a = p.parse_args(argv)
    if a.publish:
        print(json.dumps(publish(*a.publish)))
        return 0
    trees = {"new": REPO, **({"old": a.old_tree.resolve()} if a.old_tree else {})}
    results, t0 = {}, time.time()
    for code, tree in trees.items():
        for cond in a.conditions.split(","):
            with tempfile.TemporaryDirectory(prefix="bench_recording_") as work:
                results[f"{code}:{cond}"] = run(
                    a.seconds,
                    a.rate_hz,
                    cond == "hog",
                    tree,
                    Path(work),
                    a.queue_depth if code == "new" else None,
                    a.pause_s,
                )
    print(
        f"3 topics x {a.rate_hz:g} Hz x {a.seconds:g} s from another process "
        f"({os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}, {time.time() - t0:.0f} s)"
    )
    print(table(results))
    if a.json:
        a.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
