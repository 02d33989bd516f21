# SPDX-License-Identifier: Apache-2.0
"""The squeak detector: tones found down to a stated TNR, motor orders, noise and clipping
rejected, bad input never raises, offline and streaming agree frame for frame."""

import json
import math

import numpy as np
import pytest

from leadscrew_ros.model.acoustics import (
    AudioError,
    DetectorSettings,
    StreamingDetector,
    detect,
    frames_heard,
    microphone,
)
from leadscrew_ros.model.acoustics.samples import SampleTrack
from leadscrew_ros.model.acoustics.tonality import critical_band, hann_leakage, tnr_limit_db

FS = 48000
SIGMA = 0.01


def gated_tone(f, excess_db, seed, dur=1.5, on=(0.5, 1.0)):
    """White noise (rms SIGMA) and a tone switched on hard during `on`, whose true TNR in its
    critical band is the ECMA limit + `excess_db`."""
    rng = np.random.default_rng(seed)
    n = int(dur * FS)
    t = np.arange(n) / FS
    f1, f2 = critical_band(f)
    tnr = float(tnr_limit_db(f)) + excess_db
    amp = np.sqrt(2 * SIGMA**2 * (f2 - f1) / (FS / 2) * 10 ** (tnr / 10))
    gate = (t >= on[0]) & (t < on[1])
    return (rng.normal(0.0, SIGMA, n) + amp * gate * np.sin(2 * np.pi * f * t)).astype(np.float32)


def _found(d, f, on=(0.5, 1.0)):
    """The detection is exactly one episode: onset and end within 50 ms, frequency 1 %."""
    return (
        len(d.episodes) == 1
        and abs(d.episodes[0].start_s - on[0]) <= 0.05
        and abs(d.episodes[0].end_s - on[1]) <= 0.05
        and abs(d.episodes[0].frequency_hz / f - 1) <= 0.01
    )


@pytest.mark.parametrize("f", [224.0, 898.0, 2653.0])
def test_every_tone_found_down_to_the_stated_tnr(f):
    """Detection limit, 0.5 s tones in white noise, 10 noise draws each: every tone is found
    (one episode, onset and end within 50 ms, frequency within 1 %) once its TNR exceeds the
    ECMA-418-1 limit by 4 dB, at 898 and 2653 Hz already by 2 dB (measured: all 10 from +4 dB
    at 224 Hz, +2 dB at 898 / 2653 Hz; 3-8 of 10 at +1..+3 dB; none below the limit). In
    broadband SNR of a 48 kHz recording that is -6.2 dB at 224 Hz (limit 13.4 dB + 4 dB in its
    104 Hz band), -11.0 dB at 898 Hz, -9.6 dB at 2653 Hz. At 3 dB below the limit some draws
    still give fragments of the tone (its TNR scatters from frame to frame), and nothing
    appears elsewhere."""
    need = 4.0 if f < 500 else 2.0
    for seed in range(10):
        d = detect(gated_tone(f, need, seed), FS)
        assert _found(d, f), (seed, [e.as_dict() for e in d.episodes])
        assert d.heard.sum() * d.hop_s == pytest.approx(0.5, abs=0.1)
        assert np.nanmedian(d.frequency_hz) == pytest.approx(f, rel=0.01)
    for seed in range(10):
        eps = detect(gated_tone(f, -3.0, seed), FS).episodes
        assert all(
            abs(e.frequency_hz / f - 1) <= 0.01 and e.start_s >= 0.45 and e.end_s <= 1.05
            for e in eps
        )


def test_strong_tone_onset_and_level():
    d = detect(gated_tone(898.0, 30.0, 0), FS)
    (ep,) = d.episodes
    assert ep.start_s == pytest.approx(0.5, abs=0.05) and ep.end_s == pytest.approx(1.0, abs=0.05)
    amp = np.sqrt(
        2
        * SIGMA**2
        * np.diff(critical_band(898.0), axis=0)[0]
        / (FS / 2)
        * 10 ** ((float(tnr_limit_db(898.0)) + 30) / 10)
    )
    assert ep.level_db == pytest.approx(10 * np.log10(amp**2 / 2), abs=0.5)  # re full scale
    assert ep.tnr_db > float(tnr_limit_db(898.0)) + 20  # Hann side lobes cap it near 33 dB
    assert ep.loudness_sone is None and d.scale == "full scale"


def _sweep(orders, level=0.3, dur=10.0):
    t = np.linspace(0.0, dur, 301)
    speed = np.geomspace(30.0, 700.0, t.size)  # shaft 4.8 .. 111 Hz
    x = microphone(
        t,
        speed,
        np.full(t.size, np.nan),
        motor_orders=orders,
        motor_level=level,
        noise_level=0.003,
        seed=3,
    )
    return t, speed, x


@pytest.mark.parametrize("orders", [(1, 2, 3, 4, 6, 8, 12), (12, 24, 37, 45), (20, 40, 60)])
def test_no_episode_from_motor_orders_sweeping_through_the_band(orders):
    """Orders swept from ~100 Hz to ~5 kHz in 10 s: with the speed given, no episode (all
    rejected, each as its own order; a track may follow its order through the whole sweep);
    without it, the same tones are episodes (they are prominent). Orders at 1/m of the
    amplitude of an order m times lower are its harmonics (e.g. 40 and 60 beside 20)."""
    t, speed, x = _sweep(orders)
    d = detect(x, FS, speed_times_s=t, speed_rad_s=speed)
    assert d.episodes == [] and d.rejected
    assert {e.order for e in d.rejected} <= set(orders)
    assert sum(e.duration_s for e in d.rejected) > 5.0
    assert len(detect(x, FS).episodes) == len(d.rejected)


def test_a_squeak_among_sweeping_orders_is_kept():
    t, speed, _ = _sweep((12, 24, 37, 45))
    sq = np.where((t >= 3.0) & (t < 6.0), 1731.0, np.nan)
    x = microphone(
        t,
        speed,
        sq,
        squeak_level=0.02,
        motor_orders=(12, 24, 37, 45),
        motor_level=0.3,
        noise_level=0.003,
        seed=3,
    )
    d = detect(x, FS, speed_times_s=t, speed_rad_s=speed)
    assert [round(e.frequency_hz) for e in d.episodes] == [1731]
    assert d.episodes[0].start_s == pytest.approx(3.0, abs=0.05)
    assert d.episodes[0].end_s == pytest.approx(6.0, abs=0.05)


def test_constant_speed_low_orders_rejected_by_frequency_alone():
    t = np.linspace(0.0, 2.0, 201)
    speed = np.full(t.size, 300.0)  # 47.7 Hz: 143, 239, 334, 525 Hz
    x = microphone(
        t, speed, np.full(t.size, np.nan), motor_orders=(3, 5, 7, 11), motor_level=0.2, seed=1
    )
    d = detect(x, FS, speed_times_s=t, speed_rad_s=speed)
    assert d.episodes == [] and {e.order for e in d.rejected} == {3, 5, 7, 11}
    assert len(detect(x, FS).episodes) >= 4


def test_noise_alone_gives_nothing():
    for seed in range(4):
        x = np.random.default_rng(seed).normal(0.0, 0.1, 3 * FS).astype(np.float32)
        d = detect(x, FS)
        assert d.episodes == [] and not d.heard.any() and d.warnings == []


def test_clipped_signals_give_no_false_episodes():
    """A tone clipped hard: one episode at its frequency, not its odd harmonics; clipped
    orders: none; clipped noise: none; each with the 'clipped' warning."""
    t = np.linspace(0.0, 2.0, 201)
    sq = np.where((t >= 0.5) & (t < 1.5), 898.0, np.nan)
    x = microphone(t, np.full(t.size, 30.0), sq, squeak_level=0.5, noise_level=0.05)
    d = detect(np.clip(4 * x, -1, 1), FS)
    assert [round(e.frequency_hz) for e in d.episodes] == [898]
    assert any(w.startswith("clipped") for w in d.warnings)
    ts, speed, xs = _sweep((12, 24, 37, 45))
    d = detect(np.clip(20 * xs, -1, 1), FS, speed_times_s=ts, speed_rad_s=speed)
    assert d.episodes == [] and any(w.startswith("clipped") for w in d.warnings)
    noise = np.random.default_rng(0).normal(0.0, 1.0, 2 * FS)
    d = detect(np.clip(noise, -1, 1), FS)
    assert d.episodes == [] and any(w.startswith("clipped") for w in d.warnings)


def test_bad_input_never_raises():
    x = gated_tone(898.0, 20.0, 0)
    x[30000:30010] = np.nan  # inside the tone: bridged
    x[60000] = np.inf  # after it
    d = detect(x, FS)
    assert len(d.episodes) == 1 and d.episodes[0].start_s == pytest.approx(0.5, abs=0.05)
    assert d.episodes[0].end_s == pytest.approx(1.0, abs=0.05)
    assert [w for w in d.warnings if w.startswith("11 non-finite")] == [
        "11 non-finite samples (NaN/inf) set to 0; the frames holding them are dropped "
        "(tracks bridge one frame length of them)"
    ]
    # each of the two runs of NaN/inf spoils the frame_s / hop_s frames holding it: not scored
    frames = DetectorSettings().frame_s / DetectorSettings().hop_s
    assert d.unusable_s == pytest.approx(2 * frames * d.hop_s, abs=1.5 * d.hop_s)
    assert d.usable.size == d.frame_times_s.size
    assert [w for w in d.warnings if w.startswith("sound unusable")] == [
        f"sound unusable for {d.unusable_s:.2f} of {d.frame_times_s.size * d.hop_s:.2f} s "
        f"(non-finite samples {d.unusable_s:.2f} s, constant or silent 0.00 s): not scored"
    ]
    long_gap = gated_tone(898.0, 20.0, 0)
    long_gap[33600:38400] = np.nan  # 0.1 s of them: the episode splits
    d = detect(long_gap, FS)
    assert len(d.episodes) == 2 and d.episodes[0].start_s == pytest.approx(0.5, abs=0.05)
    assert d.episodes[1].end_s == pytest.approx(1.0, abs=0.05)
    for empty in ([], np.zeros(0, np.float32)):
        d = detect(empty, FS)
        assert d.frame_times_s.size == 0 and d.episodes == [] and "no audio samples" in d.warnings
        json.dumps(d.as_dict(), allow_nan=False)
    d = detect(np.zeros(100), FS)
    assert d.frame_times_s.size == 0 and "shorter than one frame" in d.warnings[-1]
    d = detect(np.full(FS, np.nan), FS)
    assert d.episodes == [] and d.warnings
    d = detect(["a", "b"], FS)
    assert d.episodes == [] and "not numbers" in d.warnings[0]
    d = detect(np.stack([x, x], axis=1), FS)  # two channels: averaged
    assert len(d.episodes) == 1 and "2 channels averaged" in d.warnings
    for rate in (0, -48000, math.nan, math.inf, "x", 100):
        with pytest.raises(AudioError):
            detect(x, rate)
    assert issubclass(AudioError, ValueError)


def test_a_constant_microphone_is_no_usable_sound_said_once():
    """A muted channel (a DC offset, no noise) and digital silence: no episode (the float
    rounding of the spectra once gave tones near -200 dBFS with a TNR near 100 dB), every
    frame unusable and not scored, the reason said once."""
    for level in (0.1, -0.37, 0.0):
        d = detect(np.full(3 * FS, level, np.float32), FS)
        assert d.episodes == [] and not d.heard.any()
        assert not d.usable.any() and d.unusable_s == pytest.approx(d.frame_times_s.size * d.hop_s)
        said = [w for w in d.warnings if w.startswith("no usable sound")]
        assert len(said) == 1 and "constant or digitally silent" in said[0]
    x = gated_tone(898.0, 20.0, 0)
    x[FS:] = 0.25  # the microphone goes mute after the tone: only that part unusable
    d = detect(x, FS)
    assert len(d.episodes) == 1 and d.usable[d.frame_times_s < 0.9].all()
    assert not d.usable[d.frame_times_s > 1.06].any()


@pytest.mark.parametrize("bits", [16, 24, None])
def test_quantisation_and_rounding_never_make_episodes(bits):
    """A clean 1 kHz tone, as float or quantised to 16/24-bit PCM: that tone and nothing else
    (quantisation peaks near -109 dBFS and float noise near -190 dBFS were episodes; with 8
    candidate slots filled by them the tone itself was lost)."""
    t = np.arange(3 * FS) / FS
    x = 0.3 * np.sin(2 * np.pi * 1000.0 * t)
    if bits:
        x = np.round(x * 2 ** (bits - 1)) / 2 ** (bits - 1)
    d = detect(x.astype(np.float32), FS)
    assert [round(e.frequency_hz) for e in d.episodes] == [1000]
    assert d.usable.all() and d.unusable_s == 0.0


def test_a_tone_of_a_few_quantisation_steps_is_still_heard():
    """The floor is the format's own noise (10 dB over 16-bit quantisation noise, -91 dB re
    full scale mean square): a tone of 2 steps' amplitude (-87 dB) stands over it, one of
    0.6 steps (rounded to a pattern of -1, 0, 1) does not."""
    t = np.arange(3 * FS) / FS
    step = 2.0**-15
    rng = np.random.default_rng(3)
    for amplitude, found in ((2.0, [1500]), (0.6, [])):
        x = amplitude * step * np.sin(2 * np.pi * 1500.0 * t + rng.uniform(0, 2 * np.pi))
        d = detect((np.round(x / step) * step).astype(np.float32), FS)
        assert [round(e.frequency_hz) for e in d.episodes] == found, amplitude


SIGMA_ROOM = 0.003  # the room's white noise (rms)


def _bench_room(rest=((0.0, 1.5), (10.5, 12.0)), squeaks=((4.0, 5.0, 2480.0, 0.02),)):
    """12 s of a room with a fan (1170 Hz), mains hum (100/200/300 Hz) and noise, the drive at
    rest in `rest` (speed 0) and at 100 rad/s otherwise (ramps of 1.5 s), squeak tones
    (start, end, Hz, amplitude) added."""
    t = np.arange(12 * FS) / FS
    x = SIGMA_ROOM * np.random.default_rng(5).standard_normal(t.size)
    room = ((1170.0, 0.01), (100.0, 0.01), (200.0, 0.005), (300.0, 0.003))
    for f, a in room:
        x += a * np.sin(2 * np.pi * f * t + f)
    for start, end, f, a in squeaks:
        x += a * np.sin(2 * np.pi * f * t) * ((t > start) & (t < end))
    ts = np.linspace(0.0, 12.0, 1201)
    moving = np.ones(ts.size)
    for a, b in rest:
        moving[(ts >= a) & (ts <= b)] = 0.0
    speed = 100.0 * np.convolve(moving, np.ones(151) / 151, mode="same")  # 1.5-s ramps
    speed[moving == 0] = 0.0
    return x.astype(np.float32), ts, speed, room


@pytest.mark.parametrize("rest", [((0.0, 1.5), (10.5, 12.0)), ((10.0, 12.0),)], ids=["both", "end"])
def test_what_sounds_at_rest_is_background(rest):
    """The fan and the hum sound at rest (at the start and the end, or only at the end of the
    log): they are the log's background (their levels within 1 dB), never squeak; a squeak at
    2480 Hz is found, and so is a squeak at the fan's frequency 15 dB louder than the fan."""
    squeaks = ((4.0, 5.0, 2480.0, 0.02), (6.0, 7.0, 1170.0, 0.06))
    x, ts, speed, room = _bench_room(rest, squeaks)
    d = detect(x, FS, speed_times_s=ts, speed_rad_s=speed)
    found = [(round(e.frequency_hz), round(e.start_s, 1), round(e.end_s, 1)) for e in d.episodes]
    assert found == [(2480, 4.0, 5.0), (1170, 6.0, 7.0)]
    tones = {round(b.frequency_hz): b.level_db for b in d.background}
    assert set(tones) == {round(f) for f, _ in room}
    for f, a in room:
        assert tones[round(f)] == pytest.approx(10 * math.log10(a * a / 2), abs=1.0)
    assert json.loads(json.dumps(d.as_dict()))["background"][0]["frequency_hz"] > 0


def test_what_rings_on_as_the_drive_stops_is_not_background():
    """A loud squeak at 2480 Hz rings on for 0.4 s after the drive stops (10.5 s): the rest
    after it is learned as background only from where its sound has settled, so its band
    stays the noise's (within 1 dB; learning the whole rest put it 29 dB higher,
    and recall on a realistic bench, seed 77, was 0.898, now 0.96) and a quieter squeak at
    the same frequency, 14 dB over the band, is found."""
    x, ts, speed, _ = _bench_room(squeaks=((4.0, 5.0, 2480.0, 0.0), (9.0, 10.9, 2480.0, 0.05)))
    band = SIGMA_ROOM**2 * 2480.0 * (2 ** (1 / 6) - 2 ** (-1 / 6)) / (FS / 2)
    t = np.arange(x.size) / FS
    quiet = np.sqrt(2 * band * 10 ** (14 / 10))
    x = x + (quiet * np.sin(2 * np.pi * 2480.0 * t) * ((t > 4.0) & (t < 5.0))).astype(np.float32)
    det = StreamingDetector(DetectorSettings(), FS)
    from leadscrew_ros.model.acoustics.detection import _learn_at_rest

    _learn_at_rest(det, x, 0.0, ts, speed)
    learned = float(det.background.band_power(np.array([2480.0]))[0])
    assert 10 * math.log10(learned / band) == pytest.approx(0.0, abs=1.0)
    d = detect(x, FS, speed_times_s=ts, speed_rad_s=speed)
    found = [(round(e.frequency_hz), round(e.start_s, 1), round(e.end_s, 1)) for e in d.episodes]
    assert found[0] == (2480, 4.0, 5.0) and len(found) == 2, found


def test_a_band_holds_a_background_tone_only_when_the_tone_is_in_it():
    """Mains hum at 200 Hz: the third-octave band of 224.75 Hz starts at 200.2 Hz, so it holds
    the noise only (within 1 dB), though the 10-Hz bin at 200 Hz holds both the hum and the
    band's edge; the band of 210 Hz (from 187 Hz) holds the hum with its whole power."""
    t = np.arange(3 * FS) / FS
    x = 0.003 * np.random.default_rng(2).standard_normal(t.size) + 0.01 * np.sin(
        2 * np.pi * 200.0 * t
    )
    det = StreamingDetector(DetectorSettings(), FS)
    det.push(x.astype(np.float32), 0.0, 0.0)
    assert [round(b.frequency_hz) for b in det.background.tones()] == [200]
    f = np.array([224.75, 210.0])
    noise = 0.003**2 * f * (2 ** (1 / 6) - 2 ** (-1 / 6)) / (FS / 2)
    got = det.background.band_power(f)
    assert 10 * math.log10(got[0] / noise[0]) == pytest.approx(0.0, abs=1.0)
    assert 10 * math.log10(got[1] / (noise[1] + 0.01**2 / 2)) == pytest.approx(0.0, abs=0.5)


def test_without_rest_the_room_is_not_learned():
    """Never at rest (or no speed at all): nothing is learned as background."""
    x, ts, speed, _ = _bench_room(rest=())
    assert detect(x, FS, speed_times_s=ts, speed_rad_s=speed).background == []
    assert detect(x, FS).background == []


def test_the_live_detector_learns_the_background_while_the_drive_rests():
    """Chunk by chunk (the node): the fan heard during the first 1.5 s at rest is learned, and
    from then on it is not heard as squeak while the drive moves; the squeak is."""
    x, ts, speed, _ = _bench_room(rest=((0.0, 1.5),))
    det = StreamingDetector(DetectorSettings(), FS)
    heard_at = {}
    for k in range(0, x.size, 4800):
        t0 = k / FS
        det.push(x[k : k + 4800], t0, np.interp([t0, t0 + 0.1], ts, speed), [t0, t0 + 0.1])
        heard_at[round(t0 + 0.1, 1)] = (det.heard_now, det.frequency_now_hz)
    assert {round(b.frequency_hz) for b in det.background.tones()} >= {100, 1170}
    # nothing has slid before the drive first moves: the fan is not squeak in the first
    # 0.5 s of rest either, before it is learned (it was, for 0.3 s of every bench unit)
    assert not any(h for t, (h, _) in heard_at.items() if t <= 3.9 or 5.2 <= t <= 12.0)
    assert heard_at[4.5][0] and heard_at[4.5][1] == pytest.approx(2480.0, rel=0.01)


def _geared_drive(ratios=((37.3, 0.01), (74.6, 0.005), (373.0, 0.003)), hold_only=False):
    """12 s: rest, a ramp to 100 rad/s (1-3 s), a hold, a ramp down (9-11 s), rest; a geared
    motor's tones at `ratios` x the screw's rotation frequency (not whole: a worm gear of
    37.3, its 2nd order, a 10-segment commutator) while it turns; squeaks at 2480 Hz (4-5 s,
    the hold) and 1000 Hz (9.3-10.3 s, the ramp down); noise. `hold_only`: the log starts in
    the hold (no ramp, no rest)."""
    t = np.arange(12 * FS) / FS
    knots = ([0, 12], [100, 100]) if hold_only else ([0, 1, 3, 9, 11, 12], [0, 0, 100, 100, 0, 0])
    ts = np.linspace(0.0, 12.0, 1201)
    speed = np.interp(ts, *knots)
    turns = np.cumsum(np.interp(t, ts, speed)) / FS  # screw angle [rad]
    x = 0.003 * np.random.default_rng(9).standard_normal(t.size)
    for r, a in ratios:
        x += a * np.sin(r * turns) * (np.interp(t, ts, speed) > 0.5)
    for start, end, f in ((4.0, 5.0, 2480.0), (9.3, 10.3, 1000.0)):
        x += 0.02 * np.sin(2 * np.pi * f * t) * ((t > start) & (t < end))
    return x.astype(np.float32), ts, speed


def test_drive_noise_at_any_ratio_is_not_squeak():
    """A worm-geared motor at 37.3 x the screw's speed, its 2nd order and its commutator
    (373 x): followed as they sweep and judged whole, they are drive noise (they were cut into
    +-2 % pieces, not whole orders, 108 false episodes on a bench); their ratios are learned
    (`drive_orders`); the squeaks during the hold and the ramp are found."""
    x, ts, speed = _geared_drive()
    d = detect(x, FS, speed_times_s=ts, speed_rad_s=speed)
    found = [(round(e.frequency_hz), round(e.start_s, 1), round(e.end_s, 1)) for e in d.episodes]
    assert found == [(2480, 4.0, 5.0), (1000, 9.3, 10.3)]
    learned = [o.ratio for o in d.drive_orders]
    for r in (37.3, 373.0):  # the 2nd order is a harmonic of the 1st in every frame: not a track
        assert any(abs(q / r - 1) < 0.005 for q in learned), (r, learned)
    assert all(e.drive_ratio is not None for e in d.rejected)


def test_drive_noise_at_constant_speed_by_its_known_ratios():
    """The log starts in the hold: nothing sweeps, so nothing tells the drive from a squeak
    by its motion; with the drive's ratios given (`drive_ratios`, the CLI's --drive-ratio)
    its tones are drive noise, without them they are kept (37.3 is no low whole order)."""
    x, ts, speed = _geared_drive(hold_only=True)
    given = DetectorSettings(drive_ratios="37.3, 74.6; 373")
    d = detect(x, FS, speed_times_s=ts, speed_rad_s=speed, settings=given)
    assert [round(e.frequency_hz) for e in d.episodes] == [2480, 1000]
    d = detect(x, FS, speed_times_s=ts, speed_rad_s=speed)
    assert {round(e.frequency_hz / (100 / (2 * np.pi)), 1) for e in d.episodes} >= {37.3, 373.0}
    with pytest.raises(ValueError, match="drive_ratios: 'x' is not a positive number"):
        DetectorSettings(drive_ratios="37.3, x")


def test_a_ratio_heard_again_at_another_speed_is_drive_noise():
    """Two holds, at 100 and 80 rad/s, reached by steps too fast to follow: a commutator at
    297 x the screw's rotation is heard in each as a constant tone (4727 and 3781 Hz); the
    same ratio at both speeds is the drive (13 false episodes on 10 realistic-bench units with
    a 29.7 gear: 2 left), while a squeak at 2480 Hz in both holds (two ratios) is kept."""
    t = np.arange(12 * FS) / FS
    ts = np.linspace(0.0, 12.0, 1201)
    speed = np.interp(ts, [0, 1, 1.01, 6, 6.01, 11, 11.01, 12], [0, 0, 100, 100, 80, 80, 0, 0])
    turns = np.cumsum(np.interp(t, ts, speed)) / FS
    x = 0.003 * np.random.default_rng(4).standard_normal(t.size)
    x += 0.01 * np.sin(297.0 * turns) * (np.interp(t, ts, speed) > 0.5)
    for start, end in ((3.0, 4.0), (8.0, 9.0)):
        x += 0.02 * np.sin(2 * np.pi * 2480.0 * t) * ((t > start) & (t < end))
    d = detect(x.astype(np.float32), FS, speed_times_s=ts, speed_rad_s=speed)
    assert [round(e.frequency_hz) for e in d.episodes] == [2480, 2480]
    drive = [e for e in d.rejected if e.drive_ratio is not None]
    assert drive and all(abs(e.drive_ratio / 297.0 - 1) < 0.01 for e in drive)
    assert {round(e.frequency_hz / 100) for e in drive} == {47, 38}


def test_a_tone_lasting_exactly_a_constant_speed_stretch_is_drive_noise():
    """One hold at 100 rad/s reached and left by steps too fast to follow (no other speed to
    compare with): a commutator at 373 x the screw's rotation sounds exactly while the speed
    holds (5 such false episodes on 10 realistic-bench units, seed 77); it is drive noise. In
    the same hold a squeak at 2480 Hz growing from 1.7 s and one at 1100 Hz growing from
    5.3 s that rings on (decays) after the drive stops at 6 s are kept: a squeak starts
    when it has grown, not when the speed settles, and outlasts the speed's change."""
    t = np.arange(8 * FS) / FS
    ts = np.linspace(0.0, 8.0, 801)
    speed = np.interp(ts, [0, 1, 1.01, 6, 6.01, 8], [0, 0, 100, 100, 0, 0])
    turns = np.cumsum(np.interp(t, ts, speed)) / FS
    x = 0.003 * np.random.default_rng(6).standard_normal(t.size)
    x += 0.005 * np.sin(373.0 * turns) * (np.interp(t, ts, speed) > 0.5)
    for start, end, f in ((1.7, 3.0, 2480.0), (5.3, 6.0, 1100.0)):
        grow = np.minimum(np.exp(40.0 * (t - start - 0.2)), 1.0)  # 35 dB in 0.2 s, saturates
        ring = np.exp(-np.maximum(t - end, 0.0) / 0.1)  # 35 dB down 0.4 s after `end`
        x += 0.02 * grow * ring * np.sin(2 * np.pi * f * t) * (t > start) * (t < end + 0.4)
    d = detect(x.astype(np.float32), FS, speed_times_s=ts, speed_rad_s=speed)
    assert [round(e.frequency_hz) for e in d.episodes] == [2480, 1100]
    drive = [e for e in d.rejected if e.drive_ratio is not None]
    assert [round(e.drive_ratio) for e in drive] == [373]
    assert [round(o.ratio) for o in d.drive_orders] == [373]  # learned: its sweeps are known
    assert drive[0].start_s == pytest.approx(1.0, abs=0.1)
    assert drive[0].end_s == pytest.approx(6.0, abs=0.1)


def test_a_piece_of_a_sweep_is_judged_by_where_its_sound_went():
    """A 60-ms track at 390 Hz on a ramp (the speed falling 50 %/s): too short to be seen
    moving (a 2nd motor order at the start of a ramp down: one false episode on a realistic
    bench, seed 2024, 12.4 gear). Followed three frames beyond its ends, a drive tone's sound
    goes on along r |speed| / 2 pi (rejected, `drive_ratio` r), a squeak's stays at 390 Hz
    (kept)."""
    from leadscrew_ros.model.acoustics.detection import Episode, _went_with_speed

    t = np.arange(3 * FS) / FS
    ts = np.linspace(0.0, 3.0, 301)
    speed = 100.0 * np.exp(-0.5 * ts)  # rad/s, -50 %/s
    f1 = speed / (2 * np.pi)
    r = 390.0 / float(np.interp(1.5, ts, f1))
    turns = np.cumsum(np.interp(t, ts, speed)) / FS
    noise = 0.003 * np.random.default_rng(8).standard_normal(t.size)
    frames = 1.5 + np.arange(-3, 3) * 0.01
    track = r * np.interp(frames, ts, f1)
    for tone, drive in (
        (0.01 * np.sin(r * turns), True),
        (0.01 * np.sin(2 * np.pi * 390 * t), False),
    ):
        ep = Episode(frames[0] - 0.005, frames[-1] + 0.005, 390.0, 20.0, 20.0, -40.0)
        ep.track_times_s, ep.track_hz = frames, track
        det = StreamingDetector(DetectorSettings(), FS)
        kept = _went_with_speed(det, [ep], ts, speed, (noise + tone).astype(np.float32), 0.0)
        assert (kept == []) == drive
        assert (ep.drive_ratio == pytest.approx(r, rel=0.01)) if drive else ep.drive_ratio is None


def test_a_224_hz_squeak_12_db_over_its_band_is_found_within_100_ms():
    """Issue 30: a 224 Hz squeak 12 dB over its third-octave background is found within
    100 ms of becoming so. The background (white noise) is learned at rest (the first 1 s);
    the squeak grows at 20 1/s (a slow onset: 1.7 dB per 10 ms) from 5 dB under the band at
    2 s and saturates 30 dB over it; it is found (offline: the episode's start; live:
    `heard_now` at the first frame whose samples have all arrived) at most 100 ms after it
    stands 12 dB over the band, for every noise draw."""
    dur, sigma, f, rate = 4.0, 0.003, 224.0, 20.0
    t = np.arange(int(dur * FS)) / FS
    band = sigma**2 * f * (2 ** (1 / 6) - 2 ** (-1 / 6)) / (FS / 2)  # noise power in the band
    top = np.sqrt(2 * band * 10 ** (30 / 10))  # amplitude 30 dB over the band
    # from 5 dB under the band at 2 s, +8.7 dB per e-fold: 12 dB over it at t12
    amplitude = top * np.minimum(10 ** (-35 / 20) * np.exp(rate * (t - 2.0)), 1.0) * (t >= 2.0)
    t12 = 2.0 + (12.0 + 5.0) / (20 * math.log10(math.e) * rate)
    ts = np.array([0.0, 1.0, 1.01, dur])
    speed = np.array([0.0, 0.0, 50.0, 50.0])
    for seed in range(5):
        rng = np.random.default_rng(seed)
        x = (rng.normal(0.0, sigma, t.size) + amplitude * np.sin(2 * np.pi * f * t)).astype(
            np.float32
        )
        d = detect(x, FS, speed_times_s=ts, speed_rad_s=speed)
        [e] = [e for e in d.episodes if abs(e.frequency_hz / f - 1) < 0.02]
        assert t12 - 0.3 <= e.start_s <= t12 + 0.1, (seed, e.start_s, t12)
        det = StreamingDetector(DetectorSettings(), FS)
        heard_at = math.inf
        for k in range(0, x.size, 480):  # 10-ms chunks: the frames as their samples arrive
            det.push(x[k : k + 480], k / FS, speed, ts)
            if det.heard_now and abs(det.frequency_now_hz / f - 1) < 0.02:
                heard_at = min(heard_at, (k + 480) / FS)
        assert heard_at <= t12 + 0.1, (seed, heard_at, t12)


@pytest.mark.parametrize("hum_db", [25.0, 55.0])
def test_a_squeak_beside_louder_hum_starts_where_it_stood_the_gate(hum_db):
    """Issue 30: a squeak at 224.75 Hz, 2.5 bins above mains hum at 200 Hz (learned at rest,
    `hum_db` over the squeak's third-octave band, which does not hold it), grows at 15 1/s
    (1.3 dB per 10 ms) to 15 dB over the hum. The tracker takes it only once it is louder than
    the hum in their critical band (with hum 25 dB over the band: about 170 ms after it stood
    the gate, `background_snr_db` over its band); offline, the episode starts where it first
    stood the gate over its band and over the hum's window leakage at its frequency (the Hann
    side lobe, -32 dB: 55 dB hum leaks 23 dB over the band there, and the walk back must not
    take that for the squeak), within 20 ms (a frame's start is a hop), one episode, for every
    noise draw."""
    dur, f, rate, gate = 4.0, 224.75, 15.0, DetectorSettings().background_snr_db
    t = np.arange(int(dur * FS)) / FS
    band = SIGMA_ROOM**2 * f * (2 ** (1 / 6) - 2 ** (-1 / 6)) / (FS / 2)
    hum = np.sqrt(2 * band * 10 ** (hum_db / 10)) * np.sin(2 * np.pi * 200.0 * t)
    top = np.sqrt(2 * band * 10 ** ((hum_db + 15) / 10))  # saturation
    # from 5 dB under the band at 2 s, +8.7 dB per e-fold
    amplitude = (
        top * np.minimum(10 ** (-(hum_db + 20) / 20) * np.exp(rate * (t - 2.0)), 1.0) * (t >= 2.0)
    )
    leak_db = hum_db + 10 * math.log10(float(hann_leakage((f - 200.0) * 0.1)))  # 10-Hz bins
    t_gate = 2.0 + (gate + max(leak_db, 0.0) + 5.0) / (20 * math.log10(math.e) * rate)
    ts, speed = np.array([0.0, 1.0, 1.01, dur]), np.array([0.0, 0.0, 50.0, 50.0])
    for seed in range(3):
        noise = np.random.default_rng(seed).normal(0.0, SIGMA_ROOM, t.size)
        x = (noise + hum + amplitude * np.sin(2 * np.pi * f * t)).astype(np.float32)
        d = detect(x, FS, speed_times_s=ts, speed_rad_s=speed)
        assert [round(b.frequency_hz) for b in d.background] == [200]
        [e] = d.episodes
        assert e.frequency_hz == pytest.approx(f, rel=0.01)
        assert e.start_s == pytest.approx(t_gate, abs=0.02), (seed, e.start_s, t_gate)
        assert e.tracked_start_s is not None and e.tracked_start_s > e.start_s + 0.05
        assert e.as_dict()["tracked_start_s"] == e.tracked_start_s  # what calibration reads


def _room_at_rest_first(tones, dur=5.0, seed=3):
    """`dur` s of white noise and steady `tones` ((Hz, amplitude), ...), the drive at rest for
    the first 1 s and at 50 rad/s from 1.01 s on: (samples, speed times, speeds)."""
    t = np.arange(int(dur * FS)) / FS
    x = SIGMA_ROOM * np.random.default_rng(seed).standard_normal(t.size)
    for f, a in tones:
        x += a * np.sin(2 * np.pi * f * t + f)
    return x, t, np.array([0.0, 1.0, 1.01, dur]), np.array([0.0, 0.0, 50.0, 50.0])


def test_no_cap_on_candidates_hides_a_real_tone():
    """Ten steady background tones at 1-7.5 kHz, each alone in its critical band (learned at
    rest), were more than the 8 candidates a frame once had and rank above a 224 Hz squeak by
    ECMA-418-1's TNR against its limit (8 dB there, 16.8 dB at 224 Hz): the squeak, 15 dB
    over its band's background, is found, at once, and the tones are all background."""
    room = [(1000.0 * 1.25**i, 0.01) for i in range(10)]
    x, t, ts, speed = _room_at_rest_first(room)
    band = SIGMA_ROOM**2 * 224.0 * (2 ** (1 / 6) - 2 ** (-1 / 6)) / (FS / 2)
    x += np.sqrt(2 * band * 10**1.5) * np.sin(2 * np.pi * 224.0 * t) * ((t > 2.0) & (t < 3.0))
    d = detect(x.astype(np.float32), FS, speed_times_s=ts, speed_rad_s=speed)
    assert len(d.episodes) == 1
    [e] = d.episodes
    assert e.frequency_hz == pytest.approx(224.0, rel=0.01)
    assert e.start_s == pytest.approx(2.0, abs=0.06) and e.end_s == pytest.approx(3.0, abs=0.06)
    learned = sorted(b.frequency_hz for b in d.background)
    assert learned == pytest.approx([f for f, _ in room], rel=1e-3)


def test_a_loud_tone_switching_is_not_heard_at_other_frequencies():
    """A squeak 50 dB over the background jumps from 900 Hz to 224 Hz within one sample (a
    mode switch) and then stops at once: the frames around each switch hold the whole
    spectrum (splatter), heard nowhere but at the two squeak frequencies."""
    x, t, ts, speed = _room_at_rest_first([])
    a = SIGMA_ROOM * 10**2.5
    x += a * np.sin(2 * np.pi * 900.0 * t) * ((t > 1.5) & (t < 3.0))
    x += a * np.sin(2 * np.pi * 224.0 * t) * ((t >= 3.0) & (t < 4.5))
    d = detect(x.astype(np.float32), FS, speed_times_s=ts, speed_rad_s=speed)
    heard = sorted(
        (round(e.frequency_hz), round(e.start_s, 1), round(e.end_s, 1)) for e in d.episodes
    )
    assert heard == [(224, 3.0, 4.5), (900, 1.5, 3.0)], heard


def test_a_drive_sweep_the_tracker_followed_onto_a_squeak_is_split_off():
    """The drive's order 30 sweeps down (100 -> 20 rad/s from 2 s on, the background learned
    at rest first) and a louder squeak at 300 Hz starts just as the order passes it: the
    track that followed the order and then stayed on the squeak is two sounds; the order's
    part is drive noise (ratio 30), the squeak's episode starts where the squeak does."""
    t = np.arange(4 * FS) / FS
    ts, vs = np.array([0.0, 1.0, 1.3, 2.0, 4.0]), np.array([0.0, 0.0, 100.0, 100.0, 20.0])
    x = SIGMA_ROOM * np.random.default_rng(3).standard_normal(t.size)
    x += 0.01 * np.sin(30.0 * np.cumsum(np.interp(t, ts, vs)) / FS)
    crossing = 2.0 + (100.0 - 2 * np.pi * 300.0 / 30.0) / 40.0  # order 30 at 300 Hz
    on = (t > crossing) & (t < crossing + 1.0)
    x += 0.03 * np.sin(2 * np.pi * 300.0 * t) * on * np.minimum((t - crossing) / 0.02, 1.0)
    d = detect(x.astype(np.float32), FS, speed_times_s=ts, speed_rad_s=vs)
    [e] = d.episodes
    assert e.frequency_hz == pytest.approx(300.0, rel=0.01)
    assert crossing - 0.06 <= e.start_s <= crossing + 0.1
    swept = [r for r in d.rejected if r.end_s <= e.start_s + 0.02 and r.start_s < 2.5]
    assert swept and all(r.drive_ratio == pytest.approx(30.0, rel=0.01) for r in swept)


def test_a_second_track_of_a_rejected_tone_is_that_tone():
    """The drive's order 2 held at 123 Hz beside louder hum at 100 Hz (a bench of seed 31):
    for 60 ms its peak split in two and a second track ran beside the rejected one, within 2 %
    of it. It is that tone (rejected with its ratio); a tone 3 % off it, or outside its span,
    is not."""
    from leadscrew_ros.model.acoustics.detection import Episode, _inside_rejected

    def track(start, end, hz, **kw):
        tt = np.arange(start + 0.005, end, 0.01)
        return Episode(start, end, hz, 10.0, 10.0, -50.0, track_times_s=tt,
                       track_hz=np.full(tt.size, hz), **kw)  # fmt: skip

    det = StreamingDetector(DetectorSettings(), FS)
    order = track(6.345, 7.555, 119.8, drive_ratio=6.577)
    det.rejected.append(order)
    second, off, after = track(7.095, 7.155, 121.8), track(7.0, 7.1, 123.5), track(7.5, 7.6, 120)
    kept = _inside_rejected(det, [second, off, after])
    assert kept == [off, after]
    assert det.rejected[-1] is second and second.drive_ratio == 6.577


def test_a_sweep_piece_teaches_its_ratio_for_the_held_fragments():
    """A commutator at 57.3 x the screw's rotation (a bench of seed 2027): a 60-ms piece of it
    while the speed ramps, whose sound went on along the speed (rejected by `_went_with_speed`),
    and a 50-ms fragment of it at constant speed, too short and too steady to be seen moving.
    The sweep's ratio is learned (`drive_orders`), so the fragment is drive noise too; a tone
    at constant speed 5 % off that ratio is kept."""
    from leadscrew_ros.model.acoustics.detection import Episode, _went_with_speed

    r = 57.3
    ts, vs = np.array([0.0, 2.0, 4.0]), np.array([20.0, 200.0, 200.0])
    t = np.arange(4 * FS) / FS
    x = SIGMA_ROOM * np.random.default_rng(5).standard_normal(t.size)
    x += 0.02 * np.sin(r * np.cumsum(np.interp(t, ts, vs)) / FS)  # r |speed|, in rad/s

    def piece(start, end, ratio=r):
        tt = np.arange(start + 0.005, end, 0.01)
        hz = ratio * np.interp(tt, ts, vs) / (2 * np.pi)
        return Episode(start, end, float(np.median(hz)), 20.0, 20.0, -40.0, track_times_s=tt,
                       track_hz=hz)  # fmt: skip

    det = StreamingDetector(DetectorSettings(), FS)
    sweep, held, other = piece(1.0, 1.06), piece(3.0, 3.05), piece(3.2, 3.25, 1.05 * r)
    kept = _went_with_speed(det, [sweep, held, other], ts, vs, x.astype(np.float32), 0.0)
    assert kept == [other]
    assert [round(o.ratio, 1) for o in det.drive_orders] == [r]
    assert held.drive_ratio == pytest.approx(r) and sweep.drive_ratio == pytest.approx(r, rel=0.01)


def test_a_squeaks_harmonics_belong_to_its_episode():
    """A squeak at 700 Hz with its 2nd and 3rd harmonics, the 2nd louder than the fundamental
    from 0.9 s on (a frame then holds the harmonic stronger: not suppressed as one, it was a
    squeak of its own): one episode at 700 Hz with harmonics_hz [1400]; the 3rd, weak enough
    to be taken as a harmonic in every frame, never makes a track."""
    t = np.arange(2 * FS) / FS
    on = (t > 0.5) & (t < 1.5)
    loud2 = np.where(t > 0.9, 0.05, 0.01)
    x = 0.003 * np.random.default_rng(4).standard_normal(t.size)
    x += on * (0.02 * np.sin(2 * np.pi * 700 * t) + loud2 * np.sin(2 * np.pi * 1400 * t))
    x += on * 0.005 * np.sin(2 * np.pi * 2100 * t)
    d = detect(x.astype(np.float32), FS)
    [e] = d.episodes
    assert round(e.frequency_hz) == 700 and [round(f) for f in e.harmonics_hz] == [1400]
    assert e.start_s == pytest.approx(0.5, abs=0.05) and e.end_s == pytest.approx(1.5, abs=0.05)
    assert d.as_dict()["episodes"][0]["harmonics_hz"] == e.harmonics_hz


def test_detection_is_json_safe():
    t = np.linspace(0.0, 2.0, 201)
    sq = np.where((t >= 0.5) & (t < 1.5), 3000.0, np.nan)
    d = detect(
        microphone(t, np.full(t.size, 20.0), sq, squeak_level=0.02, sample_rate_hz=16000), 16000
    )
    assert len(d.episodes) == 1 and any("limits the analysis" in w for w in d.warnings)
    text = json.dumps(d.as_dict(), allow_nan=False)
    back = json.loads(text)
    assert back["scale"] == "full scale" and None in back["frequency_hz"]  # nan -> None
    assert len(back["frequency_hz"]) == len(back["heard"]) == d.frame_times_s.size


def _episodes_equal(a, b):
    """The same episodes, but for what only the offline detection measures (the growth)."""
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        keep = {k: v for k, v in x.as_dict().items() if not k.startswith("growth")}
        assert keep == {k: v for k, v in y.as_dict().items() if not k.startswith("growth")}
        np.testing.assert_array_equal(x.track_hz, y.track_hz)


def test_detect_and_streaming_agree_frame_for_frame():
    """Chunks of random sizes (1 sample to 0.3 s), the speed given per chunk at its samples
    every 5 ms: the same episodes, the same heard frames and frequencies."""
    t = np.linspace(0.0, 4.0, 401)
    speed = np.geomspace(30.0, 700.0, t.size)
    sq = np.where(((t >= 0.5) & (t < 1.2)) | ((t >= 2.0) & (t < 3.1)), 1234.0, np.nan)
    x = microphone(t, speed, sq, squeak_level=0.01, motor_orders=(12, 24, 37), motor_level=0.2)
    st = np.arange(0.0, 4.0 + 1e-9, 0.005)
    sv = np.interp(st, t, speed)
    t0 = 12.5
    ref = detect(x, FS, t0_s=t0, speed_times_s=st + t0, speed_rad_s=sv)
    assert len(ref.episodes) >= 2 and ref.rejected  # order 24 crosses the second one
    rng = np.random.default_rng(0)
    det = StreamingDetector(DetectorSettings(), FS)
    got, pos, heard_now = [], 0, []
    while pos < x.size:
        n = int(rng.choice([1, 17, 480, 2000, 4800, 14400]))
        a, b = pos / FS, (pos + n) / FS
        m = (st >= a) & (st < b)
        got += det.push(x[pos : pos + n], t0 + a, sv[m], st[m] + t0)
        heard_now.append((t0 + b, det.heard_now, det.frequency_now_hz))
        pos += n
    got += det.flush()
    _episodes_equal(ref.episodes, got)
    assert len(det.rejected) == len(ref.rejected)
    heard, freq = frames_heard(ref.frame_times_s, got)
    np.testing.assert_array_equal(heard, ref.heard)
    np.testing.assert_array_equal(freq, ref.frequency_hz)
    mid = [h for tt, h, f in heard_now if 0.7 < tt - t0 < 1.1 or 2.2 < tt - t0 < 3.0]
    assert mid and all(mid)
    assert all(f == pytest.approx(1234.0, rel=0.01) for tt, h, f in heard_now if h)
    assert not any(h for tt, h, f in heard_now if 1.4 < tt - t0 < 1.8)


def test_streaming_memory_is_bounded():
    det = StreamingDetector(DetectorSettings(loudness_max_s=0.5), FS)
    rng = np.random.default_rng(0)
    for k in range(200):
        det.push(rng.normal(0.0, 0.01, 4800).astype(np.float32), k * 0.1, 20.0)
    assert det._buf.size < 1.0 * FS and det._speed_t.size < 100


def test_streaming_sample_rate_change_and_discontinuity():
    det = StreamingDetector(DetectorSettings(), FS)
    x = gated_tone(898.0, 20.0, 0, dur=1.0, on=(0.2, 1.0))
    assert det.push(x, 0.0) == [] and det.heard_now
    eps = det.push(x[:16000], 1.0, sample_rate_hz=16000)  # new rate: the open one closes
    assert len(eps) == 1 and eps[0].end_s == pytest.approx(1.0, abs=0.05)
    assert any("sample rate changed from 48000 to 16000 Hz" in w for w in det.warnings)
    assert det.sample_rate_hz == 16000 and det.frame_len == 1600
    det.push(np.zeros(8000), 5.0)  # a 3 s jump
    assert any("discontinuity" in w for w in det.warnings)
    with pytest.raises(AudioError):
        det.push(x, 6.0, sample_rate_hz=-1)
    det.push(x[:100], math.nan)  # unusable time: contiguous
    assert any("not finite" in w for w in det.warnings)
    det.push(x[:100], 6.0, speed_rad_s=[1.0, 2.0], speed_times_s=[1.0])
    assert any("speeds for" in w for w in det.warnings)


def test_calibrated_levels_and_loudness():
    pytest.importorskip("mosqito")
    x = gated_tone(898.0, 30.0, 0, dur=0.8, on=(0.2, 0.6))
    d = detect(x, FS, scale_pa=2.0, settings=DetectorSettings(loudness_max_s=0.5))
    (ep,) = d.episodes
    ref = detect(x, FS).episodes[0]
    assert d.scale == "Pa"
    assert ep.level_db == pytest.approx(ref.level_db + 20 * np.log10(2.0 / 20e-6), abs=1e-6)
    assert ep.loudness_sone is not None and 1.0 < ep.loudness_sone < 100.0
    louder = detect(x * 4, FS, scale_pa=2.0, settings=DetectorSettings(loudness_max_s=0.5))
    assert louder.episodes[0].loudness_sone > 1.5 * ep.loudness_sone


def test_settings_are_checked():
    with pytest.raises(ValueError, match="hop_s"):
        DetectorSettings(hop_s=0.2, frame_s=0.1)
    with pytest.raises(ValueError, match="out of range"):
        DetectorSettings(track_tolerance=0.5)
    with pytest.raises(ValueError, match="f_lo_hz"):
        DetectorSettings(f_lo_hz=5000.0, f_hi_hz=4000.0)


class _SlicedTrack(SampleTrack):
    """An array seen only through slices, the longest read kept (a log's track is on disk)."""

    def __init__(self, x):
        self.x, self.longest = x, 0

    @property
    def size(self):
        return self.x.size

    def read(self, start, stop):
        self.longest = max(self.longest, stop - start)
        return self.x[start:stop].copy()


def test_a_track_read_by_slices_gives_the_same_detection_without_reading_it_whole():
    """Every pass of the offline detection (background at rest or inferred, the tracks, the
    sweeps, creaks, growth) reads a `SampleTrack` by slices, never whole, and finds exactly
    what it finds in the array (a geared drive: rest, sweeps, squeaks, a dropout)."""
    x, ts, speed = _geared_drive()
    x[int(2 * FS) : int(2 * FS) + 500] = np.nan  # a dropout: not scored, either way
    for kwargs in (dict(speed_times_s=ts, speed_rad_s=speed), dict(infer_background=True)):
        track = _SlicedTrack(x)
        a, b = detect(x, FS, **kwargs), detect(track, FS, **kwargs)
        assert 0 < track.longest <= x.size // 2
        _episodes_equal(a.episodes, b.episodes)
        assert [e.growth for e in a.episodes] == [e.growth for e in b.episodes]
        assert a.as_dict() == b.as_dict()
        np.testing.assert_array_equal(a.usable, b.usable)
        assert a.episodes or a.background


def test_live_a_drive_tone_heard_only_at_constant_speed_is_learned_at_the_end_of_its_hold():
    """Live, chunk by chunk: a commutator (373 x the screw) loud only near full speed first
    sounds during the hold, where nothing tells it from a squeak, so it is heard; it ends as
    the speed leaves, exactly with the hold, so the closed episode is drive noise
    (`learn_held`) and its ratio learned: in the next stroke's hold it is not heard. The
    speed reads with an encoder's noise (0.05 %), which is no motion of the speed."""
    stroke = 12 * FS
    t = np.arange(2 * int(stroke)) / FS
    ts = np.arange(0.0, 24.0, 0.01)
    knots = ([0, 1, 3, 9, 11, 12], [0, 0, 100, 100, 0, 0])
    speed = np.interp(ts % 12.0, *knots)
    speed *= 1 + 5e-4 * np.random.default_rng(2).standard_normal(ts.size)
    turns = np.cumsum(np.interp(t % 12.0, *knots)) / FS
    x = 0.003 * np.random.default_rng(8).standard_normal(t.size)
    x += 0.01 * np.sin(373.0 * turns) * (np.interp(t % 12.0, *knots) > 99.0)
    det = StreamingDetector(DetectorSettings(), FS)
    heard = {}
    for k in range(0, x.size, 4800):
        t1 = (k + 4800) / FS
        known = ts <= t1
        closed = det.push(x[k : k + 4800], k / FS, speed[known], ts[known])
        det.learn_held(closed, ts[known], speed[known])
        heard[round(t1, 1)] = det.heard_now
    assert any(heard[round(t, 1)] for t in np.arange(4.0, 8.5, 0.1))  # the first hold
    assert any(abs(o.ratio / 373.0 - 1) < 0.005 for o in det.drive_orders)
    assert not any(heard[round(t, 1)] for t in np.arange(15.0, 21.0, 0.1))  # the next one
