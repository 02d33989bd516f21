# SPDX-License-Identifier: Apache-2.0
"""Peak memory of `leadscrew-squeak replay` against log length, with and without the report.

    .venv/bin/python benchmarks/bench_replay_rss.py [--minutes 10 60] [--rate HZ] [--src DIR]
    .venv/bin/python benchmarks/bench_replay_rss.py --sound [--minutes 10 120]
    .venv/bin/python benchmarks/bench_replay_rss.py --listen-wav --minutes 5 30

For each log length (the duty cycle of `bench_replay.py` in one MCAP file, as rosbag2 records
without `--max-bag-duration`; `--split-s` for split files; generated once and cached in the temp
directory) and each way (`replay` with the PNG report, `replay --no-report`), the command runs in
a fresh child process exactly as the console script runs it (`leadscrew_ros.cli.main`). The child
samples /proc/self/status every 20 ms and prints the peak resident memory VmHWM and the highest
file-backed (RssFile) and anonymous (RssAnon) parts it saw; the prediction workers' peak comes
from RUSAGE_CHILDREN. Streaming means equal peaks: target 60-minute peak <= 1.2 x the 10-minute
peak, both ways. `--src DIR` runs the package of another checkout (e.g. `git archive` of an old
commit) on the same logs. `--sound`: instead, a virtual-bench unit (`bench`, seed 0) whose one
stroke lasts the log's length, with its 48 kHz microphone, replayed with its sound (issue 30:
the replay's memory grew with the audio); a log longer than an hour (the bench's limit) is the
10-minute one played over and over (`repeated_log`). `--listen-wav`: `leadscrew-squeak listen
FILE.wav` on 48 kHz 16-bit WAVs of those lengths (a tone switched on and off in noise).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_replay import TARGET_RSS_RATIO, size_mb  # noqa: E402
from leadscrew_ros.bag.synthetic import DutyCycle, write_log  # noqa: E402

MAX_BENCH_MINUTES = 60.0  # `bench.duration_s` is at most an hour: a longer log repeats ...
REPEATED_MINUTES = 10.0  # ... the bench of this length

# Runs in the child: the CLI in this process, a sampler thread beside it.
CHILD = """
import json, resource, sys, threading
from leadscrew_ros.cli import main
def status():
    with open("/proc/self/status") as f:
        return {k: int(v.split()[0]) for k, v in (line.split(":", 1) for line in f)
                if k in ("VmHWM", "RssFile", "RssAnon")}
peak = dict.fromkeys(("RssFile", "RssAnon"), 0)
done = threading.Event()
def sample():
    while not done.wait(0.02):
        for k, v in status().items():
            if k in peak:
                peak[k] = max(peak[k], v)
threading.Thread(target=sample, daemon=True).start()
code = main(sys.argv[1:])
done.set()
print(json.dumps(dict(code=code, peak_mb=status()["VmHWM"] / 1024,
                      rss_file_mb=peak["RssFile"] / 1024, rss_anon_mb=peak["RssAnon"] / 1024,
                      workers_peak_mb=resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
                      / 1024)))
"""


def cached_log(cycle: DutyCycle, split_s: float) -> Path:
    """The bag directory of `cycle` split every `split_s` (0: one file), generated if not
    cached."""
    key = hashlib.sha256(repr((cycle, split_s)).encode()).hexdigest()[:12]
    root = Path(tempfile.gettempdir()) / "leadscrew_ros_bench_replay_rss" / key
    bags = sorted(root.glob("squeak_*")) if root.is_dir() else []
    if bags:
        return bags[0]
    root.mkdir(parents=True, exist_ok=True)
    return write_log(cycle, root, split_duration_s=split_s)


def cached_bench_log(minutes: float) -> tuple[Path, str]:
    """(bag directory, joint name) of a one-unit virtual bench whose stroke lasts `minutes`,
    with its microphone; generated if not cached."""
    from leadscrew_ros.bag.virtual_bench import BenchSettings, run

    settings = BenchSettings(units=1, duration_s=minutes * 60.0, seed=0)
    key = hashlib.sha256(repr(settings).encode()).hexdigest()[:12]
    root = Path(tempfile.gettempdir()) / "leadscrew_ros_bench_replay_rss" / f"sound_{key}"
    truth_path = root / "truth.json"
    if not truth_path.is_file():
        run(settings, root)
    truth = json.loads(truth_path.read_text())
    return root / truth["units"][0]["log"], DutyCycle().joint_name


def repeated_log(bag: Path, minutes: float) -> Path:
    """An MCAP file of `bag`'s messages played over and over for `minutes`: each repeat's log
    times and audio header stamps shifted by the bag's duration plus 50 ms (a bench stroke is
    at most an hour: longer sound logs are made of one). Generated once, cached beside it."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    out = bag.parent / f"repeated_{minutes:g}min.mcap"
    if out.is_file():
        return out
    [src] = sorted(bag.glob("*.mcap"))
    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        stats = summary.statistics
        period = stats.message_end_time - stats.message_start_time + 50_000_000
        repeats = int(np.ceil(minutes * 60e9 / period))
        part = out.with_suffix(".part")
        with open(part, "wb") as g:
            w = Writer(g)
            w.start(profile="ros2", library="bench_replay_rss")
            ids = {}
            for sid, sc in summary.schemas.items():
                ids[sid] = w.register_schema(sc.name, sc.encoding, sc.data)
            chans = {
                cid: w.register_channel(c.topic, c.message_encoding, ids[c.schema_id], c.metadata)
                for cid, c in summary.channels.items()
            }
            stamped = {
                cid
                for cid, c in summary.channels.items()
                if summary.schemas[c.schema_id].name.endswith("AudioDataStamped")
            }
            for m in reader.iter_metadata():
                w.add_metadata(m.name, m.metadata)
            for k in range(repeats):
                shift = k * period
                for _, channel, msg in reader.iter_messages(log_time_order=True):
                    data = msg.data
                    if channel.id in stamped:  # CDR: encapsulation, then header.stamp.sec
                        sec, nsec = struct.unpack_from("<iI", data, 4)
                        ns = sec * 1_000_000_000 + nsec + shift
                        data = bytearray(data)
                        struct.pack_into("<iI", data, 4, ns // 1_000_000_000, ns % 1_000_000_000)
                    w.add_message(
                        chans[channel.id],
                        msg.log_time + shift,
                        bytes(data),
                        msg.publish_time + shift,
                    )
            w.finish()
        part.rename(out)
    return out


def cached_wav(minutes: float) -> Path:
    """A 48 kHz 16-bit mono WAV of `minutes`: noise and a 1 kHz tone switched on for the last
    5 s of every 20 s, nothing moving; generated a minute at a time, cached."""
    from scipy.io import wavfile

    root = Path(tempfile.gettempdir()) / "leadscrew_ros_bench_replay_rss"
    path = root / f"listen_{minutes:g}min.wav"
    if path.is_file():
        return path
    root.mkdir(parents=True, exist_ok=True)
    fs, rng = 48000, np.random.default_rng(0)
    x = np.empty(round(minutes * 60 * fs), np.int16)
    for a in range(0, x.size, 60 * fs):
        t = np.arange(a, min(x.size, a + 60 * fs)) / fs
        y = 0.01 * rng.standard_normal(t.size) + 0.05 * np.sin(2e3 * np.pi * t) * (t % 20 > 15)
        x[a : a + t.size] = np.round(y * 32767).astype(np.int16)
    wavfile.write(path.with_suffix(".part"), fs, x)
    path.with_suffix(".part").rename(path)
    return path


def child_peak(argv: list[str], src: str | None = None) -> dict:
    """`leadscrew-squeak ARGV` in a fresh child process (`CHILD`): its peak memory (MB)."""
    env = dict(os.environ)  # the child runs in a temp dir: `-c` puts its cwd first on the path
    if src:
        env["PYTHONPATH"] = str(Path(src).resolve())
    with tempfile.TemporaryDirectory(prefix="bench_replay_rss_") as cwd:
        done = subprocess.run(
            [sys.executable, "-c", CHILD, *argv], env=env, cwd=cwd, capture_output=True, text=True
        )
    if done.returncode:
        raise SystemExit(f"{argv[0]} failed:\n{done.stderr[-3000:]}")
    res = json.loads(done.stdout.splitlines()[-1])
    if res["code"]:
        raise SystemExit(f"{argv[0]} exited {res['code']}:\n{done.stderr[-3000:]}")
    return res


def listen_rows(minutes: list[float], src: str | None) -> int:
    """`leadscrew-squeak listen FILE.wav` on WAVs of each length: the peak memory table."""
    rows = []
    for m in minutes:
        wav = cached_wav(m)
        with tempfile.TemporaryDirectory(prefix="bench_listen_rss_") as out:
            r = child_peak(["listen", str(wav), "--out", out], src)
        rows.append((m, size_mb(wav), r["peak_mb"]))
        print(f"{m:g} min: {r['peak_mb']:.0f} MB", file=sys.stderr, flush=True)
    print("| WAV (48 kHz, 16 bit) | file size | peak RSS (VmHWM) |\n|---|---:|---:|")
    for m, size, peak in rows:
        print(f"| {m:g} min | {size:.0f} MB | {peak:.0f} MB |")
    ratio = rows[-1][2] / rows[0][2]
    print(
        f"\nlisten: peak ratio {rows[-1][0]:g} / {rows[0][0]:g} min = **{ratio:.2f}** (target <= "
        f"{TARGET_RSS_RATIO:g}: {'met' if ratio <= TARGET_RSS_RATIO else 'MISSED'}); package "
        f"from {src or 'this checkout'}; load avg {os.getloadavg()[0]:.2f}"
    )
    return 0


def replay_peak(
    bag: Path, joint: str, report: bool, src: str | None = None, extra: tuple[str, ...] = ()
) -> dict:
    """`leadscrew-squeak replay BAG` (`--no-report` unless `report`) in a fresh child process:
    its peak memory (MB) as printed by `CHILD`."""
    with tempfile.TemporaryDirectory(prefix="bench_replay_rss_") as out:
        argv = ["replay", str(bag), "--out", out, "--joint-name", joint, "--quiet"]
        return child_peak([*argv, *(() if report else ("--no-report",)), *extra], src)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--minutes", type=float, nargs="+", default=[10.0, 60.0], help="log lengths (default 10 60)"
    )
    ap.add_argument("--rate", type=float, default=200.0, help="sample rate [Hz] (default 200)")
    ap.add_argument(
        "--split-s",
        type=float,
        default=0.0,
        help="split the logs into files of this duration [s] (default 0: one file)",
    )
    ap.add_argument("--src", metavar="DIR", help="run the package of this checkout instead")
    ap.add_argument(
        "--sound",
        action="store_true",
        help="virtual-bench logs with a 48 kHz microphone, replayed with their sound",
    )
    ap.add_argument(
        "--listen-wav",
        action="store_true",
        help="instead, `listen FILE.wav` on 48 kHz WAVs of the --minutes lengths",
    )
    args = ap.parse_args(argv)
    if args.listen_wav:
        return listen_rows(args.minutes, args.src)
    rows = []
    for minutes in args.minutes:
        if args.sound:
            long = minutes > MAX_BENCH_MINUTES
            bag, joint = cached_bench_log(REPEATED_MINUTES if long else minutes)
            if long:
                bag = repeated_log(bag, minutes)
        else:
            cycle = DutyCycle(duration_s=minutes * 60.0, rate_hz=args.rate)
            bag, joint = cached_log(cycle, args.split_s), cycle.joint_name
        for report in (True, False):
            r = replay_peak(bag, joint, report, args.src)
            r.update(minutes=minutes, report=report, log_mb=size_mb(bag))
            rows.append(r)
            print(
                f"{minutes:g} min {'with' if report else 'without'} report: {r['peak_mb']:.0f} MB",
                file=sys.stderr,
                flush=True,
            )
    print(
        "| log | report | file size | peak RSS (VmHWM) | peak RssFile | peak RssAnon | "
        "peak RSS (a worker) |\n|---|---|---:|---:|---:|---:|---:|"
    )
    for r in rows:
        what = "with 48 kHz sound" if args.sound else f"at {args.rate:g} Hz"
        print(
            f"| {r['minutes']:g} min {what} | {'yes' if r['report'] else 'no'} | "
            f"{r['log_mb']:.0f} MB | {r['peak_mb']:.0f} MB | {r['rss_file_mb']:.0f} MB | "
            f"{r['rss_anon_mb']:.0f} MB | {r['workers_peak_mb']:.0f} MB |"
        )
    print()
    for report in (True, False):
        way = [r for r in rows if r["report"] == report]
        ratio = way[-1]["peak_mb"] / way[0]["peak_mb"]
        print(
            f"{'replay' if report else 'replay --no-report'}: peak ratio "
            f"{way[-1]['minutes']:g} / {way[0]['minutes']:g} min = **{ratio:.2f}** (target <= "
            f"{TARGET_RSS_RATIO:g}: {'met' if ratio <= TARGET_RSS_RATIO else 'MISSED'})"
        )
    print(
        f"package from {args.src or 'this checkout'}; logs split every {args.split_s:g} s "
        f"(0: one file); load avg {os.getloadavg()[0]:.2f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
