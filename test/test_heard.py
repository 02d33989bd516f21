# SPDX-License-Identifier: Apache-2.0
"""Heard vs predicted in the replay and the review (`review.listen`): virtual-bench logs heard
at their unit's squeak frequency with recall and precision >= 0.95 by the unit's own model,
--compare-formulations ranking the bench's formulation first (both formulations), no sound ->
heard null, a WAV beside the log and Float32MultiArray = the topic, hostile audio -> a warning
and never a traceback, the annotated log's heard topics and clips, the fleet's columns = each
log's summary, the CLI's one-line errors."""

import csv
import errno
import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from scipy.io import wavfile

from harness.audio_logs import (
    DRIVERS_DATA,
    as_float32_multi_array,
    rewrite,
    samples_of,
    with_wav_beside,
)
from harness.calibration import QUICK_SAMPLER
from leadscrew_ros.bag import audio, audiomsgs
from leadscrew_ros.bag.virtual_bench import MIC_INFO_TOPIC, MIC_TOPIC, START_NS, BenchSettings, run
from leadscrew_ros.cli import main
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.acoustics import DetectorSettings
from leadscrew_ros.model.acoustics.bench_sound import envelope_growth
from leadscrew_ros.review.calibration.gather import observe_replay
from leadscrew_ros.review.listen import (
    CLIP_PAD_S,
    COLLAR_S,
    PredictionTrace,
    SoundSettings,
    SpeedTrace,
)
from leadscrew_ros.review.replay import ReplaySettings, replay

FORMULATIONS = ("paper", "consistent")
OTHER = {"paper": "consistent", "consistent": "paper"}


@pytest.fixture(scope="module", params=FORMULATIONS)
def bench(request, tmp_path_factory):
    """One unit, a 12 s stroke, made with each formulation: (formulation, bag, its truth)."""
    out = tmp_path_factory.mktemp(f"bench-{request.param}")
    truth = run(BenchSettings(units=1, duration_s=12.0, formulation=request.param, seed=0), out)
    unit = truth["units"][0]
    return request.param, out / unit["log"], unit


@pytest.fixture(scope="module")
def paper_bench(tmp_path_factory):
    """Two paper units, 6 s strokes (the quick cases)."""
    out = tmp_path_factory.mktemp("bench-short")
    truth = run(BenchSettings(units=2, duration_s=6.0, seed=1), out)
    return [out / u["log"] for u in truth["units"]], truth


def _replay(log, out, params=None, **listen):
    return replay(
        log,
        SqueakModel(params or ScrewParameters()),
        out,
        ReplaySettings(workers=0, progress=False, listen=SoundSettings(**listen)),
    )


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def test_bench_log_heard_at_the_units_frequency_by_its_own_model(bench, tmp_path):
    """The unit's own parameters (truth.json) in the bench's formulation: the replay hears the
    tone where the unit squeaks, at its frequency, and agrees with it."""
    formulation, log, unit = bench
    params = ScrewParameters(formulation=formulation).with_(**unit["params"])
    result = _replay(log, tmp_path, params)
    heard = _summary(tmp_path)["heard"]
    assert heard["source"] == MIC_TOPIC and heard["sample_rate_hz"] == 48000
    assert heard["scale"] == "full scale" and heard["level_unit"] == "dB re full scale"
    assert heard["episodes"] and all(e["loudness_sone"] is None for e in heard["episodes"])
    intervals = unit["squeak_intervals"]
    for e in heard["episodes"]:
        inside = [i for i in intervals if i["start_s"] - 0.1 <= e["start_s"] <= i["end_s"]]
        assert inside, e
        assert any(i["min_hz"] * 0.97 <= e["frequency_hz"] <= i["max_hz"] * 1.03 for i in inside), (
            e,
            inside,
        )
    a = heard["agreement"]
    assert a["recall"] >= 0.95 and a["precision"] >= 0.95, a
    assert a["brier"] < 0.05 and heard["collar_s"] == COLLAR_S
    assert all(m["matched"] for m in a["frequency_match"]), a["frequency_match"]
    text = (tmp_path / "summary.txt").read_text()
    assert f"recall {a['recall']:.2f}, precision {a['precision']:.2f}" in text
    assert "matches" in text and "uncalibrated: give --audio-scale PA" in text
    assert result.heard.spectrogram.level_db.shape[1] == 160


@pytest.mark.parametrize("replayed_with", ["own", "other"])
def test_compare_formulations_ranks_the_benchs_first(bench, tmp_path, capsys, replayed_with):
    """At the nominal parameters (what a unit's log is replayed with), replayed in either
    formulation, the comparison names the bench's formulation."""
    formulation, log, _ = bench
    chosen = formulation if replayed_with == "own" else OTHER[formulation]
    code = main(
        [
            "replay",
            str(log),
            "--out",
            str(tmp_path),
            "--formulation",
            chosen,
            "--compare-formulations",
            "--no-report",
            "--quiet",
            "--workers",
            "0",
        ]
    )
    assert code == 0
    s = _summary(tmp_path)
    by = s["agreement_by_formulation"]
    assert set(by) == set(FORMULATIONS)
    assert by[chosen]["brier"] == s["heard"]["agreement"]["brier"]
    assert by[formulation]["brier"] < by[OTHER[formulation]]["brier"]
    assert (
        f"{formulation} describes the drive better than {OTHER[formulation]}"
        in (tmp_path / "summary.txt").read_text()
    )


def test_no_sound_is_heard_null(paper_bench, tmp_path):
    log = rewrite(paper_bench[0][0], tmp_path / "in", lambda *_: [], "silent")
    result = _replay(log, tmp_path / "out")
    s = _summary(tmp_path / "out")
    assert s["heard"] is None and s["agreement_by_formulation"] is None and s["warnings"] == []
    assert result.heard is None
    assert "heard squeak" not in (tmp_path / "out" / "summary.txt").read_text()
    _replay(paper_bench[0][0], tmp_path / "off", enabled=False)  # --no-audio
    assert _summary(tmp_path / "off")["heard"] is None


def test_no_room_for_the_audio_track_is_one_line_and_the_replay_goes_on(
    paper_bench, tmp_path, monkeypatch
):
    """The log's audio is spilled to a temporary file as it is read: a full disk there is one
    line ("audio not analysed: ... set TMPDIR"), and the replay's predictions and summary are
    written all the same."""

    class Full:
        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

        def close(self):
            pass

    monkeypatch.setattr(audio.tempfile, "TemporaryFile", lambda **_: Full())
    result = _replay(paper_bench[0][0], tmp_path / "out")
    s = _summary(tmp_path / "out")
    assert s["heard"] is None and result.heard is None
    [line] = [w for w in s["warnings"] if "audio not analysed" in w]
    assert "no room for the audio track" in line and "No space left on device" in line
    assert "TMPDIR" in line and "\n" not in line
    assert s["predictions"] > 0


def _same_heard(a: dict, b: dict) -> None:
    assert len(a["episodes"]) == len(b["episodes"]) > 0
    for x, y in zip(a["episodes"], b["episodes"], strict=True):
        assert x["start_s"] == pytest.approx(y["start_s"], abs=0.011)
        assert x["end_s"] == pytest.approx(y["end_s"], abs=0.011)
        assert x["frequency_hz"] == pytest.approx(y["frequency_hz"], rel=1e-3)
    for key in ("recall", "precision", "brier"):
        assert a["agreement"][key] == pytest.approx(b["agreement"][key], abs=0.01)


def test_wav_beside_the_log_and_float32_multi_array_give_the_topics_result(
    paper_bench, tmp_path, capsys
):
    log = paper_bench[0][0]
    _replay(log, tmp_path / "topic")
    topic = _summary(tmp_path / "topic")["heard"]
    bag, wav, start = with_wav_beside(log, tmp_path / "wav")
    assert (
        main(
            [
                "replay",
                str(bag),
                "--out",
                str(tmp_path / "w"),
                "--audio",
                str(wav),
                "--audio-start",
                str(start),
                "--no-report",
                "--quiet",
                "--workers",
                "0",
            ]
        )
        == 0
    )
    beside = _summary(tmp_path / "w")["heard"]
    assert beside["source"] == str(wav)
    _same_heard(beside, topic)
    array = as_float32_multi_array(log, tmp_path / "f32")
    _replay(array, tmp_path / "a", rate_hz=48000.0)
    _same_heard(_summary(tmp_path / "a")["heard"], topic)
    _replay(array, tmp_path / "norate")  # no rate: the predictions without it
    s = _summary(tmp_path / "norate")
    assert s["heard"] is None
    assert any("carries no sample rate" in w and "--audio-rate" in w for w in s["warnings"])


def _f32(k, topic, data, t):
    """F32LE samples, NaN in the 3rd chunk."""
    if topic == MIC_INFO_TOPIC:
        return [
            (
                topic,
                audiomsgs.AUDIO_INFO,
                audiomsgs.encode_audio_info(1, 48000, "F32LE", 0, "wave"),
                t,
            )
        ]
    stamp, x = samples_of(data)
    x = x.astype("<f4")
    if k == 4:
        x[100:200] = np.nan
    return [
        (
            topic,
            audiomsgs.AUDIO_DATA_STAMPED,
            audiomsgs.encode_audio_data_stamped(stamp, x.view(np.uint8)),
            t,
        )
    ]


def _info(fmt="S16LE", coding="wave", rate_after_3_s=48000):
    """The AudioInfo messages changed: sample format, coding, the rate from 3 s on."""

    def change(k, topic, data, t):
        if topic == MIC_TOPIC:
            return [(topic, audiomsgs.AUDIO_DATA_STAMPED, data, t)]
        rate = rate_after_3_s if t >= START_NS + 3_000_000_000 else 48000
        return [
            (topic, audiomsgs.AUDIO_INFO, audiomsgs.encode_audio_info(1, rate, fmt, 0, coding), t)
        ]

    return change


def _truncated(k, topic, data, t):
    """The 2nd chunk empty, the 3rd cut by one byte."""
    if topic == MIC_INFO_TOPIC:
        return [(topic, audiomsgs.AUDIO_INFO, data, t)]
    stamp, _ = samples_of(data)
    raw = np.asarray(DRIVERS_DATA.decode(data)["audio"]["data"], np.uint8)
    raw = raw[:0] if k == 2 else raw[:-1] if k == 4 else raw
    return [
        (topic, audiomsgs.AUDIO_DATA_STAMPED, audiomsgs.encode_audio_data_stamped(stamp, raw), t)
    ]


def _two_mics(k, topic, data, t):
    if topic == MIC_INFO_TOPIC:
        return [(topic, audiomsgs.AUDIO_INFO, data, t)]
    return [(name, audiomsgs.AUDIO_DATA_STAMPED, data, t) for name in (MIC_TOPIC, "/mic2")]


@pytest.mark.parametrize(
    "change,heard,warning",
    [
        (_f32, True, "NaN/inf samples: the detector frames holding them are not scored"),
        (_info(fmt="S13LE"), False, "audio not analysed: "),
        (_info(coding="mp3"), False, "coded as 'mp3' (compressed)"),
        (_truncated, True, "empty audio messages"),
        (_info(rate_after_3_s=44100), True, "sample rate changed from 48000 Hz to 44100 Hz"),
        (_two_mics, False, "several audio topics, choose one: /mic2"),
    ],
    ids=["nan", "unknown-format", "mp3", "empty-truncated", "rate-change", "two-mics"],
)
def test_hostile_audio_is_a_warning_never_a_traceback(
    paper_bench, tmp_path, capsys, change, heard, warning
):
    log = rewrite(paper_bench[0][0], tmp_path / "in", change)
    code = main(
        ["replay", str(log), "--out", str(tmp_path / "out"), "--no-report", "--workers", "0"]
    )
    out, err = capsys.readouterr()
    assert code == 0 and "Traceback" not in out + err
    s = _summary(tmp_path / "out")
    assert (s["heard"] is not None) == heard
    warnings = s["warnings"] + (s["heard"]["warnings"] if heard else [])
    assert any(warning in w for w in warnings), warnings
    assert all("\n" not in w for w in warnings)
    if change is _truncated:
        assert any("partial frame" in w for w in warnings), warnings


def _muted_from(seconds: float, value: float):
    """The microphone's S16LE samples from `seconds` on: NaN (as F32LE, a broken driver) or a
    constant (a muted channel with a DC offset)."""

    def change(k, topic, data, t):
        fmt = "F32LE" if np.isnan(value) else "S16LE"
        if topic == MIC_INFO_TOPIC:
            info = audiomsgs.encode_audio_info(1, 48000, fmt, 0, "wave")
            return [(topic, audiomsgs.AUDIO_INFO, info, t)]
        stamp, x = samples_of(data)
        if t >= START_NS + int(seconds * 1e9):
            x = np.full_like(x, value)
        raw = x.astype("<f4") if fmt == "F32LE" else np.round(x * 32768).astype("<i2")
        payload = audiomsgs.encode_audio_data_stamped(stamp, raw.view(np.uint8))
        return [(topic, audiomsgs.AUDIO_DATA_STAMPED, payload, t)]

    return change


@pytest.mark.parametrize("value", [0.05, np.nan], ids=["constant", "nan"])
def test_sound_that_is_not_there_is_not_scored(paper_bench, tmp_path, value):
    """A microphone that goes mute (a constant) or NaN for the log's last 4 s: nothing is heard
    there, those frames are not scored (the agreement counts fewer frames, not 4 s of silence),
    and the summary says how long the sound was unusable."""
    log = paper_bench[0][0]
    _replay(log, tmp_path / "whole")
    whole = _summary(tmp_path / "whole")["heard"]
    mute_s = whole["duration_s"] - 4.0
    changed = rewrite(log, tmp_path / "in", _muted_from(mute_s, value))
    _replay(changed, tmp_path / "out")
    heard = _summary(tmp_path / "out")["heard"]
    hop = DetectorSettings().hop_s
    assert heard["unusable_s"] == pytest.approx(4.0, abs=DetectorSettings().frame_s + 2 * hop)
    assert all(e["start_s"] < mute_s for e in heard["episodes"])
    # every unusable frame is lost to the agreement, except those the whole log did not count
    # either: within COLLAR_S of its episodes' edges
    edges = sum(x >= mute_s for e in whole["episodes"] for x in (e["start_s"], e["end_s"]))
    lost = whole["agreement"]["frames"] - heard["agreement"]["frames"]
    assert lost * hop == pytest.approx(heard["unusable_s"] - edges * 2 * COLLAR_S, abs=2.5 * hop)
    text = (tmp_path / "out" / "summary.txt").read_text()
    assert f"sound unusable for {heard['unusable_s']:.1f} s of" in text
    if not np.isnan(value):
        said = [w for w in heard["warnings"] if w.startswith("no usable sound")]
        assert len(said) == 1


def test_annotated_log_carries_the_heard_episodes_and_clips(paper_bench, tmp_path):
    result = _replay(paper_bench[0][0], tmp_path)
    episodes = result.heard.detection.episodes
    assert episodes
    with open(result.annotated, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        attachments = {a.name: a for a in reader.iter_attachments()}
        fh.seek(0)
        got: dict = {"heard": [], "heard_frequency": []}
        for _, channel, message, decoded in reader.iter_decoded_messages(
            ["/replay/squeak/heard", "/replay/squeak/heard_frequency"]
        ):
            got[channel.topic.rsplit("/", 1)[1]].append(
                ((message.log_time - result.start_ns) / 1e9, decoded.data)
            )
    flags = got["heard"]
    assert flags[0][1] is False
    assert [v for _, v in flags[1:]] == [True, False] * len(episodes)
    for e, (on, off) in zip(episodes, zip(flags[1::2], flags[2::2], strict=True), strict=True):
        assert on[0] == pytest.approx(e.start_s, abs=0.011)
        assert off[0] == pytest.approx(e.end_s, abs=0.011)
    while_heard = [hz for t, hz in got["heard_frequency"] if hz > 0]
    assert while_heard and all(
        any(abs(hz - e.frequency_hz) < 0.03 * e.frequency_hz for e in episodes)
        for hz in while_heard
    )
    assert got["heard_frequency"][-1][1] == 0.0
    clips = sorted((tmp_path / "clips").glob("*.wav"))
    assert len(clips) == len(episodes)
    for clip, e in zip(clips, episodes, strict=True):
        assert attachments[f"clips/{clip.name}"].media_type == "audio/wav"
        assert attachments[f"clips/{clip.name}"].data == clip.read_bytes()
        rate, x = wavfile.read(clip)
        assert x.size / rate == pytest.approx(e.end_s - e.start_s + 2 * CLIP_PAD_S, abs=0.01)
    assert {"episodes.json", "summary.json"} <= set(attachments)
    assert _summary(tmp_path)["heard"]["clips"] == [f"clips/{c.name}" for c in clips]


def test_calibrated_levels_and_loudness(paper_bench, tmp_path):
    pytest.importorskip("mosqito")
    scale = paper_bench[1]["audio"]["audio_scale_pa_per_fs"]
    _replay(paper_bench[0][1], tmp_path, scale_pa=scale)
    heard = _summary(tmp_path)["heard"]
    assert heard["scale"] == "Pa" and heard["level_unit"] == "dB SPL"
    e = heard["episodes"][0]
    assert e["level_db"] == pytest.approx(94.0, abs=1.5)  # the bench's squeak_spl_db
    assert e["loudness_sone"] > 0
    assert "levels in dB SPL" in (tmp_path / "summary.txt").read_text()


def test_fleet_columns_are_each_logs_summary(paper_bench, tmp_path, capsys):
    """... and a log whose sound was not analysed (Float32MultiArray, no rate given or
    recorded) says so in its heard_status and on the console."""
    logs, _ = paper_bench
    unheard = as_float32_multi_array(logs[0], tmp_path / "f32")
    code = main(
        [
            "review",
            *map(str, logs),
            str(unheard),
            "--out",
            str(tmp_path / "out"),
            "--workers",
            "1",
            "--no-report",
            "--compare-formulations",
        ]
    )
    assert code == 0
    console = capsys.readouterr().out
    tmp_path = tmp_path / "out"
    with open(tmp_path / "fleet.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(logs) + 1
    last = rows.pop()
    why = last["heard_status"]
    assert why.startswith("audio not analysed: ") and "--audio-rate" in why
    assert why in _summary(tmp_path / last["name"])["warnings"]
    assert sum(why in line for line in console.splitlines()) == 1
    assert last["sound_share"] == ""
    for row in rows:
        assert row["heard_status"] == "analysed" and float(row["sound_share"]) == 1.0
        heard = _summary(tmp_path / row["name"])["heard"]
        a = heard["agreement"]
        assert float(row["heard_s"]) == a["both_s"] + a["heard_only_s"]
        for key in ("recall", "precision", "brier"):
            assert float(row[key]) == a[key]
        freqs = [float(f) for f in row["heard_frequencies_hz"].split(";")]
        assert freqs and all(
            any(abs(f - e["frequency_hz"]) < 1e-9 for e in heard["episodes"]) for f in freqs
        )
    doc = json.loads((tmp_path / "fleet.json").read_text())
    assert doc["parameters"]["listen"]["compare_formulations"] is True
    assert (tmp_path / "fleet.png").stat().st_size > 0


def test_a_log_heard_in_part_says_so_everywhere(paper_bench, tmp_path, capsys):
    """The microphone stops 2 s into a 6-s log: replay's console and summary.txt, summary.json,
    fleet.csv and review's console say how much of the log was heard (the agreement covers
    only that: it said recall 1.00 and nothing more)."""
    log = paper_bench[0][0]
    part = rewrite(
        log,
        tmp_path / "in",
        lambda k, topic, data, t: (
            []
            if t >= START_NS + 2e9
            else [
                (
                    topic,
                    audiomsgs.AUDIO_DATA_STAMPED if topic == MIC_TOPIC else audiomsgs.AUDIO_INFO,
                    data,
                    t,
                )
            ]
        ),
    )
    argv = ["--no-report", "--workers", "0"]
    assert main(["replay", str(part), "--out", str(tmp_path / "r"), *argv]) == 0
    console = capsys.readouterr().out
    heard = _summary(tmp_path / "r")["heard"]
    frames = (heard["log_s"] - DetectorSettings().frame_s) / DetectorSettings().hop_s + 1
    assert heard["sound_share"] == pytest.approx(
        heard["usable_s"] / (int(frames) * DetectorSettings().hop_s)
    )
    assert 0.25 < heard["sound_share"] < 0.35  # 2 s of 6 s, less a frame
    line = (
        f"heard only {heard['usable_s']:.1f} s of the log's {heard['log_s']:.1f} s "
        f"({100 * heard['sound_share']:.0f} %): heard vs predicted covers only that"
    )
    assert line in console and line in (tmp_path / "r" / "summary.txt").read_text()
    code = main(
        ["review", str(part), "--out", str(tmp_path / "f"), "--workers", "1", "--no-report"]
    )
    assert code == 0
    console = capsys.readouterr().out
    with open(tmp_path / "f" / "fleet.csv", encoding="utf-8") as fh:
        [row] = list(csv.DictReader(fh))
    assert float(row["sound_share"]) == pytest.approx(heard["sound_share"], rel=1e-12)
    assert f"{row['name']}: heard only {100 * heard['sound_share']:.0f} % of the log" in console


def test_a_realistic_bench_heard_not_its_room_nor_its_drive(tmp_path):
    """`bench --realistic` (fan, mains hum, pink noise, a worm gear at 37.3x with its 2nd order
    and a commutator at 373x, squeak grown by the amplitude equation, its harmonics, a room),
    seeds the unit tests do not use: no false episode from the background (learned at rest),
    at most one per unit in all (the commutator's constant-speed tone where its sweep was too
    fast to be learned), every audible interval of 50 ms or more found. The detector of 0.1.0
    heard 655 false episodes on 10 such units (424 of them the room's tones). The growth rate
    measured at each onset 15 dB or more over the background: median within 0.85-1.15 of the
    truth's over the window it reports (issue 30; sigma still rises after these onsets, so the
    truth within 25 ms of the onset is lower: measured 1.23x it on 10 units of seed 77)."""
    truth = run(BenchSettings(units=3, duration_s=12.0, seed=31, realistic=True), tmp_path / "b")
    background = truth["sound"]["background_tones_hz"]
    false = 0
    ratios = []
    for k, unit in enumerate(truth["units"]):
        _replay(tmp_path / "b" / unit["log"], tmp_path / f"r{k}")
        heard = _summary(tmp_path / f"r{k}")["heard"]
        audible = [
            a for a in unit["sound"]["audible_intervals"] if a["end_s"] - a["start_s"] >= 0.05
        ]
        episodes = heard["episodes"]

        def overlaps(e, a):
            return e["start_s"] < a["end_s"] and e["end_s"] > a["start_s"]

        wrong = [e for e in episodes if not any(overlaps(e, a) for a in audible)]
        assert not [
            e for e in wrong if any(abs(e["frequency_hz"] / f - 1) < 0.02 for f in background)
        ], wrong
        false += len(wrong)
        assert all(any(overlaps(e, a) for e in episodes) for a in audible), (audible, episodes)
        assert {round(b["frequency_hz"]) for b in heard["background"]} & {
            round(f) for f in background
        }
        assert any(abs(o["ratio"] / 37.3 - 1) < 0.01 for o in heard["drive_orders"])
        assert heard["creaks"] == []  # a squeak's reverberant tail, tones beating: no slips
        for a in audible:  # the episode that heard the interval's onset
            e = min((e for e in episodes if overlaps(e, a)), key=lambda e: e["start_s"])
            if e["growth_rate_per_s"] is not None and e["growth_snr_db"] >= 15.0:
                true = envelope_growth(
                    unit["sound"]["envelope_dbfs"],
                    unit["sound"]["envelope_rate_hz"],
                    e["growth_window_s"],
                )
                assert true is not None, (e["growth_window_s"], a)  # a window of >= 3 points
                ratios.append(e["growth_rate_per_s"] / true)
    assert false <= len(truth["units"])
    assert len(ratios) >= len(truth["units"]), ratios
    assert 0.85 <= float(np.median(ratios)) <= 1.15, ratios


def test_calibration_takes_no_observation_where_there_was_no_sound(paper_bench, tmp_path):
    """The microphone mute (a constant) for the last 4 s: its frames are no observations (they
    read as 'not heard': a less squeaky drive), a log mute throughout has none and says why,
    and calibration.txt names the inputs heard in part."""
    log = paper_bench[0][0]
    _replay(log, tmp_path / "whole")
    whole = observe_replay(tmp_path / "whole")
    mute_s = _summary(tmp_path / "whole")["heard"]["duration_s"] - 4.0
    _replay(rewrite(log, tmp_path / "in", _muted_from(mute_s, 0.05)), tmp_path / "part")
    part = observe_replay(tmp_path / "part")
    assert part.observations is not None and whole.observations is not None
    assert part.sound_share == pytest.approx(_summary(tmp_path / "part")["heard"]["sound_share"])
    assert 0.2 < part.sound_share < 0.5 and whole.sound_share == 1.0
    spans = _summary(tmp_path / "part")["heard"]["unusable_spans"]
    assert spans and spans[-1][0] == pytest.approx(
        mute_s + DetectorSettings().frame_s / 2, abs=0.02
    )
    frames_part = int(part.observations.frames.sum())
    assert 0 < frames_part < 0.6 * int(whole.observations.frames.sum())
    _replay(rewrite(log, tmp_path / "in0", _muted_from(0.0, 0.05)), tmp_path / "mute")
    mute = observe_replay(tmp_path / "mute")
    assert mute.observations is None and mute.reason.startswith("no usable sound")
    out = tmp_path / "cal"
    argv = [str(tmp_path / d) for d in ("whole", "part", "mute")]
    main(
        ["calibrate", *argv, "--out", str(out), "--workers", "1", "--quiet", "--no-report"]
        + QUICK_SAMPLER
    )  # only what calibration.txt says of the inputs is checked
    text = (out / "calibration.txt").read_text()
    assert f"2 inputs heard in part only: part {100 * part.sound_share:.0f} %, mute 0 %" in text


def test_detector_settings_from_the_params_file_and_the_command_line(paper_bench, tmp_path):
    """listen.f_lo_hz above the unit's 224 Hz squeak (a parameters file, as the node reads
    it, or --listen-param): only the 898 Hz squeak is heard; the option wins over the file;
    summary.json records the settings used."""
    log = str(paper_bench[0][0])
    argv = ["--no-report", "--quiet", "--workers", "0"]
    assert main(["replay", log, "--out", str(tmp_path / "d"), *argv]) == 0
    both = {round(e["frequency_hz"]) for e in _summary(tmp_path / "d")["heard"]["episodes"]}
    assert both == {224, 898}
    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    listen:\n      f_lo_hz: 400\n")
    for extra, f_lo in (
        (["--params-file", str(params)], 400.0),
        (["--listen-param", "listen.f_lo_hz=400"], 400.0),
        (["--params-file", str(params), "--listen-param", "f_lo_hz=100"], 100.0),
        (["--listen-param", "f_lo_hz=400", "--drive-ratio", "37.3", "--drive-ratio", "373"], 400.0),
    ):
        out = tmp_path / f"o{len(extra)}{f_lo:g}"
        assert main(["replay", log, "--out", str(out), *argv, *extra]) == 0
        heard = _summary(out)["heard"]
        assert heard["detector"]["f_lo_hz"] == f_lo and heard["band_hz"][0] == f_lo
        assert heard["detector"]["drive_ratios"] == (
            "37.3, 373" if "--drive-ratio" in extra else ""
        )
        found = {round(e["frequency_hz"]) for e in heard["episodes"]}
        assert found == ({898} if f_lo == 400.0 else both)


@pytest.mark.parametrize("command", ["replay", "review", "calibrate"])
@pytest.mark.parametrize(
    "setting,message",
    [
        ("bogus=1", "--listen-param: 'bogus' is not a detector setting; known: frame_s, hop_s"),
        ("frame_s", "--listen-param: expected NAME=VALUE, got 'frame_s'"),
        ("max_peaks=2.5", "--listen-param max_peaks: '2.5' is not an integer"),
        ("hop_s=x", "--listen-param hop_s: 'x' is not a number"),
        ("drive_ratios=37.3;x", "listen.drive_ratios: 'x' is not a positive number"),
        ("hop_s=5", "listen.hop_s = 5 is out of range, allowed [0.001, 0.5] s"),
    ],
)
def test_listen_param_errors_are_one_line(tmp_path, capsys, command, setting, message):
    code = main([command, str(tmp_path), "--out", str(tmp_path / "o"), "--listen-param", setting])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize(
    "args,message",
    [
        (["--audio-start", "1"], "--audio-start needs --audio FILE.wav"),
        (["--no-audio", "--audio-topic", "/m"], "--audio-topic and --no-audio exclude each other"),
        (["--audio", "missing.wav"], "--audio missing.wav: no such file"),
        (["--audio", "."], "--audio .: a directory, not a WAV file"),
        (["--audio-topic", "/mic"], "topic /mic is not an audio topic of this log; audio topics:"),
        (["--audio-info-topic", "/x"], "/x is not an AudioInfo topic of this log"),
        (["--audio", __file__, "--audio-rate", "8000"], "--audio-rate is for the log's audio"),
        (["--audio-channel", "-1"], "--audio-channel = -1 is out of range"),
        (["--audio-scale", "-2"], "--audio-scale = -2 is out of range"),
    ],
)
def test_cli_audio_options_one_line_errors(paper_bench, tmp_path, capsys, args, message):
    code = main(["replay", str(paper_bench[0][0]), "--out", str(tmp_path), *args])
    _, err = capsys.readouterr()
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err


def test_traces_are_compact():
    speed = SpeedTrace()
    for k in range(1000):  # constant, then a step, then a ramp
        speed.add(k * 0.01, 10.0 if k < 400 else 20.0 if k < 700 else 20.0 + (k - 700) * 0.1)
    t, v = speed.arrays()
    assert t.size < 340
    truth = np.where(
        np.arange(1000) < 400,
        10.0,
        np.where(np.arange(1000) < 700, 20.0, 20.0 + (np.arange(1000) - 700) * 0.1),
    )
    assert np.allclose(np.interp(np.arange(1000) * 0.01, t, v), truth, rtol=0.0021)
    trace = PredictionTrace()
    assert len(trace) == 0 and trace.squeak_points().shape == (0, 3)


@pytest.mark.parametrize("example", ["listening_example", "listening_realistic"])
def test_the_listening_page_shows_what_the_example_prints(example, tmp_path):
    """doc/user/listening.md's worked examples are tools/listening_example.py's output (a
    virtual-bench unit from three inputs) and tools/listening_realistic.py's (a realistic
    bench unit heard by `listen`)."""
    import importlib.util

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location(example, root / "tools" / f"{example}.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    page = (root / "doc" / "user" / "listening.md").read_text(encoding="utf-8")
    shown = page.split(f"% {example}: begin\n", 1)[1].split(f"\n% {example}: end", 1)[0]
    assert shown == tool.example(tmp_path)
