# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak listen FILE.wav` (a recording without a log) and `--background` (issue
30, items 1 and 7): with nothing moving a steady tone is background, not squeak, and a growing
tone is squeak; WAV formats and channels; one-line errors; a speed CSV learns the background
while the drive is off and the drive's orders; a background recording (WAV or log) is learned
first, on `listen` and on `replay`; without motor-off time the background is inferred and
`background_source` says so."""

from __future__ import annotations

import json
import wave
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from leadscrew_ros.bag import audiomsgs, cdr
from leadscrew_ros.bag.audio import read_audio
from leadscrew_ros.bag.logsource import open_log
from leadscrew_ros.bag.recorder import Recorder, RecordSettings
from leadscrew_ros.bag.synthetic import SPEED_TOPIC
from leadscrew_ros.bag.virtual_bench import MIC_INFO_TOPIC, BenchSettings, run
from leadscrew_ros.cli import main
from leadscrew_ros.model.acoustics import DetectorSettings, detect
from leadscrew_ros.review.recording import SPEED_CSV_HEADER

RATE = 48000
TONES_HZ = (440.0, 1000.0, 3150.0)  # steady tones of the synthetic recordings
SQUEAK_HZ = 2200.0


def _stationary(seconds: float = 6.0, seed: int = 3) -> np.ndarray:
    """Steady tones in white noise (ECMA-418-1 style tone-in-noise test signals)."""
    t = np.arange(int(seconds * RATE)) / RATE
    rng = np.random.default_rng(seed)
    x = 0.01 * rng.standard_normal(t.size)
    for k, f in enumerate(TONES_HZ):
        x += (0.05 / (k + 1)) * np.sin(2 * np.pi * f * t + k)
    return x


def _growing(seconds: float = 6.0, start_s: float = 3.0) -> np.ndarray:
    """A tone growing exponentially (40 dB in 0.9 s) from `start_s`, then saturating."""
    t = np.arange(int(seconds * RATE)) / RATE
    envelope = np.clip(1e-3 * np.exp(5.0 * (t - start_s)), 0.0, 0.1) * (t >= start_s)
    return envelope * np.sin(2 * np.pi * SQUEAK_HZ * t)


def _listen(capsys, *args) -> tuple[int, dict, str]:
    """Run `listen ... --json`: (exit code, heard.json printed, stderr)."""
    code = main(["listen", *map(str, args), "--json"])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if code == 0 else {}), err


def _near(f: float, freqs) -> bool:
    return any(abs(f / g - 1) < 0.02 for g in freqs)


def test_steady_tones_are_background_and_a_growing_tone_is_squeak(tmp_path, capsys):
    steady = tmp_path / "steady.wav"
    wavfile.write(steady, RATE, _stationary().astype(np.float32))
    code, heard, _ = _listen(capsys, steady, "--out", tmp_path / "a")
    assert code == 0
    assert heard["episodes"] == []
    assert heard["background_source"] == "inferred"
    assert all(_near(f, [b["frequency_hz"] for b in heard["background"]]) for f in TONES_HZ)
    assert {"frequency_hz", "level_db"} <= set(heard["background"][0])
    assert heard["usable_s"] > 5.0 and heard["unusable_s"] == 0.0
    assert heard["drive_orders"] == []
    out = tmp_path / "a"
    assert sorted(p.name for p in out.iterdir()) == ["heard.json", "spectrogram.png", "summary.txt"]
    assert json.loads((out / "heard.json").read_text()) == heard
    assert "background inferred" in (out / "summary.txt").read_text()

    grown = tmp_path / "grown.wav"
    wavfile.write(grown, RATE, (_stationary() + _growing()).astype(np.float32))
    code, heard, _ = _listen(capsys, grown, "--out", tmp_path / "b")
    assert code == 0
    [episode] = heard["episodes"]
    assert episode["frequency_hz"] == pytest.approx(SQUEAK_HZ, rel=0.02)
    assert 3.0 <= episode["start_s"] <= 3.9 and episode["end_s"] > 5.5
    assert not _near(SQUEAK_HZ, [b["frequency_hz"] for b in heard["background"]])


def _write_24bit(path: Path, x: np.ndarray) -> None:
    """A 24-bit PCM WAV by the stdlib `wave` (scipy writes no 24-bit)."""
    q = np.round(np.clip(x, -1, 1 - 2**-23) * 2**23).astype("<i4")
    raw = q.view(np.uint8).reshape(-1, 4)[:, :3].tobytes()
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(3)
        w.setframerate(RATE)
        w.writeframes(raw)


@pytest.mark.parametrize("kind", ["int16", "int32", "int24", "float32", "stereo"])
def test_wav_formats_and_channels_give_the_same_hearing(tmp_path, capsys, kind):
    x = 0.5 * (_stationary(4.0) + _growing(4.0, 1.5))
    path = tmp_path / f"{kind}.wav"
    extra: list[str] = []
    if kind == "int16":
        wavfile.write(path, RATE, np.round(x * 32767).astype(np.int16))
    elif kind == "int32":
        wavfile.write(path, RATE, np.round(x * 2**31).astype(np.int32))
    elif kind == "int24":
        _write_24bit(path, x)
    elif kind == "float32":
        wavfile.write(path, RATE, x.astype(np.float32))
    else:  # the squeak on the second channel only: --channel 1 hears it, channel 0 does not
        wavfile.write(path, RATE, np.c_[0.5 * _stationary(4.0), x].astype(np.float32))
        code, first, _ = _listen(capsys, path, "--out", tmp_path / "first")
        assert code == 0 and first["channel"] == 0 and first["channels"] == 2
        assert first["episodes"] == []
        assert "channel 0 of 2" in (tmp_path / "first" / "summary.txt").read_text()
        extra = ["--channel", "1"]
    code, heard, _ = _listen(capsys, path, "--out", tmp_path / "o", *extra)
    assert code == 0
    [episode] = heard["episodes"]
    assert episode["frequency_hz"] == pytest.approx(SQUEAK_HZ, rel=0.02)
    assert episode["level_db"] == pytest.approx(20 * np.log10(0.05 / np.sqrt(2)), abs=1.5)
    assert all(_near(f, [b["frequency_hz"] for b in heard["background"]]) for f in TONES_HZ)


@pytest.mark.parametrize(
    "make, args, message",
    [
        (None, ["missing.wav"], "missing.wav: no such file"),
        (lambda d: (d / "x.wav").mkdir(), ["x.wav"], "a directory, not a WAV file"),
        (lambda d: (d / "x.wav").write_bytes(b"junk"), ["x.wav"], "not a readable WAV file"),
        (None, ["ok.wav", "--speed-csv", "none.csv"], "--speed-csv none.csv: no such file"),
        (
            lambda d: (d / "s.csv").write_text("t,v\n0,1\n"),
            ["ok.wav", "--speed-csv", "s.csv"],
            "the first line must be time_s,speed_rad_s",
        ),
        (
            lambda d: (d / "s.csv").write_text("time_s,speed_rad_s\n0,1\n1,x\n"),
            ["ok.wav", "--speed-csv", "s.csv"],
            "line 3 is not two finite numbers",
        ),
        (
            lambda d: (d / "s.csv").write_text("time_s,speed_rad_s\n0,1\n0,2\n"),
            ["ok.wav", "--speed-csv", "s.csv"],
            "time_s does not increase at line 3",
        ),
        (None, ["ok.wav", "--background", "nothing.wav"], "--background nothing.wav: no such"),
        (
            lambda d: (d / "bg.wav").write_bytes(b"junk"),
            ["ok.wav", "--background", "bg.wav"],
            "not a readable WAV file",
        ),
        (None, ["ok.wav", "--channel", "3"], "channel 3 asked of a mono WAV"),
        (None, ["ok.wav", "--listen-param", "frame_s=2"], "listen.frame_s"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, monkeypatch, make, args, message):
    monkeypatch.chdir(tmp_path)
    wavfile.write(tmp_path / "ok.wav", RATE, _stationary(1.0).astype(np.float32))
    if make is not None:
        make(tmp_path)
    assert main(["listen", *args, "--out", "o"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("leadscrew-squeak: error: ") and message in err, err
    assert err.count("\n") == 1


def _driven(tmp_path: Path, ratio: float = 100.0) -> tuple[Path, Path, np.ndarray]:
    """A drive: 1.5 s at rest, a speed ramp 10 -> 30 rad/s for 5 s, 1 s at rest; a fan tone
    all along and a drive tone at `ratio` x the screw's rotation frequency while it moves.
    Returns the WAV, the speed CSV and the samples."""
    seconds = 7.5
    t = np.arange(int(seconds * RATE)) / RATE
    speed = np.where((t >= 1.5) & (t < 6.5), 10.0 + 4.0 * (t - 1.5), 0.0)
    phase = 2 * np.pi * np.cumsum(ratio * speed / (2 * np.pi)) / RATE
    rng = np.random.default_rng(5)
    x = 0.005 * rng.standard_normal(t.size) + 0.03 * np.sin(2 * np.pi * 1170.0 * t)
    x += 0.02 * (speed > 0) * np.sin(phase)
    wav, csv = tmp_path / "drive.wav", tmp_path / "speed.csv"
    wavfile.write(wav, RATE, x.astype(np.float32))
    step = RATE // 100
    rows = "\n".join(f"{a:.4f},{v:.4f}" for a, v in zip(t[::step], speed[::step], strict=True))
    csv.write_text(",".join(SPEED_CSV_HEADER) + "\n" + rows + "\n")
    return wav, csv, x


def test_speed_csv_learns_the_background_at_rest_and_the_drive_ratio(tmp_path, capsys):
    wav, csv, _ = _driven(tmp_path)
    code, heard, _ = _listen(capsys, wav, "--speed-csv", csv, "--out", tmp_path / "o")
    assert code == 0
    assert heard["background_source"] == "motor-off"
    assert _near(1170.0, [b["frequency_hz"] for b in heard["background"]])
    assert any(abs(o["ratio"] / 100.0 - 1) < 0.01 for o in heard["drive_orders"])
    assert heard["episodes"] == []
    assert heard["speed_file"] == str(csv)


def test_a_background_recording_is_learned_first(tmp_path, capsys):
    """A fan heard only while the drive moves (no rest in the recording): the background
    WAV (the fan alone, at another sample rate) makes it background ('file')."""
    t = np.arange(4 * RATE) / RATE
    rng = np.random.default_rng(8)
    fan = 0.03 * np.sin(2 * np.pi * 1170.0 * t)
    # on 1.5 of the 4 s (38 %: under `background_infer_share`, no inference; "> 0.2" would be
    # on for 50.3 % of these 4 s, the share of its frames then on either side of one half)
    fan_bursts = fan * (np.sin(2 * np.pi * 0.3 * t) > 0.5)
    wav = tmp_path / "rec.wav"
    wavfile.write(wav, RATE, (0.005 * rng.standard_normal(t.size) + fan_bursts).astype("f4"))
    bg = tmp_path / "fan.wav"
    t44 = np.arange(2 * 44100) / 44100
    wavfile.write(
        bg,
        44100,
        (0.005 * rng.standard_normal(t44.size) + 0.03 * np.sin(2 * np.pi * 1170.0 * t44)).astype(
            "f4"
        ),
    )
    code, alone, _ = _listen(capsys, wav, "--out", tmp_path / "a")
    assert code == 0 and _near(1170.0, [e["frequency_hz"] for e in alone["episodes"]])
    code, heard, _ = _listen(capsys, wav, "--background", bg, "--out", tmp_path / "b")
    assert code == 0
    assert heard["background_source"] == "file" and heard["episodes"] == []
    assert heard["background_file"] == str(bg.resolve())
    assert _near(1170.0, [b["frequency_hz"] for b in heard["background"]])


def test_inference_holds_on_each_side_of_the_condition():
    """A tone held over 70 % of the recording, but only where the condition (the prediction)
    holds: inferred as background without the condition, squeak with it."""
    x = _stationary(5.0)
    t = np.arange(x.size) / RATE
    x = x + 0.05 * (t >= 1.5) * np.sin(2 * np.pi * SQUEAK_HZ * t)
    settings = DetectorSettings()
    plain = detect(x.astype(np.float32), RATE, settings=settings, infer_background=True)
    assert plain.background_source == "inferred"
    assert _near(SQUEAK_HZ, [b.frequency_hz for b in plain.background])
    assert not plain.episodes
    cond = detect(
        x.astype(np.float32),
        RATE,
        settings=settings,
        condition_times_s=[0.0, 1.5],
        condition=[False, True],
        infer_background=True,
    )
    assert cond.background_source == "inferred"
    assert not _near(SQUEAK_HZ, [b.frequency_hz for b in cond.background])
    assert _near(SQUEAK_HZ, [e.frequency_hz for e in cond.episodes])
    assert _near(1000.0, [b.frequency_hz for b in cond.background])


def test_nothing_to_learn_from_is_none():
    """Shorter than a frame; or a bare call (the node's way: every steady tone is heard)."""
    d = detect(np.zeros(100, np.float32), RATE, infer_background=True)
    assert d.background_source == "none" and d.background == []
    d = detect(_stationary(2.0).astype(np.float32), RATE)
    assert d.background_source == "none" and d.background == []
    assert {round(e.frequency_hz) for e in d.episodes} == {round(f) for f in TONES_HZ}


# ---------------------------------------------------------------- replay --background
def _cut_rest(bag: Path, out_dir: Path, keep: tuple[int, int]) -> Path:
    """`bag` written again with only the messages logged within `keep` [ns] (the microphone's
    latched info always): the motor-off stretches cut off."""
    source = open_log(bag)
    rec = Recorder(
        RecordSettings(
            directory=str(out_dir), split_size_mb=0.0, split_duration_s=0.0, compression="none"
        ),
        name="cut",
        schemas={n: audiomsgs.definition(n) for n in audiomsgs.TEXTS[audiomsgs.DRIVERS]},
    )
    messages = [m for _, m in source.messages()]
    assert rec.start(keep[0])
    for m in messages:
        if m.topic.name == MIC_INFO_TOPIC:
            rec.write_serialized(
                m.topic.name, m.topic.type_name, m.data, max(m.log_time_ns, keep[0])
            )
        elif keep[0] <= m.log_time_ns <= keep[1]:
            rec.write_serialized(m.topic.name, m.topic.type_name, m.data, m.log_time_ns)
    rec.stop()
    assert not rec.error, rec.error
    return rec.bag


@pytest.fixture(scope="module")
def cut_bench(tmp_path_factory):
    """A realistic bench unit (fan 1170 Hz, mains hum) whose motor-off stretches are cut off,
    and the cut-off start as a background WAV: (cut log, background WAV, background tones)."""
    d = tmp_path_factory.mktemp("cut")
    truth = run(BenchSettings(units=1, duration_s=6.0, seed=44, realistic=True), d / "bench")
    log = d / "bench" / truth["units"][0]["log"]
    messages = [m for _, m in open_log(log).messages()]
    moving = [
        m.log_time_ns
        for m in messages
        if m.topic.name == SPEED_TOPIC
        and abs(cdr.decode_float64(m.data)) >= DetectorSettings().motor_off_rad_s
    ]
    margin_ns = int(0.2e9)  # under motor_off_min_s: no rest stretch is left
    cut = _cut_rest(log, d / "cut", (moving[0] + margin_ns, moving[-1] - margin_ns))
    track = read_audio(log)
    rest_s = (moving[0] - messages[0].log_time_ns) / 1e9
    i = int((rest_s - 0.1 - track.t0_s) * track.sample_rate_hz)
    background = d / "background.wav"
    wavfile.write(background, int(track.sample_rate_hz), track.samples[:i])
    return cut, background, truth["sound"]["background_tones_hz"]


def _replayed(capsys, log, out, *args) -> dict:
    assert main(["replay", str(log), "--out", str(out), "--quiet", "--no-report", *args]) == 0
    capsys.readouterr()
    return json.loads((out / "summary.json").read_text())["heard"]


def test_replay_with_a_background_recording_hears_no_fan(cut_bench, tmp_path, capsys):
    cut, background, tones = cut_bench
    heard = _replayed(capsys, cut, tmp_path / "bg", "--background", str(background))
    assert heard["background_source"] == "file"
    learned = [b["frequency_hz"] for b in heard["background"]]
    assert _near(1170.0, learned) and 1170.0 in tones
    assert not [e for e in heard["episodes"] if _near(e["frequency_hz"], tones)], heard["episodes"]
    summary = (tmp_path / "bg" / "summary.txt").read_text()
    assert "background learned from the background recording" in summary

    inferred = _replayed(capsys, cut, tmp_path / "inf")
    assert inferred["background_source"] == "inferred"
    assert _near(1170.0, [b["frequency_hz"] for b in inferred["background"]])
    assert "background inferred" in (tmp_path / "inf" / "summary.txt").read_text()


def test_a_log_as_background_recording(cut_bench, tmp_path, capsys):
    """--background LOG: the log's audio (here the cut log itself on its own WAV)."""
    cut, background, _ = cut_bench
    code, heard, _ = _listen(capsys, background, "--background", cut, "--out", tmp_path / "o")
    assert code == 0 and heard["background_source"] == "file"
    assert heard["background_file"] == str(Path(cut).resolve())


def test_listen_takes_the_detector_settings_of_the_params_file(tmp_path, capsys):
    """listen.* of --params-file, as the node reads them, and --listen-param over them: no
    tone can be held by more than all frames (share 1), so nothing is inferred and every
    steady tone is heard."""
    steady = tmp_path / "steady.wav"
    wavfile.write(steady, RATE, _stationary(3.0).astype(np.float32))
    params = tmp_path / "p.yaml"
    params.write_text(
        "squeak_node:\n  ros__parameters:\n    listen:\n      background_infer_share: 1\n"
    )
    code, heard, _ = _listen(capsys, steady, "--params-file", params, "--out", tmp_path / "a")
    assert code == 0 and heard["detector"]["background_infer_share"] == 1.0
    assert heard["background"] == [] and heard["background_source"] == "inferred"
    assert {round(e["frequency_hz"], -1) for e in heard["episodes"]} == {
        round(f, -1) for f in TONES_HZ
    }
    code, heard, _ = _listen(
        capsys,
        steady,
        "--params-file",
        params,
        "--listen-param",
        "background_infer_share=0.5",
        "--out",
        tmp_path / "b",
    )
    assert code == 0 and heard["episodes"] == [] and len(heard["background"]) == len(TONES_HZ)


@pytest.mark.parametrize("command", ["replay", "review", "calibrate", "listen"])
def test_every_listening_command_takes_background_and_refuses_a_missing_one(
    tmp_path, capsys, command
):
    wavfile.write(tmp_path / "ok.wav", RATE, _stationary(1.0).astype(np.float32))
    source = tmp_path / "ok.wav" if command == "listen" else tmp_path
    code = main([command, str(source), "--out", str(tmp_path / "o"), "--background", "gone.wav"])
    err = capsys.readouterr().err
    assert (
        code == 2
        and err == "leadscrew-squeak: error: --background gone.wav: no such file or directory\n"
    )


def test_a_tone_switched_on_again_and_again_is_one_background_tone():
    """With nothing moving, a tone switched on and off (each time a step, not a growth) is
    background: one tone with the shares of its stretches added, not one per stretch (a
    5-min file listed "1000 Hz (-29 dB)" 15 times)."""
    fs = 16000.0
    t = np.arange(int(60 * fs)) / fs
    x = 0.003 * np.random.default_rng(3).standard_normal(t.size)
    x += 0.05 * np.sin(2 * np.pi * 1000.0 * t) * ((t % 20.0) > 15.0)
    d = detect(x.astype(np.float32), fs, infer_background=True)
    assert d.episodes == []
    [tone] = d.background
    assert tone.frequency_hz == pytest.approx(1000.0, rel=0.005)
    assert tone.share == pytest.approx(0.25, abs=0.03)
