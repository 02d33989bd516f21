# SPDX-License-Identifier: Apache-2.0
"""A bench that sounds like a bench: the squeak grown by its amplitude equation, with
harmonics, a geared motor, a background that also sounds while the drive is off, a room.

The parts (each switched off by its setting, see `BenchSound`):

- squeak: the fundamental at the most unstable mode's frequency (phase-continuous through
  changes and mode switches: the amplitude carries over), amplitude A(t) from
  `envelope.squeak_envelope` (grows at the model's Re(lambda) from a floor, saturates at the
  squeak level, decays when stable), and its 2nd and 3rd harmonics at stated levels re the
  fundamental, following the same envelope (none above the Nyquist frequency);
- geared motor: the motor shaft turns `gear_ratio` times the screw; its orders 1 and 2 (the
  second 6 dB under the first) and the commutator at `commutator_segments` times the motor
  speed, amplitudes proportional to |speed| (stated at the reference speed) and faded out
  below `synthesis.HIGH_PASS_HZ`: nothing while the motor stands;
- background, the whole log: a fan tone at `fan_hz`, mains hum at 2, 4 and 6 times
  `mains_hz` (amplitudes 1, 1/2, 1/3 of `hum_level_dbfs`), pink noise (power density 1/f
  from `PINK_LOW_HZ` to the Nyquist frequency) at `pink_noise_dbfs`;
- room: everything above heard through `room.reverberate` (RT60 `rt60_s`).

Levels are dB re full scale for a sine (dBFS: a tone of amplitude a is 20 log10 a, a noise of
rms r is 20 log10(r sqrt 2)); a level at `OFF_DB` switches its part off.

Audible (`BenchAudio.audible`): the squeak's fundamental stands more than `audible_snr_db`
over the background in its third-octave band (f 2^-1/6 .. f 2^1/6): the squeak's level at the
microphone is the envelope's mean square through the room's expected energy response
(`room.energy_response`), the background's band level is the pink noise's power in the band
plus the fan and hum tones inside it (the drive's orders are not background: they stop with
the motor). With no background at all every squeak, the floor included, is audible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..physics.metadata import check, documented, setting
from ..physics.parameters import ParameterError
from . import room
from .envelope import ENVELOPE_RATE_HZ, squeak_envelope
from .synthesis import shaft_orders

OFF_DB = -200.0  #: a level at this [dB] switches its part off
PINK_LOW_HZ = 20.0  #: the pink noise starts here [Hz]
HUM_MULTIPLES = (2, 4, 6)  #: mains hum at these multiples of the mains frequency
MOTOR_ORDER_2_DB = -6.0  #: motor order 2 re order 1
ONSET_WINDOW_S = 0.025  #: the growth at an onset is fitted within this of it
ONSET_UNSATURATED_DB = -20.0  #: ... where A is at least this under saturation
ONSET_OVER_FLOOR_DB = 6.0  #: ... and this over the floor


def envelope_growth(
    envelope_db: Any, rate_hz: float, window_s: tuple[float, float]
) -> float | None:
    """The growth rate a measurement over `window_s` should find: the least-squares slope of
    ln A [1/s] of an envelope in dB (20 log10 A, sampled at `rate_hz` [Hz] from t = 0, as
    truth.json keeps it) over the window [s]. Where sigma still rises after the onset (a
    ramp into the band) it exceeds the growth at the onset (`Onset`): a rate measured at one
    time is compared at that time. None with fewer than 3 envelope points in the window.

    Parameters
    ----------
    envelope_db : array_like
        The envelope [dB], one value per 1 / `rate_hz`.
    rate_hz : float
        Its sample rate [Hz].
    window_s : tuple of float
        Start and end of the window [s].

    Returns
    -------
    float or None
        The slope [1/s].
    """
    level = np.asarray(envelope_db, float)
    t = np.arange(level.size) / rate_hz
    inside = (t >= window_s[0]) & (t <= window_s[1])
    if np.count_nonzero(inside) < 3:
        return None
    return float(np.polyfit(t[inside], level[inside] * (math.log(10.0) / 20.0), 1)[0])


def _level(db: float) -> float:
    """Amplitude [FS] of a level [dBFS]; 0 at `OFF_DB`."""
    return 0.0 if db <= OFF_DB else float(10.0 ** (db / 20.0))


@documented
@dataclass(frozen=True)
class BenchSound:
    """The parts of a realistic bench's sound (see the module; levels in dBFS, `OFF_DB` off)."""

    rest_s: float = setting(
        1.5,
        "s",
        "motor-off time added before and after the stroke (speed 0: only the background sounds)",
        0.0,
        60.0,
    )
    squeak_floor_db: float = setting(
        -60.0,
        "dB",
        "noise floor of the squeak's amplitude re its saturated level (below the default "
        "background in every band): where it grows from, what it decays to",
        -120.0,
        -6.0,
    )
    harmonic2_db: float = setting(
        -12.0, "dB", "2nd harmonic of the squeak re its fundamental (-200: off)", OFF_DB, 0.0
    )
    harmonic3_db: float = setting(
        -20.0, "dB", "3rd harmonic of the squeak re its fundamental (-200: off)", OFF_DB, 0.0
    )
    gear_ratio: float = setting(
        37.3, "1", "motor turns per screw turn (a worm or planetary gear)", 0.5, 2000.0
    )
    motor_level_dbfs: float = setting(
        -40.0,
        "dBFS",
        "motor order 1 at the reference (peak) speed, order 2 6 dB under it; amplitude "
        "proportional to the speed (-200: off)",
        OFF_DB,
        0.0,
    )
    commutator_segments: int = setting(
        10, "1", "commutator segments: a tone at this order of the motor (0: off)", 0, 1000
    )
    commutator_level_dbfs: float = setting(
        -50.0,
        "dBFS",
        "commutator tone at the reference (peak) speed, proportional to the speed (-200: off)",
        OFF_DB,
        0.0,
    )
    fan_hz: float = setting(1170.0, "Hz", "a fan's steady tone (0: off)", 0.0, 96000.0)
    fan_level_dbfs: float = setting(-45.0, "dBFS", "the fan tone's level (-200: off)", OFF_DB, 0.0)
    mains_hz: float = setting(
        50.0, "Hz", "mains frequency: hum at 2, 4 and 6 times it (0: off)", 0.0, 1000.0
    )
    hum_level_dbfs: float = setting(
        -45.0,
        "dBFS",
        "hum at 2 x mains; 4 x and 6 x at 1/2 and 1/3 of it (-200: off)",
        OFF_DB,
        0.0,
    )
    pink_noise_dbfs: float = setting(
        -50.0, "dBFS", "pink noise from 20 Hz to the Nyquist frequency (-200: off)", OFF_DB, 0.0
    )
    rt60_s: float = setting(0.3, "s", "the room's reverberation time (0: no room)", 0.0, 10.0)
    audible_snr_db: float = setting(
        6.0,
        "dB",
        "the squeak is audible (truth.json) this far over the background in its third-octave band",
        0.0,
        60.0,
    )

    def __post_init__(self) -> None:
        check(self, ParameterError, "bench.sound.")

    @property
    def background_tones(self) -> list[tuple[float, float]]:
        """(frequency [Hz], amplitude [FS]) of the background's tones that are on."""
        tones = [(self.fan_hz, _level(self.fan_level_dbfs))] if self.fan_hz > 0 else []
        if self.mains_hz > 0:
            hum = _level(self.hum_level_dbfs)
            tones += [(m * self.mains_hz, hum / (k + 1)) for k, m in enumerate(HUM_MULTIPLES)]
        return [(f, a) for f, a in tones if a > 0]

    @property
    def drive_orders(self) -> list[tuple[float, float]]:
        """(order of the screw speed, amplitude [FS] at the reference speed) that are on."""
        motor, r = _level(self.motor_level_dbfs), self.gear_ratio
        orders = [(r, motor), (2 * r, motor * 10.0 ** (MOTOR_ORDER_2_DB / 20.0))]
        if self.commutator_segments:
            orders.append((self.commutator_segments * r, _level(self.commutator_level_dbfs)))
        return [(k, a) for k, a in orders if a > 0]

    def background_band_dbfs(self, frequency_hz: Any, sample_rate_hz: float) -> np.ndarray:
        """The background's level [dBFS] in the third-octave band centred on each frequency
        (-inf where there is none)."""
        f = np.asarray(frequency_hz, float)
        lo, hi = f * 2.0 ** (-1 / 6), f * 2.0 ** (1 / 6)
        nyquist = sample_rate_hz / 2.0
        pink = _level(self.pink_noise_dbfs) ** 2 / 2.0  # mean square
        share = np.log(np.clip(hi, PINK_LOW_HZ, nyquist) / np.clip(lo, PINK_LOW_HZ, nyquist))
        power = pink * share / np.log(nyquist / PINK_LOW_HZ)
        for tone_hz, amplitude in self.background_tones:
            power = power + np.where((lo <= tone_hz) & (tone_hz < hi), amplitude**2 / 2.0, 0.0)
        with np.errstate(divide="ignore"):
            return 10.0 * np.log10(2.0 * power)


@dataclass(frozen=True)
class Onset:
    """Where the squeak becomes audible, with the growth-rate truth there.

    Attributes
    ----------
    time_s : float
        Start of the audible interval [s].
    frequency_hz : float
        The squeak's frequency there [Hz].
    growth_rate_per_s : float
        The model's Re(lambda) of the mode there [1/s].
    fitted_growth_per_s : float or None
        Slope of ln A [1/s] fitted where A grows unsaturated within `ONSET_WINDOW_S` of the
        onset (at least `ONSET_OVER_FLOOR_DB` over the floor, `ONSET_UNSATURATED_DB` under
        saturation); None when fewer than 3 points are (`reason` says why).
    window_s : tuple of float or None
        The fitted span [s].
    reason : str
        Why there is no fit ('' with one).
    """

    time_s: float
    frequency_hz: float
    growth_rate_per_s: float
    fitted_growth_per_s: float | None
    window_s: tuple[float, float] | None
    reason: str = ""


@dataclass(frozen=True)
class BenchAudio:
    """A realistic bench recording and its truth on the envelope grid.

    Attributes
    ----------
    samples : numpy.ndarray
        float32 microphone samples.
    grid_s : numpy.ndarray
        Envelope grid times [s] (`envelope.ENVELOPE_RATE_HZ`).
    amplitude : numpy.ndarray
        The squeak's fundamental amplitude A at the source [FS] on the grid.
    frequency_hz, growth_rate_per_s : numpy.ndarray
        The squeak's frequency [Hz] and sigma [1/s] on the grid.
    level_dbfs, background_dbfs : numpy.ndarray
        The fundamental's level at the microphone and the background in its third-octave
        band [dBFS] on the grid.
    audible : numpy.ndarray
        Bool on the grid: level over background by more than `audible_snr_db`.
    onsets : list of Onset
        One per audible interval.
    """

    samples: np.ndarray
    grid_s: np.ndarray
    amplitude: np.ndarray
    frequency_hz: np.ndarray
    growth_rate_per_s: np.ndarray
    level_dbfs: np.ndarray
    background_dbfs: np.ndarray
    audible: np.ndarray
    onsets: list[Onset]


def _pink(n: int, rms: float, sample_rate_hz: float, rng: np.random.Generator) -> np.ndarray:
    """Pink noise of rms `rms`: white noise shaped to 1/f power from `PINK_LOW_HZ`."""
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / sample_rate_hz)
    shape = np.where(f >= PINK_LOW_HZ, 1.0 / np.sqrt(np.maximum(f, PINK_LOW_HZ)), 0.0)
    x = np.fft.irfft(spectrum * shape, n)
    return x * (rms / max(float(np.sqrt(np.mean(x**2))), 1e-300))


def _onset(
    i: int,
    grid_s: np.ndarray,
    a: np.ndarray,
    sigma: np.ndarray,
    f: np.ndarray,
    floor: float,
    sat: float,
) -> Onset:
    """The growth truth at grid index `i` (an audible interval's start)."""
    near = np.abs(grid_s - grid_s[i]) <= ONSET_WINDOW_S
    ok = (
        near
        & (a >= floor * 10 ** (ONSET_OVER_FLOOR_DB / 20))
        & (a <= sat * 10 ** (ONSET_UNSATURATED_DB / 20))
        & (np.gradient(a) > 0)
    )
    # the run of such points that holds (or is nearest to) the onset
    idx = np.flatnonzero(ok)
    base = (float(grid_s[i]), float(f[i]), float(sigma[i]))
    if idx.size < 3:
        return Onset(*base, None, None, "A does not grow unsaturated near the onset")
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    run = min(runs, key=lambda r: float(np.min(np.abs(r - i))))
    if run.size < 3:
        return Onset(*base, None, None, "A does not grow unsaturated near the onset")
    slope = float(np.polyfit(grid_s[run], np.log(a[run]), 1)[0])
    return Onset(*base, slope, (float(grid_s[run[0]]), float(grid_s[run[-1]])))


def bench_microphone(
    times_s: Any,
    speed_rad_s: Any,
    growth_rate_per_s: Any,
    squeak_hz: Any,
    saturation: float,
    reference_speed_rad_s: float,
    sound: BenchSound,
    sample_rate_hz: float = 48000.0,
    seed: int = 0,
) -> BenchAudio:
    """Microphone samples of a stroke on a realistic bench, and the truth of its squeak.

    Parameters
    ----------
    times_s : array_like
        Increasing times [s] of the inputs; the samples run from the first to the last.
    speed_rad_s : array_like
        Screw speed [rad/s] at `times_s` (interpolated linearly; its magnitude counts).
    growth_rate_per_s : array_like
        sigma = Re(lambda) [1/s] of the most unstable mode at `times_s`, finite.
    squeak_hz : array_like
        That mode's frequency [Hz] at `times_s`, finite (ValueError otherwise), or nan
        throughout: no mode, no squeak (amplitude 0).
    saturation : float
        The squeak's limit-cycle amplitude [FS] (the squeak level).
    reference_speed_rad_s : float
        Screw speed [rad/s] at which the drive's levels are stated.
    sound : BenchSound
        The parts and their levels.
    sample_rate_hz : float
        Sample rate [Hz].
    seed : int
        Seed of the noise, the phases and the room.

    Returns
    -------
    BenchAudio
    """
    times = np.asarray(times_s, float).reshape(-1)
    finite = np.isfinite(np.asarray(squeak_hz, float))
    if finite.any() and not finite.all():
        raise ValueError("bench_microphone: the squeak's frequency must be finite throughout")
    sigma_in = np.broadcast_to(np.asarray(growth_rate_per_s, float), times.shape)
    f_in = np.broadcast_to(np.asarray(squeak_hz, float), times.shape)
    speed_in = np.broadcast_to(np.asarray(speed_rad_s, float), times.shape)
    fs = float(sample_rate_hz)
    n = int(np.floor((times[-1] - times[0]) * fs)) + 1
    t = times[0] + np.arange(n) / fs
    rng = np.random.default_rng(seed)

    # the squeak: amplitude equation on the envelope grid, ln A interpolated to the samples
    grid = times[0] + np.arange(int(np.floor((times[-1] - times[0]) * ENVELOPE_RATE_HZ)) + 1) / (
        ENVELOPE_RATE_HZ
    )
    sigma = np.interp(grid, times, sigma_in)
    f_grid = np.interp(grid, times, f_in)
    floor = saturation * 10.0 ** (sound.squeak_floor_db / 20.0)
    a = squeak_envelope(sigma, 1.0 / ENVELOPE_RATE_HZ, saturation, floor) * finite.all()
    with np.errstate(divide="ignore"):
        amp = np.exp(np.interp(t, grid, np.log(a)))
    freq = np.nan_to_num(np.interp(t, times, f_in))
    phase = 2 * np.pi * np.cumsum(freq) / fs
    out = amp * np.sin(phase)
    for k, db in ((2, sound.harmonic2_db), (3, sound.harmonic3_db)):
        level = _level(db)
        if level:
            out += (k * freq < fs / 2) * level * amp * np.sin(k * phase + 2 * np.pi * rng.random())

    # the geared motor, proportional to the speed
    speed = np.abs(np.interp(t, times, speed_in))
    orders = sound.drive_orders
    out += shaft_orders(
        speed / (2 * np.pi),
        fs,
        [k for k, _ in orders],
        [level * speed / reference_speed_rad_s for _, level in orders],
        rng,
    )

    # the background, the whole log
    for tone_hz, level in sound.background_tones:
        out += (tone_hz < fs / 2) * level * np.sin(2 * np.pi * (tone_hz * t + rng.random()))
    pink = _level(sound.pink_noise_dbfs)
    if pink:
        out += _pink(n, pink / np.sqrt(2.0), fs, rng)

    # the room, and the squeak's level at the microphone through it
    mean_square = a**2 / 2.0
    if sound.rt60_s > 0:
        out = room.reverberate(out, sound.rt60_s, fs, rng)
        kernel = room.energy_response(sound.rt60_s, ENVELOPE_RATE_HZ)
        mean_square = np.convolve(mean_square, kernel)[: a.size]
    with np.errstate(divide="ignore", invalid="ignore"):
        level_dbfs = 10.0 * np.log10(2.0 * mean_square)
        background = sound.background_band_dbfs(f_grid, fs)
    audible = level_dbfs - background > sound.audible_snr_db
    starts = np.flatnonzero(np.diff(np.concatenate([[0], audible.astype(np.int8)])) > 0)
    onsets = [_onset(int(i), grid, a, sigma, f_grid, floor, saturation) for i in starts.tolist()]
    return BenchAudio(
        out.astype(np.float32), grid, a, f_grid, sigma, level_dbfs, background, audible, onsets
    )
