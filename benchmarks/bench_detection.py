# SPDX-License-Identifier: Apache-2.0
"""Benchmark of the squeak detector: x real time of 48 kHz mono on one core.

    .venv/bin/python benchmarks/bench_detection.py [--rounds N] [--seconds S]

The signal is a simulated bench stroke (`acoustics.synthesis.microphone`): the speed ramps
20 -> 300 rad/s and back, the default motor orders, white noise, and a squeak at 2480 Hz during
the middle third. Timed: (1) `detect` of the whole signal with the speed (FFT of all frames,
tone candidates, tracking, order test; no loudness: uncalibrated); (2) `StreamingDetector.push`
of 0.1 s chunks with the speed per chunk, as the node's listening thread does; (3) of which the
short-time spectra alone (`tonality.short_time_psd`) and (4) the spectra and tone candidates
(`ToneAnalyzer.candidates`) without tracking. Then (5) `detect` and (6) the streaming push of
one unit of `leadscrew-squeak bench --realistic` (seed 77, made in a temp directory): motor-off
stretches whose background is learned (then every spectral peak through the gate is a tone
candidate), a geared motor, fan and mains hum, a room, the squeak grown from the noise floor,
offline also the growth measured at each onset: what `replay` and `listen` analyse. Each row is
the median over rounds of the signal's duration divided by the wall time. Issue 30's targets:
detection >= 100x real time (1 and 5, as `replay` and `listen` run it over a fleet's logs), and
the node's listening at most 10 % of one core (the streaming push, 2 and 6: >= 10x here; the
node's whole listening, callback and thread, is measured by bench_listen.py). The threads
of OpenBLAS and scipy.fft are limited to one (the environment variables below; scipy.fft uses
one worker unless told otherwise).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import json
import tempfile
import time
from pathlib import Path
from statistics import median

import numpy as np

from bench_realistic import speed_of
from leadscrew_ros.bag.audio import read_audio
from leadscrew_ros.cli import main as cli
from leadscrew_ros.model.acoustics import DetectorSettings, StreamingDetector, detect, microphone
from leadscrew_ros.model.acoustics.tonality import ToneAnalyzer, short_time_psd

FS = 48000
TARGET = 100.0  # x real time, offline detection
NODE_TARGET = 10.0  # x real time: the node's listening at most 10 % of one core


def stroke(seconds: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(profile times, speed, samples) of the benchmark's stroke."""
    t = np.linspace(0.0, seconds, int(seconds * 100) + 1)
    speed = np.interp(t, [0.0, seconds / 6, 5 * seconds / 6, seconds], [20.0, 300.0, 300.0, 20.0])
    sq = np.where((t >= seconds / 3) & (t < 2 * seconds / 3), 2480.0, np.nan)
    return t, speed, microphone(t, speed, sq, squeak_level=0.02, motor_level=0.3)


def realistic_unit(root: Path, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(speed times [s], speed [rad/s], samples, t0 [s]) of one unit of `bench --realistic`
    (motor-off stretches, a geared motor, fan and mains hum, a room, the squeak grown)."""
    out = root / "bench"
    if (
        cli(
            ["bench", "--out", str(out), "--units", "1", "--seed", str(seed), "--realistic"]
            + ["--quiet"]
        )
        != 0
    ):
        raise SystemExit("bench failed")
    unit = json.loads((out / "truth.json").read_text())["units"][0]
    log = next(out.glob(unit["log"] + "*"))
    track = read_audio(log)
    t, v = speed_of(log)  # from the log's first message, as the audio's times
    return t, v, np.asarray(track.samples), track.t0_s


def cases(seconds: float, root: Path) -> dict:
    t, speed, x = stroke(seconds)
    settings = DetectorSettings()
    n, hop = round(settings.frame_s * FS), round(settings.hop_s * FS)
    analyzer = ToneAnalyzer(FS, n, settings.f_lo_hz, settings.f_hi_hz, settings.max_peaks)
    chunk = FS // 10

    def offline():
        d = detect(x, FS, speed_times_s=t, speed_rad_s=speed)
        assert len(d.episodes) == 1

    def streaming():
        det = StreamingDetector(settings, FS)
        for a in range(0, x.size, chunk):
            det.push(x[a : a + chunk], a / FS, float(np.interp(a / FS, t, speed)))
        det.flush()

    def spectra():
        for a in range(0, x.size, 256 * hop):
            short_time_psd(x[a : a + 255 * hop + n], FS, n, hop)

    def candidates():
        for a in range(0, x.size, 256 * hop):
            analyzer.candidates(short_time_psd(x[a : a + 255 * hop + n], FS, n, hop))

    rt, rv, rx, r0 = realistic_unit(root, 77)

    def realistic():  # as `replay` and `listen` call it
        detect(rx, FS, t0_s=r0, speed_times_s=rt, speed_rad_s=rv, infer_background=True)

    def realistic_streaming():
        det = StreamingDetector(settings, FS)
        for a in range(0, rx.size, chunk):
            end = r0 + (a + chunk) / FS
            known = rt <= end
            det.push(rx[a : a + chunk], r0 + a / FS, rv[known], speed_times_s=rt[known])
        det.flush()

    return {
        "detect (offline, whole signal)": offline,
        "StreamingDetector.push, 0.1 s chunks": streaming,
        "… of which short-time spectra (FFT of 256-frame blocks)": spectra,
        "… of which spectra + tone candidates (TNR, PR, suppression)": candidates,
        "detect of a realistic bench unit (`bench --realistic`, seed 77: background learned "
        "at rest, every peak through its gate a candidate, growth measured; as `replay`)": (
            realistic,
            rx.size / FS,
        ),
        "StreamingDetector.push of it, 0.1 s chunks": (realistic_streaming, rx.size / FS),
    }


def run(seconds: float, rounds: int) -> dict[str, float]:
    """Median x real time of each case (a case is a function of the stroke, or a function
    and the duration of its own signal)."""
    with tempfile.TemporaryDirectory(prefix="bench_detection_") as root:
        fns = {
            k: v if isinstance(v, tuple) else (v, seconds)
            for k, v in cases(seconds, Path(root)).items()
        }
        for fn, _ in fns.values():  # warm up
            fn()
        samples: dict[str, list[float]] = {k: [] for k in fns}
        for r in range(rounds):
            for name in list(fns) if r % 2 == 0 else list(fns)[::-1]:
                fn, duration = fns[name]
                start = time.perf_counter()
                fn()
                samples[name].append(duration / (time.perf_counter() - start))
    return {k: median(v) for k, v in samples.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7, help="alternating rounds (default 7)")
    ap.add_argument("--seconds", type=float, default=20.0, help="signal duration [s] (default 20)")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    start = time.perf_counter()
    res = run(args.seconds, args.rounds)
    print("| measure | x real time (48 kHz mono, one core) |")
    print("|---|---:|")
    for i, (name, ratio) in enumerate(res.items()):
        goal = {0: TARGET, 1: NODE_TARGET, 4: TARGET, 5: NODE_TARGET}.get(i)
        target = f" (target ≥ {goal:g}×)" if goal else ""
        print(f"| {name} | {ratio:,.0f}×{target} |")
    print(
        f"\n{args.rounds} rounds of a {args.seconds:g} s stroke; {os.cpu_count()} CPUs; "
        f"load avg {load0:.2f} → {os.getloadavg()[0]:.2f}; "
        f"{time.perf_counter() - start:.0f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
