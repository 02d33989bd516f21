#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""The documentation's pictures, made by running the real commands (doc/images/*.png).

    .venv/bin/python tools/doc_figures.py [--out doc/images] [--keep DIR]   # ~2 min on 2 cores

1. the replay's report of a synthetic seat-adjuster log (`bag.synthetic`: two 12 s strokes
   with rests, 100 Hz, nut position published): `leadscrew-squeak replay LOG --out DIR`
   -> report_timeline.png, report_map.png, report_frequency.png;
2. a stability map with P(squeak): `leadscrew-squeak map --x speed_rad_s:1:100:80
   --y load_n:5:600:60 --probability --plot stability_map.png`;
3. a small fleet review (five synthetic logs of different strokes, loads and seeds, each with
   a unit id in its `leadscrew_ros` metadata record; 1 worker):
   `leadscrew-squeak review LOGS --out DIR --workers 1` -> fleet.png;
4. a virtual-bench unit heard: `leadscrew-squeak bench --units 1 --out BENCH`, then
   `leadscrew-squeak replay BENCH/LOG --out DIR` -> listening_timeline.png (the replay's
   timeline with its spectrogram panel and the heard episodes);
5. a small virtual-bench fleet calibrated: `leadscrew-squeak bench` of `CALIBRATION_BENCH`
   (the population of doc/user/calibration.md's example, `calibration_example.POPULATION`),
   then `leadscrew-squeak calibrate BENCH --out DIR --workers 1` -> calibration.png.

The PNGs are written smaller (palette PNG, at most `MAX_BYTES` each) so that they can live in
git. doc/images/transient.png comes from tools/transient_table.py --plot (about 5 min),
doc/images/listening_realistic.png from tools/listening_realistic.py --image.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "doc" / "images"
MAX_BYTES = 300_000
CALIBRATION_BENCH = ["--units", "6", "--duration", "6", "--seed", "11"]
MAP_ARGS = ["map", "--x", "speed_rad_s:1:100:80", "--y", "load_n:5:600:60", "--probability"]


def _cli(*args: str, ok: tuple[int, ...] = (0,)) -> None:
    """Run `leadscrew-squeak ARGS` of this checkout in a child process (as a user would); an
    exit status not in `ok` is an error."""
    env = {
        **os.environ,
        "MPLBACKEND": "Agg",
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    cmd = [sys.executable, "-m", "leadscrew_ros.cli", *args]
    print("$ leadscrew-squeak " + " ".join(args), file=sys.stderr)
    done = subprocess.run(cmd, env=env, cwd=ROOT, stdout=subprocess.DEVNULL)
    if done.returncode not in ok:
        raise subprocess.CalledProcessError(done.returncode, cmd)


def _small(src: Path, dst: Path) -> None:
    """Copy PNG `src` to `dst` as a palette PNG (256 colours), halving the size until it is at
    most `MAX_BYTES`."""
    from PIL import Image

    image = Image.open(src).convert("RGB")
    while True:
        image.quantize(256, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)
        if dst.stat().st_size <= MAX_BYTES:
            break
        image = image.resize((image.width * 3 // 4, image.height * 3 // 4), Image.LANCZOS)
    print(
        f"{dst.relative_to(ROOT) if dst.is_relative_to(ROOT) else dst}: "
        f"{dst.stat().st_size // 1000} kB",
        file=sys.stderr,
    )


def _logs(work: Path) -> list[Path]:
    """Synthetic seat-adjuster logs: the report's (first) and the fleet's, each with a
    `leadscrew_ros` metadata record naming its drive (the fleet's rows)."""
    from leadscrew_ros.bag import logmeta
    from leadscrew_ros.bag.synthetic import DutyCycle, write_log
    from leadscrew_ros.live.profile import StrokeProfile
    from leadscrew_ros.model import ScrewParameters

    strokes = [
        StrokeProfile(),
        StrokeProfile(peak_speed_rad_s=40.0),
        StrokeProfile(load_min_n=40.0, load_max_n=90.0, peak_speed_rad_s=100.0),
        StrokeProfile(load_min_n=200.0, load_max_n=500.0),
        StrokeProfile(load_min_n=2.0, load_max_n=6.0),
    ]  # too light to squeak
    logs = []
    for i, stroke in enumerate(strokes):
        record = logmeta.LogMetadata(
            params=ScrewParameters().as_dict(), unit_id=f"seat-{i + 1:04d}"
        )
        logs.append(
            write_log(
                DutyCycle(
                    duration_s=60.0, rest_s=18.0, stroke=stroke, seed=i, nut_position_topic=True
                ),
                work / "logs" / f"seat_{i}",
                metadata={logmeta.RECORD_NAME: record.record()},
            )
        )
    return logs


def _bench_logs(bench: Path) -> list[Path]:
    """The logs of a `leadscrew-squeak bench` output directory (its truth.json's order)."""
    truth = json.loads((bench / "truth.json").read_text(encoding="utf-8"))
    return [bench / unit["log"] for unit in truth["units"]]


def _listening(work: Path, out: Path) -> None:
    """listening_timeline.png: the replay of one virtual-bench unit, heard."""
    bench = work / "bench_one"
    _cli("bench", "--units", "1", "--out", str(bench), "--quiet")
    listen = work / "listening"
    _cli("replay", str(_bench_logs(bench)[0]), "--out", str(listen), "--quiet")
    _small(listen / "timeline.png", out / "listening_timeline.png")


def _calibration(work: Path, out: Path) -> None:
    """calibration.png of a small virtual-bench fleet (exit status 3, not converged, is a
    picture too: it is drawn the same way)."""
    from calibration_example import POPULATION

    bench = work / "bench_fleet"
    population = [f"--population={k}={v:g}" for k, v in POPULATION.items()]
    _cli("bench", *CALIBRATION_BENCH, *population, "--out", str(bench), "--quiet")
    result = work / "calibration"
    _cli("calibrate", str(bench), "--out", str(result), "--workers", "1", "--quiet", ok=(0, 3, 4))
    _small(result / "calibration.png", out / "calibration.png")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help="directory of the PNGs")
    parser.add_argument("--keep", type=Path, help="keep the logs and reviews here")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="doc_figures_")) if args.keep is None else args.keep
    work.mkdir(parents=True, exist_ok=True)
    try:
        logs = _logs(work)
        replay = work / "replay"
        _cli("replay", str(logs[0]), "--out", str(replay), "--quiet")
        for name, target in (
            ("timeline", "report_timeline"),
            ("map_speed_load", "report_map"),
            ("frequency_vs_speed", "report_frequency"),
        ):
            _small(replay / f"{name}.png", args.out / f"{target}.png")
        _cli(*MAP_ARGS, "--plot", str(work / "stability_map.png"))
        _small(work / "stability_map.png", args.out / "stability_map.png")
        fleet = work / "fleet"
        _cli(
            "review",
            *map(str, logs),
            "--out",
            str(fleet),
            "--workers",
            "1",
            "--no-report",
            "--quiet",
        )
        _small(fleet / "fleet.png", args.out / "fleet.png")
        _listening(work, args.out)
        _calibration(work, args.out)
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
