# SPDX-License-Identifier: Apache-2.0
"""What the listening hears on a realistic bench, against the bench's truth (issue 30).

    .venv/bin/python benchmarks/bench_realistic.py [--units N] [--seed S] [--duration D]
        [--gear-ratio R] [--fan-hz F] [--mains-hz F] [--json OUT.json]

Makes `leadscrew-squeak bench --realistic` (fan, mains hum and its harmonics, pink noise, a
worm-geared motor with its 2nd order and commutator, a room, the squeak grown by the amplitude
equation with its harmonics) in a temp directory and replays every unit with its sound (the
CLI, no report). Each heard episode is judged against truth.json: a squeak when it overlaps an
audible interval; else false, by cause: a background tone (within 2 % of one), the drive (within
2 % of a drive ratio times the screw's rotation frequency at its start), a squeak harmonic (2-5x
the squeak's frequency at its time), else other. Printed, in Markdown: the false episodes by
cause, the audible intervals found, onset delays (episode start minus the interval's start,
by the growth at the onset, >= 50 1/s or less), frame recall and precision against the
audible frames, creaks, and the measured growth rate against the truth's at the onsets
measured (`growth_snr_db` >= 15 dB): the slope of the truth's envelope over the window the
measurement reports (`envelope_growth`; sigma still rises after an onset on a ramp, so the
growth within 25 ms of the onset, `Onset`, is printed beside it but is not what was measured).
Live: each unit's sound also goes through a `StreamingDetector` in 0.1-s chunks with the speed
known up to each chunk's end, as the node listens, twice back to back (what a node running
across strokes has learned by the second); its heard state at each chunk's end against the
truth's audible intervals gives the live recall and precision of each pass.
Nothing is asserted: the tests hold the targets.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from leadscrew_ros.bag.audio import read_audio
from leadscrew_ros.bag.cdr import decode_float64
from leadscrew_ros.bag.logsource import open_log
from leadscrew_ros.bag.synthetic import SPEED_TOPIC
from leadscrew_ros.cli import main as cli
from leadscrew_ros.model.acoustics import DetectorSettings, StreamingDetector
from leadscrew_ros.model.acoustics.bench_sound import ONSET_WINDOW_S, envelope_growth

TOLERANCE = 0.02  # relative frequency tolerance of a cause
LIVE_CHUNK_S = 0.1  # the node's microphone chunks
LIVE_SPEED_S = 40.0  # the speed history the node keeps (`live.listen.SPEED_HISTORY` at 100 Hz)
FAST_GROWTH_PER_S = 50.0  # onset within 50 ms where the growth is at least this, else 150 ms


def speed_of(log: Path) -> tuple[np.ndarray, np.ndarray]:
    """(times [s] from the log's first message, screw speed [rad/s]) of a log."""
    source = open_log(log)
    t, v, first = [], [], None
    for _, m in source.messages():
        first = m.log_time_ns if first is None else first
        if m.topic.name == SPEED_TOPIC:
            t.append((m.log_time_ns - first) * 1e-9)
            v.append(decode_float64(m.data))
    return np.asarray(t), np.asarray(v)


def _live(log: Path, speed: tuple[np.ndarray, np.ndarray], audible: list[dict]) -> np.ndarray:
    """The node's listening replayed: the unit's sound and speed played twice back to back (a
    node runs across strokes), 0.1-s chunks pushed into a `StreamingDetector` with the speed
    of the last `LIVE_SPEED_S` up to each chunk's end, the closed episodes through
    `learn_held` (as `live.listen.Listener` does); per pass and chunk (heard now, audible at
    its end) counts as [pass][[both, heard only], [audible only, neither]]."""
    track = read_audio(log)
    x, fs = np.asarray(track.samples), track.sample_rate_hz
    t1, v1 = speed
    span = track.t0_s + x.size / fs
    t, v = np.concatenate([t1, t1 + span]), np.concatenate([v1, v1])
    det = StreamingDetector(DetectorSettings(), fs)
    n = round(LIVE_CHUNK_S * fs)
    counts = np.zeros((2, 2, 2), int)
    for rep in range(2):
        for a in range(0, x.size - n + 1, n):
            start = track.t0_s + a / fs + rep * span
            end = start + n / fs
            known = (t <= end) & (t > end - LIVE_SPEED_S)
            closed = det.push(x[a : a + n], start, v[known], speed_times_s=t[known])
            det.learn_held(closed, t[known], v[known])
            on = any(i["start_s"] <= end - rep * span < i["end_s"] for i in audible)
            counts[rep, int(not on), int(not det.heard_now)] += 1
    return counts


def _cause(e: dict, unit: dict, sound: dict, speed: tuple[np.ndarray, np.ndarray]) -> str:
    f = e["frequency_hz"]
    audible = unit["sound"]["audible_intervals"]
    if any(e["start_s"] < a["end_s"] and e["end_s"] > a["start_s"] for a in audible):
        return "squeak"
    if any(abs(f / b - 1) <= TOLERANCE for b in sound["background_tones_hz"]):
        return "background tone"
    rotation_hz = abs(float(np.interp(e["start_s"], *speed))) / (2 * np.pi)
    if rotation_hz > 0 and any(
        abs(f / (r * rotation_hz) - 1) <= TOLERANCE for r in sound["drive_orders"]
    ):
        return "drive order"
    squeak_hz = [
        (a["min_hz"], a["max_hz"]) for a in audible if abs(a["start_s"] - e["start_s"]) < 1.0
    ]
    if any(
        abs(f / (m * g) - 1) <= TOLERANCE
        for lo, hi in squeak_hz
        for g in (lo, hi)
        for m in range(2, 6)
    ):
        return "squeak harmonic"
    return "other"


def _frames(intervals: list[tuple[float, float]], t: np.ndarray) -> np.ndarray:
    on = np.zeros(t.size, bool)
    for a, b in intervals:
        on |= (t >= a) & (t < b)
    return on


def evaluate(root: Path, args: argparse.Namespace) -> dict:
    bench = root / "bench"
    argv = ["bench", "--out", str(bench), "--units", str(args.units), "--seed", str(args.seed)]
    argv += ["--duration", str(args.duration), "--realistic", "--quiet"]
    for option, value in (
        ("--gear-ratio", args.gear_ratio),
        ("--fan-hz", args.fan_hz),
        ("--mains-hz", args.mains_hz),
    ):
        if value:
            argv += [option, str(value)]
    if cli(argv) != 0:
        raise SystemExit("bench failed")
    truth = json.loads((bench / "truth.json").read_text())
    sound = truth["sound"]
    causes: dict[str, int] = {}
    found = audible_n = 0
    delays_fast, delays_slow, growth, creaks = [], [], [], 0
    tp = fp = fn = 0
    live = np.zeros((2, 2, 2), int)
    t0 = time.perf_counter()
    for k, unit in enumerate(truth["units"]):
        log = next(bench.glob(unit["log"] + "*"))
        out = root / f"r{k}"
        cli(["replay", str(log), "--out", str(out), "--no-report", "--quiet", "--workers", "0"])
        heard = json.loads((out / "summary.json").read_text())["heard"]
        speed = speed_of(log)
        for e in heard["episodes"]:
            c = _cause(e, unit, sound, speed)
            causes[c] = causes.get(c, 0) + 1
        creaks += len(heard.get("creaks", []))
        live += _live(log, speed, unit["sound"]["audible_intervals"])
        audible = [
            a for a in unit["sound"]["audible_intervals"] if a["end_s"] - a["start_s"] >= 0.05
        ]
        onsets = {round(o["time_s"], 3): o for o in unit["sound"]["onsets"]}
        for a in audible:
            audible_n += 1
            hits = [
                e
                for e in heard["episodes"]
                if e["start_s"] < a["end_s"] and e["end_s"] > a["start_s"]
            ]
            if not hits:
                continue
            found += 1
            first = min(hits, key=lambda e: e["start_s"])
            onset = onsets.get(round(a["start_s"], 3))
            rate = onset["growth_rate_per_s"] if onset else 0.0
            (delays_fast if rate >= FAST_GROWTH_PER_S else delays_slow).append(
                first["start_s"] - a["start_s"]
            )
            g = first.get("growth_rate_per_s")
            if onset and g is not None and (first.get("growth_snr_db") or 0) >= 15.0:
                true = envelope_growth(
                    unit["sound"]["envelope_dbfs"],
                    unit["sound"]["envelope_rate_hz"],
                    first["growth_window_s"],
                )
                at_onset = onset["fitted_growth_per_s"] or onset["growth_rate_per_s"]
                if true is not None:
                    growth.append(
                        (round(a["start_s"], 2), at_onset, true, g, first["growth_rate_se"])
                    )
        t = np.arange(0.0, heard["log_s"], 0.01)
        truth_on = _frames(
            [(a["start_s"], a["end_s"]) for a in unit["sound"]["audible_intervals"]], t
        )
        heard_on = _frames([(e["start_s"], e["end_s"]) for e in heard["episodes"]], t)
        tp += int(np.sum(truth_on & heard_on))
        fp += int(np.sum(~truth_on & heard_on))
        fn += int(np.sum(truth_on & ~heard_on))
    return dict(
        units=len(truth["units"]),
        seed=args.seed,
        causes=causes,
        false_episodes=sum(v for k, v in causes.items() if k != "squeak"),
        audible_intervals=audible_n,
        found=found,
        onset_delay_fast_s=delays_fast,
        onset_delay_slow_s=delays_slow,
        frame_recall=tp / (tp + fn) if tp + fn else None,
        frame_precision=tp / (tp + fp) if tp + fp else None,
        creaks=creaks,
        live=[
            (
                float(c[0, 0] / c[0].sum()) if c[0].sum() else None,
                float(c[0, 0] / c[:, 0].sum()) if c[:, 0].sum() else None,
            )
            for c in live
        ],
        growth=growth,
        wall_s=time.perf_counter() - t0,
    )


def _delays(d: list[float]) -> str:
    if not d:
        return "-"
    ms = [1000 * x for x in d]
    return f"{len(ms)}: median {statistics.median(ms):+.0f} ms, worst {max(ms, key=abs):+.0f} ms"


def report(r: dict) -> str:
    lines = [
        f"{r['units']} units, seed {r['seed']}: {r['false_episodes']} false episodes "
        f"({r['false_episodes'] / r['units']:.2f} per unit), {r['found']} of "
        f"{r['audible_intervals']} audible intervals found, {r['creaks']} creaks",
        "",
        "| heard episode | count |",
        "|---|---:|",
        *[f"| {k} | {v} |" for k, v in sorted(r["causes"].items())],
        "",
        "| measure | value |",
        "|---|---|",
        f"| onset delay, growth >= {FAST_GROWTH_PER_S:g} 1/s "
        f"| {_delays(r['onset_delay_fast_s'])} |",
        f"| onset delay, slower growth | {_delays(r['onset_delay_slow_s'])} |",
        f"| frame recall / precision (10 ms frames) | {r['frame_recall']:.3f} / "
        f"{r['frame_precision']:.3f} |",
        *[
            f"| live, {which} (the node's heard state, {LIVE_CHUNK_S:g}-s chunks): "
            f"recall / precision | {rec:.3f} / {prec:.3f} |"
            for which, (rec, prec) in zip(
                ("first stroke", "the same again"), r["live"], strict=True
            )
        ],
    ]
    if r["growth"]:
        ratios = [g / t for _, _, t, g, _ in r["growth"]]
        early = [g / o for _, o, _, g, _ in r["growth"]]
        lines += [
            "",
            "| onset [s] | truth at the onset [1/s] | truth over the window [1/s] "
            "| measured [1/s] | se [1/s] | measured / truth over the window |",
            "|---:|---:|---:|---:|---:|---:|",
            *[
                f"| {s} | {o:.1f} | {t:.1f} | {g:.1f} | {se:.1f} | {g / t:.2f} |"
                for s, o, t, g, se in r["growth"]
            ],
            "",
            f"growth measured / truth over the measurement's window: median "
            f"{statistics.median(ratios):.2f} over {len(ratios)} onsets (against the truth "
            f"within {1000 * ONSET_WINDOW_S:g} ms of the onset: {statistics.median(early):.2f})",
        ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--units", type=int, default=10)
    p.add_argument("--seed", type=int, default=77)
    p.add_argument("--duration", type=float, default=12.0, help="stroke duration [s]")
    p.add_argument("--gear-ratio", type=float, default=0.0, help="0: the bench's default")
    p.add_argument("--fan-hz", type=float, default=0.0, help="the fan's tone; 0: the default")
    p.add_argument("--mains-hz", type=float, default=0.0, help="hum at 2, 4, 6 x; 0: default")
    p.add_argument("--json", metavar="OUT.json")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        r = evaluate(Path(tmp), args)
    print(report(r))
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
