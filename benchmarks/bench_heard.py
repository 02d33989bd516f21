# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the replay with sound (heard vs predicted) on the virtual bench.

    .venv/bin/python benchmarks/bench_heard.py [--units N] [--duration S] [--rounds R]
        [--agreement] [--json OUT.json]

Throughput (default): a virtual bench of `--units` units (`bag.virtual_bench`, paper
formulation, `--duration` s strokes, 48 kHz microphone) is made in a temp directory; each unit
is replayed in this process (workers 0, no report) with its sound and with `--no-audio`,
interleaved, for `--rounds` rounds. Printed: x real time with and without sound (log duration /
wall time, medians), their ratio, and the share of the replay with sound spent in the detector
(`summary.json` `detect_wall_s` / `wall_s`). Ratios only: nothing is asserted.

`--agreement`: benches made with each formulation (same seed), every unit replayed with each
formulation at the NOMINAL parameters (as a real unit's log is replayed: the drawn parameters
are in truth.json only), then also at the unit's own drawn parameters; a table of the median
(and worst) recall, precision and Brier score over the units, 2 x 2 per parameter choice.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from leadscrew_ros.bag.virtual_bench import BenchSettings, run
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.review.listen import FORMULATIONS, SoundSettings
from leadscrew_ros.review.replay import ReplaySettings, replay


def _replay(log: Path, out: Path, model: SqueakModel, sound: bool) -> dict:
    replay(
        log,
        model,
        out,
        ReplaySettings(workers=0, progress=False, listen=SoundSettings(enabled=sound)),
    )
    return json.loads((out / "summary.json").read_text())


def _bench(root: Path, units: int, duration_s: float, formulation: str, seed: int) -> list:
    """The bench's (log, truth of the unit) pairs."""
    out = root / f"bench-{formulation}"
    truth = run(
        BenchSettings(units=units, duration_s=duration_s, formulation=formulation, seed=seed), out
    )
    return [(out / u["log"], u) for u in truth["units"]]


def throughput(root: Path, args: argparse.Namespace) -> dict:
    logs = _bench(root, args.units, args.duration, "paper", args.seed)
    model = SqueakModel()
    with_sound, without, share = [], [], []
    for r in range(args.rounds):
        for k, (log, _) in enumerate(logs):
            for sound in (True, False) if (r + k) % 2 == 0 else (False, True):
                s = _replay(log, root / "out", model, sound)
                (with_sound if sound else without).append(s["x_real_time"])
                if sound:
                    share.append(s["detect_wall_s"] / s["wall_s"])
    return {
        "x_real_time_with_sound": statistics.median(with_sound),
        "x_real_time_without_sound": statistics.median(without),
        "with_over_without": statistics.median(with_sound) / statistics.median(without),
        "detection_share": statistics.median(share),
        "replays": len(with_sound) + len(without),
    }


def agreement_table(root: Path, args: argparse.Namespace) -> dict:
    out: dict = {}
    for made in FORMULATIONS:
        logs = _bench(root, args.units, args.duration, made, args.seed)
        for params_kind in ("nominal", "unit"):
            for replayed in FORMULATIONS:
                scores: dict[str, list[float]] = {"recall": [], "precision": [], "brier": []}
                for log, unit in logs:
                    params = ScrewParameters(formulation=replayed)
                    if params_kind == "unit":
                        params = params.with_(**unit["params"])
                    s = _replay(log, root / "out", SqueakModel(params), True)
                    a = s["heard"]["agreement"]
                    for key in scores:
                        if a[key] is not None:
                            scores[key].append(a[key])
                out[f"{params_kind} bench={made} replay={replayed}"] = {
                    key: {
                        "median": statistics.median(v) if v else None,
                        "worst": (max(v) if key == "brier" else min(v)) if v else None,
                        "units": len(v),
                    }
                    for key, v in scores.items()
                }
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--units", type=int, default=3)
    p.add_argument("--duration", type=float, default=6.0, help="stroke duration [s]")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--agreement",
        action="store_true",
        help="the 2 x 2 table of recall, precision and Brier instead",
    )
    p.add_argument("--json", metavar="OUT.json")
    args = p.parse_args(argv)
    start, load0 = time.perf_counter(), os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench_heard_") as tmp:
        result = (agreement_table if args.agreement else throughput)(Path(tmp), args)
    if args.agreement:
        print(
            "| parameters | bench | replay | recall median (worst) | precision median "
            "(worst) | Brier median (worst) |"
        )
        print("|---|---|---|---|---|---|")
        for key, v in result.items():
            kind, made, replayed = key.replace("bench=", "").replace("replay=", "").split()
            cells = [
                f"{v[m]['median']:.3f} ({v[m]['worst']:.3f})"
                if v[m]["median"] is not None
                else "n/a"
                for m in ("recall", "precision", "brier")
            ]
            print(f"| {kind} | {made} | {replayed} | " + " | ".join(cells) + " |")
    else:
        print("| what | value |\n|---|---|")
        for key, v in result.items():
            print(f"| {key} | {v:.3g} |")
    print(
        f"\n{datetime.date.today()}, Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, "
        f"load {load0:.2f} -> {os.getloadavg()[0]:.2f}, {args.units} units x "
        f"{args.duration:g} s, wall {time.perf_counter() - start:.0f} s"
    )
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
