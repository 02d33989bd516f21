# SPDX-License-Identifier: Apache-2.0
"""Numbers and picture for doc/user/listening.md's worked example on a realistic bench.

    .venv/bin/python tools/listening_realistic.py [--image doc/images/listening_realistic.png]

Makes `leadscrew-squeak bench --realistic --units 1 --seed 77` in a temp directory (a fan, mains
hum and its harmonics, pink noise, a worm-geared motor with its 2nd order and commutator, a
room, the squeak grown from the floor), writes the unit's microphone as a WAV file and its
speed as a CSV beside it, and runs `leadscrew-squeak listen unit.wav --speed-csv speed.csv
--out heard`. Prints the page's Markdown between its `listening_realistic` markers (test_heard
checks the page has it); `--image` also writes the listen's spectrogram.png there, made
smaller as tools/doc_figures.py makes the others.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.io import wavfile

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

from leadscrew_ros.bag.audio import read_audio  # noqa: E402
from leadscrew_ros.bag.cdr import decode_float64  # noqa: E402
from leadscrew_ros.bag.logsource import open_log  # noqa: E402
from leadscrew_ros.bag.synthetic import SPEED_TOPIC  # noqa: E402
from leadscrew_ros.cli import main as cli  # noqa: E402
from leadscrew_ros.model.acoustics.bench_sound import envelope_growth  # noqa: E402

BENCH = ["--units", "1", "--seed", "77", "--realistic"]


def listened(tmp: Path) -> tuple[dict, Path]:
    """(the bench's truth, the listen's output directory) of the example."""
    with contextlib.redirect_stdout(io.StringIO()):
        assert cli(["bench", "--out", str(tmp / "bench"), *BENCH, "--quiet"]) == 0
    truth = json.loads((tmp / "bench" / "truth.json").read_text())
    log = next((tmp / "bench").glob(truth["units"][0]["log"] + "*"))
    track = read_audio(log)
    wavfile.write(tmp / "unit.wav", int(track.sample_rate_hz), np.asarray(track.samples))
    t, v, first = [], [], None
    for _, m in open_log(log).messages():
        first = m.log_time_ns if first is None else first
        if m.topic.name == SPEED_TOPIC:  # times from the WAV's first sample
            t.append((m.log_time_ns - first) * 1e-9 - track.t0_s)
            v.append(decode_float64(m.data))
    rows = [f"{a:.6f},{b:.6f}" for a, b in zip(t, v, strict=True)]
    (tmp / "speed.csv").write_text("\n".join(["time_s,speed_rad_s", *rows]) + "\n")
    with contextlib.redirect_stdout(io.StringIO()):
        args = [str(tmp / "unit.wav"), "--speed-csv", str(tmp / "speed.csv")]
        assert cli(["listen", *args, "--out", str(tmp / "heard")]) == 0
    return truth, tmp / "heard"


def example(tmp: Path, image: Path | None = None) -> str:
    """The page's Markdown (and the picture, given `image`)."""
    truth, heard = listened(tmp)
    if image is not None:
        from doc_figures import _small

        _small(heard / "spectrogram.png", image)
    sound, unit = truth["sound"], truth["units"][0]["sound"]
    audible = ", ".join(
        f"{a['start_s']:.2f}-{a['end_s']:.2f} s ({a['min_hz']:.0f}-{a['max_hz']:.0f} Hz)"
        for a in unit["audible_intervals"]
    )
    tones = ", ".join(f"{f:g}" for f in sound["background_tones_hz"])
    orders = ", ".join(f"{r:g}" for r in sound["drive_orders"])
    return "\n".join(
        [
            f"The bench's truth (truth.json): background tones at {tones} Hz, drive orders at "
            f"{orders} times the screw's rotation, the squeak audible {audible}.",
            "",
            "summary.txt says:",
            "",
            "```text",
            *(heard / "summary.txt").read_text().rstrip("\n").splitlines(),
            "```",
            "",
            "and heard.json's episodes:",
            "",
            "| start [s] | end [s] | frequency [Hz] | growth at the onset [1/s] | the truth's "
            "envelope over its window [1/s] | harmonics [Hz] |",
            "|---:|---:|---:|---:|---:|---|",
            *(_row(e, unit) for e in json.loads((heard / "heard.json").read_text())["episodes"]),
        ]
    )


def _row(e: dict, unit: dict) -> str:
    """One episode of heard.json against the bench's truth, as a table row."""
    grew = e["growth_rate_per_s"] is not None
    true = (
        envelope_growth(unit["envelope_dbfs"], unit["envelope_rate_hz"], e["growth_window_s"])
        if grew
        else None
    )
    return (
        f"| {e['start_s']:.3f} | {e['end_s']:.3f} | {e['frequency_hz']:.1f} | "
        + (
            f"{e['growth_rate_per_s']:.1f} ± {e['growth_rate_se']:.1f}"
            if grew
            else e["growth_reason"]
        )
        + f" | {'' if true is None else f'{true:.1f}'}"
        + f" | {', '.join(f'{h:.0f}' for h in e['harmonics_hz']) or 'none'} |"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--image", type=Path, help="write the spectrogram here")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="listening_realistic_") as tmp:
        print(example(Path(tmp), args.image))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
