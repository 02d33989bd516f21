# SPDX-License-Identifier: Apache-2.0
"""The virtual bench (`bag.virtual_bench`, `leadscrew-squeak bench`): the truth stays in
truth.json (the logs carry the nominal parameters), the logs read with rosbags, with the
package's replay and with `read_audio`, the squeak tone is in the microphone exactly where the
unit's own model squeaks (by FFT of frames), the model along the stroke agrees with
`SqueakModel.predict`, and the same seed gives the same messages."""

import json
from pathlib import Path

import numpy as np
import pytest

from leadscrew_ros.bag import logmeta
from leadscrew_ros.bag.audio import read_audio
from leadscrew_ros.bag.logsource import open_log
from leadscrew_ros.bag.virtual_bench import (
    MIC_INFO_TOPIC,
    MIC_TOPIC,
    TRUTH,
    BenchSettings,
    draw_params,
    run,
    simulate_unit,
)
from leadscrew_ros.cli import main
from leadscrew_ros.live.settings import LiveSettings
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.acoustics.bench_sound import BenchSound
from leadscrew_ros.model.physics.parameters import ParameterError
from leadscrew_ros.model.uncertainty.scatter import Scatter

SETTINGS = BenchSettings(units=2, duration_s=12.0, seed=3)
FRAME = 4096  # 85 ms at 48 kHz


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    truth = run(SETTINGS, out)
    return out, truth


def _bag(out: Path, unit: dict) -> Path:
    return out / unit["log"]


def _messages(bag: Path):
    return [(m.topic.name, m.log_time_ns, m.data) for _, m in open_log(bag).messages()]


def test_truth_is_apart_and_the_logs_carry_the_nominal_parameters(bench):
    out, truth = bench
    assert json.loads((out / TRUTH).read_text()) == truth
    nominal = ScrewParameters(formulation="paper").as_dict()
    assert truth["nominal"] == nominal and set(truth["scatter"]) == set(Scatter().names)
    for unit in truth["units"]:
        bag = _bag(out, unit)
        files = sorted(bag.glob("*.mcap"))
        record = logmeta.read(files[0])
        assert record.params == nominal and record.unit_id == unit["unit_id"]
        assert all(unit["params"][k] != nominal[k] for k in unit["params"])
        assert {p.name for p in bag.iterdir()} == {files[0].name, "metadata.yaml"}
        assert "truth" not in (bag / "metadata.yaml").read_text()
        assert set(logmeta.read_record(files[0])) == set(logmeta.LogMetadata({}).record())
        topics = {t for t, _, _ in _messages(bag)}
        assert topics == {"/motor_speed", "/axial_load", "/nut_position", MIC_TOPIC, MIC_INFO_TOPIC}


def test_logs_read_with_rosbags(bench):
    from rosbags.highlevel import AnyReader

    out, truth = bench
    bag = _bag(out, truth["units"][0])
    counts: dict[str, int] = {}
    raw = bytearray()
    with AnyReader([bag]) as reader:
        for conn, _, data in reader.messages():
            msg = reader.deserialize(data, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            if conn.topic == MIC_TOPIC:
                raw += msg.audio.data.tobytes()
            if conn.topic == MIC_INFO_TOPIC:
                assert (msg.channels, msg.sample_rate, msg.sample_format, msg.coding_format) == (
                    1,
                    48000,
                    "S16LE",
                    "wave",
                )
    n_inputs = int(SETTINGS.duration_s * SETTINGS.input_rate_hz) + 1
    assert counts["/motor_speed"] == counts["/axial_load"] == counts["/nut_position"] == n_inputs
    assert counts[MIC_INFO_TOPIC] == 13  # at 0 s and every second to 12 s
    track = read_audio(bag)
    assert track.warnings == [] and track.t0_s == 0.0 and track.sample_rate_hz == 48000
    np.testing.assert_array_equal(
        np.frombuffer(bytes(raw), "<i2") / np.float32(32768), track.samples
    )


def test_replay_runs_on_a_bench_log(bench, tmp_path, capsys):
    out, truth = bench
    bag = _bag(out, truth["units"][0])
    assert (
        main(
            ["replay", str(bag), "--out", str(tmp_path), "--no-report", "--quiet", "--workers", "0"]
        )
        == 0
    )
    summary = json.loads((tmp_path / "summary.json").read_text())
    n_inputs = int(SETTINGS.duration_s * SETTINGS.input_rate_hz) + 1
    assert summary["input_messages"] == {
        t: n_inputs for t in ("/motor_speed", "/axial_load", "/nut_position")
    }
    assert summary["predictions"] > 0 and summary["time_in_squeak_s"] > 0
    assert summary["ignored_inputs"] == {} and summary["rejected_inputs"] == {}


def _amplitude(frame: np.ndarray, f_hz: float, fs: float) -> float:
    """Amplitude [FS] of a tone at `f_hz` in a frame (Hann window, peak within +-3 bins)."""
    w = np.hanning(frame.size)
    spectrum = np.abs(np.fft.rfft(frame * w)) * 2 / w.sum()
    k = int(round(f_hz * frame.size / fs))
    return float(spectrum[max(k - 3, 0) : k + 4].max())


def test_tone_exactly_where_the_unit_squeaks(bench):
    out, truth = bench
    for k, unit in enumerate(truth["units"]):
        track = read_audio(_bag(out, unit))
        fs = track.sample_rate_hz
        sim = _unit(k)
        squeaks = sim.squeaks
        frequencies = sorted({round(f) for f in sim.squeak_hz[squeaks]})
        # frames centred on input samples at least 60 ms from any change of the verdict or of
        # the most unstable mode
        f = np.nan_to_num(sim.squeak_hz)
        steady = np.ones(squeaks.size, bool)
        for edge in np.flatnonzero(np.diff(squeaks.astype(int)) | (np.abs(np.diff(f)) > 5)):
            steady[max(edge - 6, 0) : edge + 8] = False
        rng = np.random.default_rng(k)
        on = rng.choice(np.flatnonzero(steady & squeaks), 6, replace=False)
        off = rng.choice(np.flatnonzero(steady & ~squeaks), 6, replace=False)
        amp = BenchSettings().squeak_amplitude_fs
        for i in on.tolist() + off.tolist():
            centre = int(round(sim.times_s[i] * fs))
            frame = track.samples[max(centre - FRAME // 2, 0) :][:FRAME]
            if frame.size < FRAME:
                continue
            if squeaks[i]:
                assert _amplitude(frame, sim.squeak_hz[i], fs) > 0.6 * amp, (k, i)
            else:
                for f in frequencies:
                    assert _amplitude(frame, f, fs) < 0.1 * amp, (k, i, f)


def _unit(k: int):
    """Unit k of SETTINGS, simulated again (as `run` draws it)."""
    rng = np.random.default_rng(SETTINGS.seed)
    nominal, scatter = ScrewParameters(formulation=SETTINGS.formulation), Scatter()
    for j in range(k + 1):
        unit_rng, _ = (np.random.default_rng(s) for s in rng.integers(2**63, size=2))
        if j == k:
            return simulate_unit(SETTINGS, k, unit_rng, nominal, scatter)


def test_squeak_along_the_stroke_agrees_with_predict(bench):
    _, truth = bench
    sim = _unit(1)
    assert truth["units"][1]["params"] == {n: getattr(sim.params, n) for n in Scatter().names}
    model = SqueakModel(sim.params, Scatter({}))
    step = LiveSettings().nut_deadband_m
    for i in np.linspace(0, sim.times_s.size - 1, 25).astype(int).tolist():
        nut = round(sim.nut_position_m[i] / step) * step
        p = model.with_params(nut_position_m=nut).predict(sim.speed_rad_s[i], sim.load_n[i])
        squeaks = bool(p.valid and p.squeak_modes)
        assert squeaks == bool(sim.squeaks[i]), i
        if squeaks:
            assert sim.squeak_hz[i] == pytest.approx(p.unstable_frequencies_hz[0], rel=1e-9)


def test_same_seed_same_messages(bench, tmp_path):
    out, truth = bench
    again = run(SETTINGS, tmp_path)
    for a, b in zip(truth["units"], again["units"], strict=True):
        assert _messages(_bag(out, a)) == _messages(_bag(tmp_path, b))
        assert {**a, "log": ""} == {**b, "log": ""}
    other = run(BenchSettings(units=1, duration_s=SETTINGS.duration_s, seed=4), tmp_path / "other")
    assert other["units"][0]["params"] != truth["units"][0]["params"]


def test_cli(tmp_path, capsys):
    assert (
        main(
            [
                "bench",
                "--units",
                "1",
                "--duration",
                "3",
                "--seed",
                "1",
                "--formulation",
                "consistent",
                "--out",
                str(tmp_path / "b"),
            ]
        )
        == 0
    )
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("bench-000: bench-000_") and len(lines) == 2
    assert json.loads(lines[1])["units"] == 1
    truth = json.loads((tmp_path / "b" / TRUTH).read_text())
    assert truth["formulation"] == "consistent" and truth["seed"] == 1
    assert truth["audio"]["audio_scale_pa_per_fs"] == pytest.approx(
        20e-6 * 10 ** (94 / 20) / (0.1 / np.sqrt(2)), rel=1e-12
    )
    for argv, message in (
        (["--units", "0"], "bench.units = 0 is out of range"),
        (["--duration", "0.5"], "bench.duration_s = 0.5 is out of range"),
        (["--formulation", "x"], "invalid choice"),
    ):
        assert main(["bench", "--out", str(tmp_path / "c"), *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1


def test_a_population_other_than_the_prior(tmp_path, capsys):
    """--population / --population-scatter: the units are drawn from that population (truth's
    nominal and scatter), the logs still carry the prior (truth's prior), as a real unit's."""
    argv = ["bench", "--units", "2", "--duration", "2", "--out", str(tmp_path / "p"), "--quiet"]
    pop = ["--population", "mu_static=0.28", "--population", "modal_damping=0.002"]
    assert main([*argv, *pop, "--population-scatter", "mu_kinetic=0.1"]) == 0
    truth = json.loads((tmp_path / "p" / TRUTH).read_text())
    prior = ScrewParameters(formulation="paper")
    assert truth["prior"] == {"nominal": prior.as_dict(), "scatter": dict(Scatter().sd)}
    assert truth["nominal"] == prior.with_(mu_static=0.28, modal_damping=0.002).as_dict()
    assert truth["scatter"] == {**Scatter().sd, "mu_kinetic": 0.1}
    assert truth["settings"]["population"] == {"mu_static": 0.28, "modal_damping": 0.002}
    for unit in truth["units"]:
        record = logmeta.read(sorted((tmp_path / "p" / unit["log"]).glob("*.mcap"))[0])
        assert record.params == prior.as_dict()
        assert record.scatter == {**Scatter().sd, "samples": 1024}
    settings = BenchSettings(population={"mu_static": 0.28, "modal_damping": 0.002})
    rng = np.random.default_rng(0)
    draws = [
        draw_params(settings.population_params, settings.population_sd, rng) for _ in range(2000)
    ]
    mu_s = np.array([d.mu_static for d in draws])
    damping = np.log([d.modal_damping for d in draws])
    assert mu_s.mean() == pytest.approx(0.28, abs=4 * 0.014 / np.sqrt(2000))
    assert mu_s.std() == pytest.approx(0.05 * 0.28, rel=0.1)
    assert damping.mean() == pytest.approx(np.log(0.002), abs=4 * 0.35 / np.sqrt(2000))
    for bad, message in (
        (["--population", "radius=1"], "radius is not a scatterable parameter"),
        (["--population", "mu_kinetic=0.3"], "exceeds mu_static"),
        (["--population", "mu_static=nan"], "'nan' is not a finite number"),
        (["--population-scatter", "mu_static=2"], "scatter.mu_static = 2.0 must be a number"),
        (["--population-scatter", "mu_static"], "expected NAME=VALUE"),
    ):
        assert main([*argv, *bad]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err


def test_a_bench_is_not_written_over_another(tmp_path, capsys, monkeypatch):
    """A non-empty --out is refused (the old logs would stay beside the new truth.json under
    the same unit ids); --force empties it first; the working directory is never emptied."""
    argv = ["bench", "--units", "1", "--duration", "2", "--quiet", "--out", str(tmp_path / "b")]
    assert main([*argv, "--seed", "1"]) == 0
    old_logs = {p.name for p in (tmp_path / "b").iterdir()}
    (tmp_path / "b" / "notes.txt").write_text("mine")
    assert main([*argv, "--seed", "2"]) == 2
    err = capsys.readouterr().err
    assert "is not empty" in err and "--force" in err and len(err.strip().splitlines()) == 1
    assert json.loads((tmp_path / "b" / TRUTH).read_text())["seed"] == 1  # untouched
    assert main([*argv, "--seed", "2", "--force"]) == 0
    assert json.loads((tmp_path / "b" / TRUTH).read_text())["seed"] == 2
    new = {p.name for p in (tmp_path / "b").iterdir()}
    assert "notes.txt" not in new and new != old_logs and len(new) == len(old_logs)
    monkeypatch.chdir(tmp_path / "b")
    assert main(["bench", "--units", "1", "--duration", "2", "--out", ".", "--force"]) == 2
    assert "does not empty the working" in capsys.readouterr().err
    assert (tmp_path / "b" / TRUTH).is_file()


# ----------------------------------------------------------------------------- realistic bench
REALISTIC = BenchSettings(units=1, duration_s=12.0, seed=5, realistic=True)


@pytest.fixture(scope="module")
def realistic(tmp_path_factory):
    out = tmp_path_factory.mktemp("realistic")
    return out, run(REALISTIC, out)


def _third_octave_dbfs(x: np.ndarray, f_hz: float, fs: float) -> float:
    """The level [dBFS] of `x` in the third-octave band centred on `f_hz` (Welch, Hann)."""
    import scipy.signal

    f, psd = scipy.signal.welch(x, fs, nperseg=int(fs) // 4)  # density: sum * df is the power
    band = (f >= f_hz * 2 ** (-1 / 6)) & (f < f_hz * 2 ** (1 / 6))
    return float(10 * np.log10(2 * psd[band].sum() * (f[1] - f[0])))


def test_realistic_bench_rests_and_keeps_the_sound_truth(realistic):
    """Motor off for rest_s (>= 1 s) at the start and the end (the speed inputs 0 there, the
    stroke shifted), the drive and background in truth.json, and per unit the envelope at
    100 Hz, the audible intervals and the growth at each onset: the fitted growth of ln A within
    5 % of the model's Re(lambda) there."""
    out, truth = realistic
    sound = REALISTIC.sound
    assert truth["sound"] == {
        "realistic": True,
        "gear_ratio": 37.3,
        "drive_orders": [37.3, 74.6, 373.0],
        "background_tones_hz": [1170.0, 100.0, 200.0, 300.0],
        "pink_noise_dbfs": -50.0,
        "rt60_s": 0.3,
        "saturation_dbfs": -20.0,
        "floor_dbfs": -80.0,
        "audible_snr_db": 6.0,
        "rest_s": 1.5,
    }
    (unit,) = truth["units"]
    assert unit["stroke_start_s"] == sound.rest_s
    span = REALISTIC.duration_s + 2 * sound.rest_s
    speeds = [
        (m.log_time_ns, np.frombuffer(m.data[4:12], "<f8")[0])
        for _, m in open_log(_bag(out, unit)).messages()
        if m.topic.name == "/motor_speed"
    ]
    t = (np.array([s[0] for s in speeds]) - speeds[0][0]) / 1e9
    v = np.array([s[1] for s in speeds])
    assert t[-1] == pytest.approx(span, abs=1e-6)
    rest = (t < sound.rest_s) | (t > span - sound.rest_s)
    assert np.abs(v[rest]).max() < 0.1 < np.abs(v).max()  # sensor noise only
    env = np.array(unit["sound"]["envelope_dbfs"])
    assert env.size == int(round(span * 100)) + 1
    assert env.min() >= truth["sound"]["floor_dbfs"] - 1e-9
    assert env.max() == pytest.approx(truth["sound"]["saturation_dbfs"], abs=0.05)
    assert env[0] == pytest.approx(truth["sound"]["floor_dbfs"], abs=1e-9)
    onsets = unit["sound"]["onsets"]
    assert len(onsets) == len(unit["sound"]["audible_intervals"]) >= 1
    for onset in onsets:
        assert onset["growth_rate_per_s"] > 0
        assert onset["fitted_growth_per_s"] == pytest.approx(onset["growth_rate_per_s"], rel=0.05)
    # the model squeaks first, the sound grows audible after
    first_squeak = unit["squeak_intervals"][0]["start_s"]
    assert first_squeak < onsets[0]["time_s"] < first_squeak + 1.0


def test_realistic_audible_intervals_agree_with_envelope_and_background(realistic):
    """At each onset the envelope stands audible_snr_db over the background in its band as
    measured from the recording's first motor-off second (within 2 dB: the room's level at one
    frequency); wherever it stands 3 dB more over it, the truth says audible."""
    out, truth = realistic
    (unit,) = truth["units"]
    track = read_audio(_bag(out, unit))
    fs = int(track.sample_rate_hz)
    quiet = track.samples[:fs].astype(float)
    env = np.array(unit["sound"]["envelope_dbfs"])
    freq = np.array(unit["sound"]["frequency_hz"])
    grid = np.arange(env.size) / 100.0
    snr = truth["sound"]["audible_snr_db"]
    bands = {f: _third_octave_dbfs(quiet, f, fs) for f in sorted({round(f) for f in freq})}
    background = np.array([bands[round(f)] for f in freq])
    for onset in unit["sound"]["onsets"]:
        level = np.interp(onset["time_s"], grid, env)
        band = _third_octave_dbfs(quiet, onset["frequency_hz"], fs)
        assert level - band == pytest.approx(snr, abs=2.0), onset
    intervals = unit["sound"]["audible_intervals"]
    inside = np.zeros(env.size, bool)
    for iv in intervals:
        inside |= (grid >= iv["start_s"] - 0.01) & (grid <= iv["end_s"] + 0.01)
    loud = env - background > snr + 3
    assert loud.any() and np.all(inside[loud])


def test_realistic_recording_holds_its_parts(realistic):
    """In the recording: the fan and hum in both motor-off stretches, the motor's orders at
    37.3 and 74.6 times the screw's rotation at the stroke's constant speed and not in the
    rest, the squeak saturated at its level with its 2nd harmonic where truth says so."""
    out, truth = realistic
    (unit,) = truth["units"]
    track = read_audio(_bag(out, unit))
    fs = int(track.sample_rate_hz)
    x = np.asarray(track.samples, dtype=float)
    span = len(unit["sound"]["envelope_dbfs"]) / 100.0
    for start in (0.2, span - 1.2):
        for f_hz, level in ((1170.0, -45.0), (100.0, -45.0), (200.0, -51.0)):
            seg = x[int(start * fs) :][:fs]
            assert 20 * np.log10(_flat_top(seg, f_hz, fs)) == pytest.approx(level, abs=3.0)
    sim = _realistic_unit()
    hold = np.flatnonzero(np.abs(np.diff(sim.speed_rad_s)) < 1e-9)
    hold = hold[np.abs(sim.speed_rad_s[hold]) > 1]
    t0 = sim.times_s[hold[len(hold) // 2]]
    shaft_hz = abs(sim.speed_rad_s[hold[len(hold) // 2]]) / (2 * np.pi)
    seg = x[int((t0 - 0.25) * fs) :][: fs // 2]
    rest = x[int(0.2 * fs) :][: fs // 2]
    for order in (37.3, 74.6):
        assert _flat_top(seg, order * shaft_hz, fs) > 10 * _flat_top(rest, order * shaft_hz, fs)
    env = np.array(unit["sound"]["envelope_dbfs"])
    freq = np.array(unit["sound"]["frequency_hz"])
    k = int(np.flatnonzero(env > -20.1)[len(np.flatnonzero(env > -20.1)) // 2])
    seg = x[int((k / 100 - 0.1) * fs) :][: fs // 5]
    assert 20 * np.log10(_flat_top(seg, freq[k], fs)) == pytest.approx(-20.0, abs=4.0)
    assert 20 * np.log10(_flat_top(seg, 2 * freq[k], fs)) == pytest.approx(-32.0, abs=4.0)


def _flat_top(seg: np.ndarray, f_hz: float, fs: float) -> float:
    import scipy.signal

    w = scipy.signal.windows.flattop(seg.size, sym=False)
    spectrum = np.abs(np.fft.rfft(seg * w)) * 2 / w.sum()
    i = int(round(f_hz * seg.size / fs))
    return float(spectrum[max(i - 2, 0) : i + 3].max())


def _realistic_unit():
    """Unit 0 of REALISTIC, simulated again (as `run` draws it)."""
    rng = np.random.default_rng(REALISTIC.seed)
    unit_rng, _ = (np.random.default_rng(s) for s in rng.integers(2**63, size=2))
    return simulate_unit(REALISTIC, 0, unit_rng, ScrewParameters(), Scatter())


def test_realistic_cli_switches_parts_and_refuses_them_without_realistic(tmp_path, capsys):
    argv = ["bench", "--units", "1", "--duration", "2", "--quiet", "--seed", "2"]
    assert (
        main(
            [
                *argv,
                "--out",
                str(tmp_path / "a"),
                "--realistic",
                "--fan-hz",
                "0",
                "--gear-ratio",
                "12.5",
                "--rt60-s",
                "0",
            ]
        )
        == 0
    )
    truth = json.loads((tmp_path / "a" / TRUTH).read_text())
    assert truth["sound"]["background_tones_hz"] == [100.0, 200.0, 300.0]
    assert truth["sound"]["drive_orders"] == [12.5, 25.0, 125.0]
    assert truth["settings"]["sound"]["rt60_s"] == 0.0 and truth["settings"]["realistic"]
    for bad, message in (
        (["--fan-hz", "0"], "--fan-hz sets a part of the realistic bench: add --realistic"),
        (["--realistic", "--rt60-s", "-1"], "bench.sound.rt60_s = -1 is out of range"),
        (["--realistic", "--commutator-segments", "2.5"], "invalid int value"),
    ):
        assert main([*argv, "--out", str(tmp_path / "b"), *bad]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    with pytest.raises(ParameterError, match="needs realistic = true"):
        BenchSettings(sound=BenchSound(fan_hz=0.0))


def test_realistic_same_seed_same_messages(realistic, tmp_path):
    out, truth = realistic
    again = run(REALISTIC, tmp_path)
    (a,), (b,) = truth["units"], again["units"]
    assert _messages(_bag(out, a)) == _messages(_bag(tmp_path, b))
    assert {**a, "log": ""} == {**b, "log": ""}
