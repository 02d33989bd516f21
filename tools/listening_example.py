# SPDX-License-Identifier: Apache-2.0
"""Numbers for doc/user/listening.md: one virtual-bench unit replayed with its sound, from the
three inputs, calibrated, and with both formulations compared.

    .venv/bin/python tools/listening_example.py

Makes `leadscrew-squeak bench --units 1 --duration 12 --seed 0` in a temp directory and
replays its log (the CLI, no report) (1) from its AudioDataStamped + AudioInfo topics, (2)
rewritten with the microphone as std_msgs/Float32MultiArray, given --audio-rate, (3) without
audio topics and the microphone as a WAV file beside it, --audio/--audio-start; then (1) again
calibrated (--audio-scale, the bench's Pa per full scale) with --compare-formulations. Prints
the page's Markdown between its `listening_example` markers (test_heard checks the page has
it); the log and WAV conversions are the tests' (test/harness/audio_logs.py).
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

from harness.audio_logs import as_float32_multi_array, with_wav_beside  # noqa: E402
from leadscrew_ros.bag.virtual_bench import BenchSettings, run  # noqa: E402
from leadscrew_ros.cli import main as cli  # noqa: E402

BENCH = BenchSettings(units=1, duration_s=12.0, seed=0)


def _replay(log: Path, out: Path, *options: str) -> dict:
    with contextlib.redirect_stdout(io.StringIO()):
        code = cli(
            [
                "replay",
                str(log),
                "--out",
                str(out),
                "--no-report",
                "--quiet",
                "--workers",
                "0",
                *options,
            ]
        )
    assert code == 0, code
    return json.loads((out / "summary.json").read_text())


def _row(name: str, options: str, heard: dict) -> str:
    a = heard["agreement"]
    freqs = ", ".join(f"{e['frequency_hz']:.0f}" for e in heard["episodes"])
    return (
        f"| {name} | `{options}` | {len(heard['episodes'])} ({freqs} Hz) | "
        f"{a['recall']:.3f} | {a['precision']:.3f} | {a['brier']:.4f} |"
    )


def example(tmp: Path) -> str:
    """The page's Markdown."""
    truth = run(BENCH, tmp / "bench")
    unit = truth["units"][0]
    log = tmp / "bench" / unit["log"]
    scale = truth["audio"]["audio_scale_pa_per_fs"]
    rows = [
        _row(
            "AudioDataStamped + AudioInfo",
            "(none: the only audio topic)",
            _replay(log, tmp / "r1")["heard"],
        )
    ]
    array = as_float32_multi_array(log, tmp / "f32")
    rows.append(
        _row(
            "Float32MultiArray",
            "--audio-rate 48000",
            _replay(array, tmp / "r2", "--audio-rate", "48000")["heard"],
        )
    )
    bag, wav, start = with_wav_beside(log, tmp / "wav")
    rows.append(
        _row(
            "WAV beside the log",
            f"--audio <bag>/microphone.wav --audio-start {start:g}",
            _replay(bag, tmp / "r3", "--audio", str(wav), "--audio-start", f"{start!r}")["heard"],
        )
    )
    s = _replay(log, tmp / "r4", "--audio-scale", f"{scale:.4g}", "--compare-formulations")
    text = (tmp / "r4" / "summary.txt").read_text().splitlines()
    heard_lines = [
        line
        for line in text
        if line.startswith(("heard", "background", "levels", "paper ", "consistent "))
    ]
    first = s["heard"]["episodes"][0]
    episode = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in first.items()}
    agreement = {
        k: (round(v, 4) if isinstance(v, float) else v)
        for k, v in s["heard"]["agreement"].items()
        if k != "frequency_match"
    }
    match = {
        k: (round(v, 5) if isinstance(v, float) else v)
        for k, v in s["heard"]["agreement"]["frequency_match"][0].items()
    }
    truth_line = ", ".join(
        f"{i['start_s']:.2f}-{i['end_s']:.2f} s ({i['min_hz']:.0f}-{i['max_hz']:.0f} Hz)"
        for i in unit["squeak_intervals"]
    )
    return "\n".join(
        [
            f"The unit squeaks (truth.json, its own model): {truth_line}; the bench's scale is "
            f"{scale:.4g} Pa per full-scale unit.",
            "",
            "| input | replay options | heard episodes | recall | precision | Brier |",
            "|---|---|---|---:|---:|---:|",
            *rows,
            "",
            f"Calibrated (`--audio-scale {scale:.4g} --compare-formulations`), summary.txt says:",
            "",
            "```text",
            *heard_lines,
            "```",
            "",
            "and summary.json's `heard` holds, among the rest, the first episode",
            "",
            "```json",
            json.dumps(episode),
            "```",
            "",
            "the agreement (`frequency_match` aside)",
            "",
            "```json",
            json.dumps(agreement),
            "```",
            "",
            "and the first episode's frequency match",
            "",
            "```json",
            json.dumps(match),
            "```",
        ]
    )


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="listening_example_") as tmp:
        print(example(Path(tmp)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
