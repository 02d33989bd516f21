# SPDX-License-Identifier: Apache-2.0
"""The realistic bench's sound (`model.acoustics.bench_sound`, `envelope`, `room`): the squeak's
amplitude equation (grows at sigma, saturates, decays, never below the floor; exact against an
ODE solver), the squeak in the samples growing at sigma, its harmonics, the geared motor's
orders at a non-whole ratio only while it turns and rising with speed, the background (fan,
hum, pink noise) in the motor-off stretches, the room's RT60, each part switched off, the
audibility rule, and the seed."""

from dataclasses import replace

import numpy as np
import pytest
import scipy.integrate
import scipy.signal

from leadscrew_ros.model.acoustics import room
from leadscrew_ros.model.acoustics.bench_sound import OFF_DB, BenchSound, bench_microphone
from leadscrew_ros.model.acoustics.envelope import squeak_envelope
from leadscrew_ros.model.physics.parameters import ParameterError

FS = 16000
SAT = 0.1  # saturation amplitude [FS], -20 dBFS
#: every part off: only the squeak's fundamental sounds
QUIET = BenchSound(
    harmonic2_db=OFF_DB,
    harmonic3_db=OFF_DB,
    motor_level_dbfs=OFF_DB,
    commutator_segments=0,
    fan_hz=0.0,
    mains_hz=0.0,
    pink_noise_dbfs=OFF_DB,
    rt60_s=0.0,
)


def _amp(x: np.ndarray, f_hz: float, start_s: float, length_s: float = 1.0) -> float:
    """Amplitude [FS] of the tone at `f_hz` in x[start_s, start_s + length_s] (flat-top)."""
    seg = np.asarray(x[int(start_s * FS) :][: int(length_s * FS)], float)
    w = scipy.signal.windows.flattop(seg.size, sym=False)
    spectrum = np.abs(np.fft.rfft(seg * w)) * 2 / w.sum()
    k = int(round(f_hz * seg.size / FS))
    return float(spectrum[max(k - 1, 0) : k + 2].max())


def _db(a: float) -> float:
    return 20 * np.log10(max(a, 1e-15))


def _stroke(sigma: float = -100.0, f_hz: float = 700.0):
    """1 s motor off, 100 rad/s for 1.5 s, 50 rad/s for 1.5 s, 1 s motor off (ramps 0.1 s)."""
    times = np.arange(0, 5.2 + 1e-9, 0.01)
    speed = np.interp(times, [0, 1.0, 1.1, 2.6, 2.7, 4.1, 4.2, 5.2], [0, 0, 100, 100, 50, 50, 0, 0])
    return times, speed, np.full(times.size, sigma), np.full(times.size, f_hz)


def _mic(sound: BenchSound, sigma: float = -100.0, f_hz: float = 700.0, seed: int = 1):
    times, speed, s, f = _stroke(sigma, f_hz)
    return bench_microphone(times, speed, s, f, SAT, 100.0, sound, FS, seed)


def test_the_amplitude_equation():
    """Grows at sigma from the floor, saturates at the level, decays at sigma when stable, never
    below the floor; exact (an ODE solver of the same law agrees) with sigma varying."""
    step, floor = 1 / 2000, SAT * 1e-3
    sigma = np.concatenate([np.full(2000, 80.0), np.full(2000, -50.0)])
    a = squeak_envelope(sigma, step, SAT, floor)
    t = np.arange(a.size) * step
    assert a[0] == floor and a.min() >= floor and a.max() <= SAT
    unsaturated = (t < 1) & (a < SAT * 0.1) & (a > 2 * floor)
    slope = np.polyfit(t[unsaturated], np.log(a[unsaturated]), 1)[0]
    assert slope == pytest.approx(80.0, rel=0.05)
    assert _db(a[1999] / SAT) == pytest.approx(0.0, abs=0.01)  # saturated
    decay = (t > 1.001) & (a > 2 * floor)
    assert np.polyfit(t[decay], np.log(a[decay]), 1)[0] == pytest.approx(-50.0, rel=0.01)
    assert a[-1] == floor  # held at the floor, not below

    varying = 150 * np.sin(2 * np.pi * np.arange(4000) * step / 1.3) + 20
    a = squeak_envelope(varying, step, SAT, floor)

    def rhs(time, y):
        s = varying[min(int(time / step), varying.size - 1)]  # held over each step
        return [s * (1 - np.exp(2 * y[0]) / SAT**2) if s > 0 else s]

    # up to the first time the floor holds it (the solver knows no floor)
    first = np.flatnonzero((a[1:] == floor) & (varying[:-1] < 0))
    end = int(first[0]) if first.size else a.size - 1
    sol = scipy.integrate.solve_ivp(
        rhs,
        (0, end * step),
        [np.log(floor)],
        t_eval=np.arange(end + 1) * step,
        rtol=1e-9,
        atol=1e-9,
        max_step=step / 4,
    )
    assert end > 500
    np.testing.assert_allclose(np.log(a[: end + 1]), sol.y[0], atol=2e-3)


def test_the_squeak_in_the_samples_grows_at_sigma_and_saturates():
    """Demodulated at its frequency, the fundamental grows at sigma (within 5 %) between the
    floor and saturation, then stands at the squeak level; the truth's envelope agrees."""
    sound = replace(QUIET, squeak_floor_db=-80.0)
    times = np.arange(0, 1.0 + 1e-9, 0.01)
    sigma = np.where(times < 0.2, -10.0, 60.0)
    audio = bench_microphone(times, 0 * times, sigma, 700.0 + 0 * times, SAT, 100.0, sound, FS)
    x = audio.samples.astype(float)
    t = np.arange(x.size) / FS
    z = x * np.exp(-2j * np.pi * 700.0 * t)
    frame = FS // 100  # 10 ms: 7 periods, a moving mean removes the 1400 Hz image
    envelope = 2 * np.abs(np.convolve(z, np.ones(frame) / frame, mode="same"))
    centre = np.arange(frame, x.size - frame, frame // 4)
    a = envelope[centre]
    growing = (t[centre] > 0.22) & (a < SAT * 0.1) & (a > SAT * 10 ** (-74 / 20))
    assert growing.sum() > 10
    slope = np.polyfit(t[centre][growing], np.log(a[growing]), 1)[0]
    assert slope == pytest.approx(60.0, rel=0.05)
    assert _db(a[-5] / SAT) == pytest.approx(0.0, abs=0.2)
    truth = np.interp(t[centre], audio.grid_s, audio.amplitude)
    np.testing.assert_allclose(_db_array(a), _db_array(truth), atol=0.5)


def _db_array(a: np.ndarray) -> np.ndarray:
    return 20 * np.log10(np.maximum(a, 1e-15))


def test_harmonics_at_their_levels():
    x = _mic(replace(QUIET, harmonic2_db=-12.0, harmonic3_db=-20.0), sigma=200.0).samples
    fundamental = _amp(x, 700, 2.0)
    assert _db(fundamental / SAT) == pytest.approx(0.0, abs=0.1)
    assert _db(_amp(x, 1400, 2.0) / fundamental) == pytest.approx(-12.0, abs=0.2)
    assert _db(_amp(x, 2100, 2.0) / fundamental) == pytest.approx(-20.0, abs=0.2)
    x = _mic(QUIET, sigma=200.0).samples
    assert _amp(x, 1400, 2.0) < 1e-6 and _amp(x, 2100, 2.0) < 1e-6


def test_the_geared_motor():
    """At a non-whole ratio its orders 1 and 2 and the commutator sound at R, 2R and 10R times
    the screw's rotation frequency, at their levels at the reference speed, 6 dB lower at half
    of it, and not at all while the motor is off."""
    sound = replace(QUIET, motor_level_dbfs=-40.0, commutator_segments=10)
    x = _mic(sound).samples
    r = sound.gear_ratio
    assert r == 37.3
    f1 = 100 / (2 * np.pi)  # screw rotation at 100 rad/s [Hz]
    for order, level in ((r, -40.0), (2 * r, -46.0), (10 * r, -50.0)):
        assert _db(_amp(x, order * f1, 1.3)) == pytest.approx(level, abs=0.3), order
        assert _db(_amp(x, order * f1 / 2, 2.9)) == pytest.approx(level - 6.02, abs=0.3), order
        for quiet_s in (0.0, 4.2):  # motor off
            assert _amp(x, order * f1, quiet_s) < 1e-6
    # at 37.3, not at the nearest whole order 37
    assert _db(_amp(x, 37 * f1, 1.3, 1.5)) < -40.0 - 30


def test_the_background_sounds_while_the_motor_is_off():
    sound = replace(QUIET, fan_hz=1170.0, mains_hz=50.0, pink_noise_dbfs=-50.0)
    x = _mic(sound, f_hz=3000.0).samples
    for start in (0.0, 4.2):  # the motor-off stretches
        assert _db(_amp(x, 1170, start)) == pytest.approx(-45.0, abs=1.0)
        for k, f in enumerate((100, 200, 300)):
            assert _db(_amp(x, f, start)) == pytest.approx(-45.0 - _db(k + 1), abs=1.0), f
    floor = SAT * 1e-3 * np.sin(2 * np.pi * 3000 * np.arange(1, x.size + 1) / FS)  # squeak
    pink = _mic(replace(QUIET, pink_noise_dbfs=-50.0), f_hz=3000.0).samples - floor
    assert np.abs(_mic(QUIET, f_hz=3000.0).samples - floor).max() < 1e-6  # pink noise off
    # level: rms of a -50 dBFS noise; 1/f: equal power in every octave
    assert 20 * np.log10(np.sqrt(2 * np.mean(pink**2))) == pytest.approx(-50.0, abs=0.5)
    f, psd = scipy.signal.welch(pink, FS, nperseg=4096)
    octaves = [psd[(f >= c / np.sqrt(2)) & (f < c * np.sqrt(2))].sum() for c in (125, 1000, 4000)]
    assert 10 * np.log10(max(octaves) / min(octaves)) < 1.5


def _rt60(energy: np.ndarray) -> float:
    """RT60 [s] from Schroeder's backward integral of `energy` (samples from a stop), its
    slope between -5 and -25 dB."""
    edc = 10 * np.log10(np.cumsum(energy[::-1])[::-1] / energy.sum() + 1e-30)
    t = np.arange(edc.size) / FS
    fit = (edc < -5) & (edc > -25)
    return float(-60 / np.polyfit(t[fit], edc[fit], 1)[0])


def test_the_room_lengthens_the_decay():
    """A saturated squeak stopped abruptly: without the room it is gone within milliseconds;
    with it the reverberant part decays 60 dB in RT60, measured within 20 % (the energy after
    the stop summed over 12 squeak frequencies: one tone's decay through a random tail
    fluctuates by tens of per cent), and the room's impulse response's own within 10 %."""
    times = np.arange(0, 2.0 + 1e-9, 0.01)
    sigma = np.where(times < 1.0, 300.0, -3000.0)
    sound = replace(QUIET, squeak_floor_db=-120.0)

    def stopped(f_hz: float, rt60: float) -> np.ndarray:
        s = replace(sound, rt60_s=rt60)
        x = bench_microphone(times, 0 * times, sigma, f_hz + 0 * times, SAT, 100.0, s, FS)
        return x.samples[int(1.005 * FS) :].astype(float)

    for rt60 in (0.3, 1.0):
        energy = sum(stopped(f, rt60) ** 2 for f in np.geomspace(400, 4000, 12))
        assert _rt60(energy) == pytest.approx(rt60, rel=0.2), rt60
        h = room.impulse_response(rt60, FS, np.random.default_rng(0))
        assert np.sum(h**2) == pytest.approx(1.0, rel=1e-9)
        assert _rt60(h[1:] ** 2) == pytest.approx(rt60, rel=0.1)
    assert np.abs(stopped(1000.0, 0.0)[int(0.015 * FS) :]).max() < SAT * 1e-4


@pytest.mark.parametrize(
    ("part", "on", "f_hz", "start_s"),
    [
        ("harmonic2_db", -12.0, 1400.0, 2.0),
        ("harmonic3_db", -20.0, 2100.0, 2.0),
        ("motor_level_dbfs", -40.0, 37.3 * 100 / (2 * np.pi), 1.3),
        ("commutator_segments", 10, 373.0 * 100 / (2 * np.pi), 1.3),
        ("fan_hz", 1170.0, 1170.0, 0.0),
        ("mains_hz", 50.0, 100.0, 0.0),
    ],
)
def test_each_part_switches_off(part, on, f_hz, start_s):
    """Each part on alone: its tone is there; off (`QUIET`): not."""
    if part == "commutator_segments":
        base = replace(QUIET, commutator_level_dbfs=-50.0)  # its level; the motor stays off
    else:
        base = QUIET
    heard = _amp(_mic(replace(base, **{part: on}), sigma=200.0).samples, f_hz, start_s)
    silent = _amp(_mic(base, sigma=200.0).samples, f_hz, start_s)
    assert heard > 10 ** (-60 / 20) and silent < heard * 1e-4, (heard, silent)


def test_audible_where_the_squeak_stands_over_its_band():
    """The rule: level at the microphone more than audible_snr_db over the background's
    third-octave band; the background's band level agrees with the samples' (motor off)."""
    # no room: through it one tone's level moves by a few dB (the bench test has the room)
    sound = replace(QUIET, fan_hz=1170.0, pink_noise_dbfs=-50.0)
    times = np.arange(0, 3.0 + 1e-9, 0.01)
    sigma = np.where((times > 1.0) & (times < 2.0), 40.0, -30.0)
    audio = bench_microphone(times, 0 * times, sigma, 1100.0 + 0 * times, SAT, 100.0, sound, FS)
    assert audio.audible.any() and not audio.audible.all()
    np.testing.assert_array_equal(
        audio.audible, audio.level_dbfs - audio.background_dbfs > sound.audible_snr_db
    )
    # the band level from the samples before the squeak rises (floor 60 dB under it)
    x = audio.samples[:FS].astype(float)
    f, psd = scipy.signal.welch(x, FS, nperseg=FS // 4)  # density: sum * df is the power
    band = (f >= 1100 * 2 ** (-1 / 6)) & (f < 1100 * 2 ** (1 / 6))
    measured = 10 * np.log10(2 * psd[band].sum() * (f[1] - f[0]))
    assert audio.background_dbfs[0] == pytest.approx(measured, abs=1.0)
    (onset,) = audio.onsets
    assert onset.growth_rate_per_s == 40.0
    assert onset.fitted_growth_per_s == pytest.approx(40.0, rel=0.05)
    i = np.searchsorted(audio.grid_s, onset.time_s)
    assert audio.level_dbfs[i] - measured == pytest.approx(sound.audible_snr_db, abs=1.5)


def test_same_seed_same_sound_and_bad_settings():
    a, b, c = (_mic(BenchSound(), sigma=50.0, seed=s).samples for s in (4, 4, 5))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    for bad in ({"fan_hz": -1.0}, {"rt60_s": 11.0}, {"commutator_segments": 2.5}):
        with pytest.raises(ParameterError, match="bench.sound."):
            BenchSound(**bad)
    times, speed, s, f = _stroke()
    with pytest.raises(ValueError, match="finite throughout"):
        bench_microphone(times, speed, s, np.where(times > 1, f, np.nan), SAT, 100.0, QUIET, FS)
    silent = bench_microphone(times, speed, s, np.full(times.size, np.nan), SAT, 100.0, QUIET, FS)
    assert not silent.audible.any() and np.abs(silent.samples).max() == 0
