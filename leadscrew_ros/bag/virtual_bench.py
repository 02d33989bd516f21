# SPDX-License-Identifier: Apache-2.0
"""The virtual bench: recordings of simulated units, each with a microphone, the truth apart.

Each of `BenchSettings.units` units is one seat stroke (`live.profile.StrokeProfile`, with a
per-unit peak speed, load range and start position drawn from the seed) of a drive whose
friction and damping are drawn from the bench's generating population: by default the
package's nominal parameters (Table 1) with the default unit-to-unit scatter (`Scatter()`:
mu_static, mu_kinetic, friction_decay_s_m, modal_damping), or another population
(`BenchSettings.population`, `population_scatter`: a fleet the prior does not describe, for
calibration): the hidden truth. A unit's recording is what the node would have recorded on the
bench (a rosbag2 bag directory written by `Recorder`, the `leadscrew_ros` metadata record
carrying the package's NOMINAL parameters and default scatter, the prior, as a real unit's
recording would, and its unit id), holding:

- `/motor_speed`, `/axial_load`, `/nut_position` (std_msgs/Float64) at `input_rate_hz`, with
  the sensor noise of `synthetic.DutyCycle`;
- `/microphone`: ros-drivers audio_common AudioDataStamped, `chunk_samples` S16LE samples per
  message at `sample_rate_hz`, stamped with the time of its first sample and logged when it
  is full; `/microphone_info`: AudioInfo (1 channel, S16LE, wave), at the start and every
  `info_period_s`.

The microphone (`model.acoustics.synthesis.microphone`) holds motor orders following the
speed, broadband noise and, whenever the unit's own model squeaks (`SqueakModel` at the
unit's parameters, nominal verdict without scatter, at the true speed, load and nut position
of every input sample, the nut moved in steps of the node's `nut_deadband_m`), a tone at the
frequency of its most unstable mode with ~20 ms onset and decay: the clean bench, the default.
With `BenchSettings.realistic` the bench sounds like a bench instead
(`model.acoustics.bench_sound.bench_microphone`, its parts in `BenchSettings.sound`): the
squeak grown by its amplitude equation from the unit's own Re(lambda) along the stroke, with
harmonics, a geared motor, a background, a room, and `sound.rest_s` of standstill (speed 0)
before and after the stroke; the default will switch to it once the detector hears such a
bench (it does not yet learn the background nor reject drive orders at a non-whole ratio).

Level assumption: the squeak tone's amplitude (on the realistic bench: its saturated,
limit-cycle amplitude) is `squeak_level_dbfs` re full scale (a full-scale sine is 0 dBFS) and
stands for `squeak_spl_db` SPL (rms), which fixes the microphone's scale
`audio_scale_pa_per_fs` (Pa per full-scale unit: -20 dBFS = 94 dB SPL gives 14.1 Pa/FS).

`DIR/truth.json` holds what the logs must not: per unit the drawn parameters and stroke,
where it squeaks and at which frequency, the generating population (`nominal`, `scatter`) and
the prior the logs carry (`prior`), with the formulation, seed, settings and audio scale; on
the realistic bench also the sound's parts (`sound`) and per unit the squeak's envelope, the
audible intervals and the growth truth at each onset (`_sound_truth`).
Nothing of it is written into the logs.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from ..live.profile import HOLD, RAMP, StrokeProfile
from ..live.settings import LiveSettings
from ..model import ScrewParameters, SqueakModel
from ..model.acoustics.bench_sound import OFF_DB, BenchAudio, BenchSound, bench_microphone
from ..model.acoustics.synthesis import microphone
from ..model.physics.metadata import check, setting
from ..model.physics.parameters import ParameterError
from ..model.studies.fields import GrowthField, growth_field
from ..model.uncertainty.scatter import (
    DEFAULT_SCATTER,
    LIVE_SAMPLES,
    Scatter,
    scatterable,
    valid_mask,
)
from . import audiomsgs, logmeta
from .cdr import FLOAT64, encode_float64
from .recorder import Recorder, RecordSettings, ensure_directory
from .synthetic import LOAD_TOPIC, NUT_TOPIC, SPEED_TOPIC, DutyCycle

MIC_TOPIC, MIC_INFO_TOPIC = "/microphone", "/microphone_info"
TRUTH = "truth.json"
TRUTH_RATE_HZ = 100.0  # the realistic bench's envelope in truth.json
START_NS = DutyCycle.start_ns
P_REF_PA = 20e-6  # reference pressure of dB SPL
_TOPIC_OFFSET_NS = 100_000  # topics of one input sample 0.1 ms apart (synthetic)
_NUT_MARGIN_M = 0.002  # a stroke ends this short of the end of the screw
_MAX_REDRAWS = 100


@dataclass(frozen=True)
class BenchSettings:
    """The bench run: units, stroke, microphone (SI units; metadata as for the node's)."""

    units: int = setting(10, "1", "simulated units, one recording each", 1, 100000)
    formulation: str = setting(
        "paper", "", "friction matrices of every unit's model", choices=("paper", "consistent")
    )
    seed: int = setting(
        0, "1", "seed of the units, strokes, sensor noise and microphone", 0, 2**31 - 1
    )
    duration_s: float = setting(12.0, "s", "stroke duration of every unit", 1.0, 3600.0)
    input_rate_hz: float = setting(
        100.0,
        "Hz",
        "rate of motor_speed, axial_load and nut_position (and of the model along the stroke)",
        1.0,
        10000.0,
    )
    peak_speed_rad_s: float = setting(
        120.0,
        "rad/s",
        "peak speed of a stroke before the "
        "per-unit spread (lowered when the nut would leave the "
        "screw)",
        1.0,
        1000.0,
    )
    speed_spread: float = setting(
        0.15, "1", "a unit's peak speed is peak_speed_rad_s times U(1 - speed_spread, 1)", 0.0, 0.9
    )
    load_spread: float = setting(
        0.15,
        "1",
        "a unit's load range is the profile's times U(1 - load_spread, 1 + load_spread), each end",
        0.0,
        0.9,
    )
    sample_rate_hz: int = setting(48000, "Hz", "microphone sample rate", 8000, 192000)
    chunk_samples: int = setting(
        4800, "1", "microphone samples per AudioDataStamped message", 16, 1_000_000
    )
    info_period_s: float = setting(
        1.0, "s", "AudioInfo published at the start and this often", 0.01, 3600.0
    )
    squeak_level_dbfs: float = setting(
        -20.0,
        "dBFS",
        "squeak tone amplitude re full scale (a full-scale sine is 0 dBFS)",
        -120.0,
        0.0,
    )
    squeak_spl_db: float = setting(
        94.0,
        "dB",
        "sound pressure level (rms, re 20 uPa) the "
        "squeak tone stands for; fixes audio_scale_pa_per_fs",
        0.0,
        194.0,
    )
    realistic: bool = setting(
        False,
        "",
        "the bench sounds like a bench (`sound`: the squeak grown by its amplitude equation, "
        "harmonics, a geared motor, a background with motor-off rest, a room); false: the "
        "clean bench (a gated tone, whole motor orders, white noise)",
    )
    sound: BenchSound = field(
        default_factory=BenchSound,
        metadata={"help": "the realistic bench's parts (with realistic only)"},
    )
    population: dict[str, float] = field(
        default_factory=dict,
        metadata={
            "help": "the nominal value of a scatterable parameter in the population the "
            "units are drawn from, in the field's unit (default: the package's nominal, "
            "Table 1)"
        },
    )
    population_scatter: dict[str, float] = field(
        default_factory=dict,
        metadata={
            "help": "the scatter of a parameter in that population: relative SD, SD of ln "
            "for modal_damping, 0 fixes it (default: the package's default scatter)"
        },
    )

    def __post_init__(self) -> None:
        check(self, ParameterError, "bench.")
        if not isinstance(self.sound, BenchSound):
            raise ParameterError("bench.sound must be a BenchSound")
        if not self.realistic and self.sound != BenchSound():
            raise ParameterError(
                "bench.sound sets the realistic bench's parts: it needs realistic = true"
            )
        for what, values in (
            ("population", self.population),
            ("population_scatter", self.population_scatter),
        ):
            for name in values:
                if name not in scatterable():
                    raise ParameterError(
                        f"bench.{what}: {name} is not a scatterable parameter; one of "
                        f"{', '.join(scatterable())}"
                    )
        try:
            _ = (self.population_params, self.population_sd)
        except ParameterError as exc:
            raise ParameterError(f"bench population: {exc}") from None

    @property
    def prior(self) -> tuple[ScrewParameters, Scatter]:
        """What the logs' metadata record carries, as a real unit's would: the package's
        nominal parameters (of the bench's formulation) and default scatter."""
        return ScrewParameters(formulation=self.formulation), Scatter()

    @property
    def population_params(self) -> ScrewParameters:
        """The generating population's nominal parameters (the prior's with `population`)."""
        return self.prior[0].with_(**self.population)

    @property
    def population_sd(self) -> Scatter:
        """The generating population's scatter (the default with `population_scatter`)."""
        return Scatter({**DEFAULT_SCATTER, **self.population_scatter})

    @property
    def squeak_amplitude_fs(self) -> float:
        """The squeak tone's amplitude [full scale]."""
        return 10.0 ** (self.squeak_level_dbfs / 20.0)

    @property
    def audio_scale_pa_per_fs(self) -> float:
        """Pressure per full-scale unit [Pa/FS]: the tone's rms stands for squeak_spl_db."""
        p_rms = P_REF_PA * 10.0 ** (self.squeak_spl_db / 20.0)
        return p_rms / (self.squeak_amplitude_fs / math.sqrt(2.0))


@dataclass(frozen=True)
class Unit:
    """One simulated unit: its hidden parameters, its stroke and the squeak along it.

    Attributes
    ----------
    unit_id : str
        The unit's identity ('bench-000', ...), also in its log's metadata record.
    params : ScrewParameters
        The unit's true parameters (the scattered ones drawn, the rest nominal).
    stroke : StrokeProfile
        Its stroke.
    times_s : numpy.ndarray
        Input sample times [s] from the start of the stroke.
    speed_rad_s, load_n, nut_position_m : numpy.ndarray
        True (noise-free) operating points at `times_s`.
    squeak_hz : numpy.ndarray
        Frequency of the most unstable mode where the unit's model squeaks, else nan.
    growth_rate_per_s, mode_hz : numpy.ndarray
        Re(lambda) [1/s] and frequency [Hz] of the most unstable mode, squeaking or not; nan
        where the model is not valid (e.g. below its minimum speed).
    stroke_start_s : float
        When the stroke starts [s] (the realistic bench's rest before it; 0 otherwise).
    """

    unit_id: str
    params: ScrewParameters
    stroke: StrokeProfile
    times_s: np.ndarray
    speed_rad_s: np.ndarray
    load_n: np.ndarray
    nut_position_m: np.ndarray
    squeak_hz: np.ndarray
    growth_rate_per_s: np.ndarray
    mode_hz: np.ndarray
    stroke_start_s: float = 0.0

    @property
    def squeaks(self) -> np.ndarray:
        """Where the unit's model squeaks (bool per input sample)."""
        return np.isfinite(self.squeak_hz)


def draw_params(
    nominal: ScrewParameters, scatter: Scatter, rng: np.random.Generator
) -> ScrewParameters:
    """One unit's parameters: standard-normal draws of the scatter, redrawn outside the valid
    domain (mu_s >= mu_k, field ranges)."""
    for _ in range(_MAX_REDRAWS):
        u = rng.standard_normal(len(scatter.names))
        values = scatter.values(nominal, u)
        if bool(valid_mask(nominal, values)):
            return nominal.with_(**{k: float(v) for k, v in values.items()})
    raise ParameterError("the scatter's valid domain is (almost) never hit")


def draw_stroke(
    settings: BenchSettings, params: ScrewParameters, rng: np.random.Generator
) -> StrokeProfile:
    """One unit's stroke: peak speed, load range and start position drawn; the peak speed is
    lowered where the nut would otherwise run off the screw."""
    base = StrokeProfile()
    start = float(rng.uniform(0.015, 0.03))
    lead, d = params.lead_per_rad_m, settings.duration_s
    fits = (params.nut_travel_m - start - _NUT_MARGIN_M) / (lead * d * (2 * RAMP / 3 + HOLD))
    peak = min(settings.peak_speed_rad_s * float(rng.uniform(1 - settings.speed_spread, 1.0)), fits)
    spread = settings.load_spread
    lo = base.load_min_n * float(rng.uniform(1 - spread, 1 + spread))
    hi = max(base.load_max_n * float(rng.uniform(1 - spread, 1 + spread)), lo)
    return StrokeProfile.for_params(
        params,
        duration_s=d,
        peak_speed_rad_s=peak,
        load_min_n=lo,
        load_max_n=hi,
        start_nut_position_m=start,
    )


def mode_field(
    params: ScrewParameters,
    speed_rad_s: np.ndarray,
    load_n: np.ndarray,
    nut_position_m: np.ndarray,
    nut_step_m: float = LiveSettings.nut_deadband_m,
) -> GrowthField:
    """The most unstable mode of the model of `params` (no scatter) at each operating point,
    the nut position in steps of `nut_step_m` (points of one step share one batched
    eigen-solve, `fields.growth_field`)."""
    model = SqueakModel(params, Scatter({}))
    nut = np.round(np.asarray(nut_position_m, float) / nut_step_m) * nut_step_m
    nut = np.clip(nut, 0.0, params.nut_travel_m)
    return growth_field(model, speed_rad_s, load_n, nut_position_m=nut)


def squeak_frequencies(
    params: ScrewParameters,
    speed_rad_s: np.ndarray,
    load_n: np.ndarray,
    nut_position_m: np.ndarray,
    nut_step_m: float = LiveSettings.nut_deadband_m,
) -> np.ndarray:
    """Frequency [Hz] of the most unstable mode where the model of `params` (no scatter)
    squeaks at each operating point, else nan (`mode_field`)."""
    field = mode_field(params, speed_rad_s, load_n, nut_position_m, nut_step_m)
    squeak = field.valid & (field.max_growth_rate > 0)
    return np.where(squeak, field.peak_frequency_hz, np.nan)


def simulate_unit(
    settings: BenchSettings,
    index: int,
    rng: np.random.Generator,
    nominal: ScrewParameters,
    scatter: Scatter,
) -> Unit:
    """Unit `index`: draw its parameters and stroke and evaluate its model along the stroke
    (on the realistic bench with `sound.rest_s` of standstill before and after it)."""
    params = draw_params(nominal, scatter, rng)
    stroke = draw_stroke(settings, params, rng)
    times, speed, load, nut = stroke.sampled(settings.input_rate_hz)  # duration_s: the bench's
    rest = int(round(settings.sound.rest_s * settings.input_rate_hz)) if settings.realistic else 0
    if rest:  # the motor off: speed 0, load and nut held
        speed = np.pad(speed, rest)
        load, nut = (np.pad(a, rest, mode="edge") for a in (load, nut))
        times = np.arange(speed.size) / settings.input_rate_hz
    field = mode_field(params, speed, load, nut)
    squeak = field.valid & (field.max_growth_rate > 0)
    return Unit(
        f"bench-{index:03d}",
        params,
        stroke,
        times,
        speed,
        load,
        nut,
        np.where(squeak, field.peak_frequency_hz, np.nan),
        field.max_growth_rate,
        field.peak_frequency_hz,
        rest / settings.input_rate_hz,
    )


def _held(values: np.ndarray) -> np.ndarray:
    """`values` with each nan replaced by the last finite value before it (before the first
    finite one: that one); all nan stays all nan."""
    ok = np.isfinite(values)
    if not ok.any():
        return values
    index = np.maximum.accumulate(np.where(ok, np.arange(values.size), 0))
    index[: np.flatnonzero(ok)[0]] = np.flatnonzero(ok)[0]
    return values[index]


def realistic_sound(settings: BenchSettings, unit: Unit, seed: int) -> BenchAudio:
    """The realistic bench's microphone of `unit` (`bench_sound.bench_microphone`). Where the
    unit's model is not valid (the nut at standstill, below the model's minimum speed) its
    mode keeps the last frequency and rings down at the structure's own damping,
    sigma = -modal_damping 2 pi f (no sliding, no friction feeding it)."""
    f = _held(unit.mode_hz)
    idle = -unit.params.modal_damping * 2 * math.pi * f
    sigma = np.where(np.isfinite(unit.growth_rate_per_s), unit.growth_rate_per_s, idle)
    return bench_microphone(
        unit.times_s,
        unit.speed_rad_s,
        sigma,
        f,
        settings.squeak_amplitude_fs,
        settings.peak_speed_rad_s,
        settings.sound,
        settings.sample_rate_hz,
        seed,
    )


def _metadata(nominal: ScrewParameters, scatter: Scatter, unit_id: str) -> dict[str, str]:
    """The recording's `leadscrew_ros` record: nominal parameters, as a real unit's has."""
    return logmeta.LogMetadata(
        nominal.as_dict(), {**scatter.sd, "samples": LIVE_SAMPLES}, {}, unit_id, "virtual_bench"
    ).record()


def write_unit(
    settings: BenchSettings,
    unit: Unit,
    directory: Path,
    nominal: ScrewParameters,
    scatter: Scatter,
    rng: np.random.Generator,
) -> tuple[Path, BenchAudio | None]:
    """Record one unit's stroke (inputs with sensor noise, the microphone) into a new bag
    directory under `directory`, its metadata record carrying `nominal` and `scatter` (the
    prior, `BenchSettings.prior`); returns the bag and, on the realistic bench, its sound's
    truth."""
    cycle = DutyCycle()
    n = unit.times_s.size
    speed = unit.speed_rad_s + rng.normal(0.0, cycle.speed_noise_rad_s, n)
    load = unit.load_n + rng.normal(0.0, cycle.load_noise_n, n)
    sound = None
    if settings.realistic:
        sound = realistic_sound(settings, unit, int(rng.integers(2**31)))
        audio = sound.samples
    else:
        audio = microphone(
            unit.times_s,
            unit.speed_rad_s,
            unit.squeak_hz,
            settings.squeak_amplitude_fs,
            settings.sample_rate_hz,
            seed=int(rng.integers(2**31)),
        )
    pcm = np.round(np.clip(audio, -1.0, 1.0) * 32767.0).astype("<i2")
    fs, chunk = settings.sample_rate_hz, settings.chunk_samples
    events: list[tuple[int, int, str, str, bytes]] = []  # (log time, order, topic, ...)
    stamps = START_NS + np.round(unit.times_s * 1e9).astype(np.int64)
    for k, t in enumerate(stamps.tolist()):
        events.append((t, 0, SPEED_TOPIC, FLOAT64, encode_float64(float(speed[k]))))
        events.append(
            (t + _TOPIC_OFFSET_NS, 0, LOAD_TOPIC, FLOAT64, encode_float64(float(load[k])))
        )
        events.append(
            (
                t + 2 * _TOPIC_OFFSET_NS,
                0,
                NUT_TOPIC,
                FLOAT64,
                encode_float64(float(unit.nut_position_m[k])),
            )
        )
    info = audiomsgs.encode_audio_info(1, fs, "S16LE", 16 * fs, "wave")
    for t in np.arange(0.0, unit.times_s[-1] + 1e-9, settings.info_period_s).tolist():
        events.append(
            (START_NS + int(round(t * 1e9)), 1, MIC_INFO_TOPIC, audiomsgs.AUDIO_INFO, info)
        )
    for start in range(0, pcm.size, chunk):
        part = pcm[start : start + chunk]
        stamp = START_NS + int(round(start / fs * 1e9))
        full = START_NS + int(round((start + part.size) / fs * 1e9))
        events.append(
            (
                full,
                2,
                MIC_TOPIC,
                audiomsgs.AUDIO_DATA_STAMPED,
                audiomsgs.encode_audio_data_stamped(stamp, part.view(np.uint8), "microphone"),
            )
        )
    events.sort(key=lambda e: (e[0], e[1]))
    rec = Recorder(
        RecordSettings(directory=str(directory), split_size_mb=0.0, split_duration_s=0.0),
        name=unit.unit_id,
        metadata={logmeta.RECORD_NAME: _metadata(nominal, scatter, unit.unit_id)},
        schemas={
            name: audiomsgs.definition(name)
            for name in (audiomsgs.AUDIO_DATA_STAMPED, audiomsgs.AUDIO_INFO)
        },
    )
    if not rec.start(START_NS):
        raise OSError(rec.error)
    for t, _, topic, type_name, data in events:
        rec.write_serialized(topic, type_name, data, t)
        rec.tick(t)
    rec.stop()
    if rec.error:
        raise OSError(rec.error)
    assert rec.bag is not None
    return rec.bag, sound


def _intervals(
    times_s: np.ndarray, on: np.ndarray, frequency_hz: np.ndarray
) -> list[dict[str, float]]:
    """Runs of `on`: start and end [s] (first and last point) and the frequency range."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(np.int8), [0]])))
    out = []
    for a, b in zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True):
        f = frequency_hz[a:b]
        out.append(
            {
                "start_s": float(times_s[a]),
                "end_s": float(times_s[b - 1]),
                "min_hz": float(f.min()),
                "max_hz": float(f.max()),
            }
        )
    return out


def _sound_truth(sound: BenchAudio) -> dict[str, Any]:
    """A realistic unit's sound in truth.json: the envelope (the fundamental's amplitude A at
    the source, dBFS, and its frequency) at `TRUTH_RATE_HZ`, the audible intervals (on the
    envelope grid) and the growth truth at each onset."""
    step = max(int(round(1.0 / (TRUTH_RATE_HZ * (sound.grid_s[1] - sound.grid_s[0])))), 1)
    return {
        "envelope_rate_hz": TRUTH_RATE_HZ,
        "envelope_dbfs": np.round(
            20 * np.log10(np.maximum(sound.amplitude[::step], 10 ** (OFF_DB / 20))), 2
        ).tolist(),  # OFF_DB: no mode, no squeak
        "frequency_hz": np.round(sound.frequency_hz[::step], 2).tolist(),
        "audible_intervals": _intervals(sound.grid_s, sound.audible, sound.frequency_hz),
        "audible_s": float(sound.audible.sum() * (sound.grid_s[1] - sound.grid_s[0])),
        "onsets": [
            {**asdict(o), "window_s": list(o.window_s) if o.window_s else None}
            for o in sound.onsets
        ],
    }


def _sound_settings(settings: BenchSettings) -> dict[str, Any]:
    """truth.json's `sound`: which bench, and on the realistic one its drive and background
    (orders of the screw speed, tone frequencies) and the squeak's saturation and floor."""
    if not settings.realistic:
        return {"realistic": False}
    s = settings.sound
    saturation = settings.squeak_level_dbfs
    return {
        "realistic": True,
        "gear_ratio": s.gear_ratio,
        "drive_orders": [k for k, _ in s.drive_orders],
        "background_tones_hz": [f for f, _ in s.background_tones],
        "pink_noise_dbfs": s.pink_noise_dbfs,
        "rt60_s": s.rt60_s,
        "saturation_dbfs": saturation,
        "floor_dbfs": saturation + s.squeak_floor_db,
        "audible_snr_db": s.audible_snr_db,
        "rest_s": s.rest_s,
    }


def run(
    settings: BenchSettings,
    out: Path | str,
    progress: Callable[[int, Unit, Path], None] | None = None,
) -> dict[str, Any]:
    """Simulate and record every unit into `out` (created if needed), write `out/truth.json`.

    Parameters
    ----------
    settings : BenchSettings
        Units, formulation, seed, stroke, microphone and the generating population.
    out : path
        Output directory: one bag directory per unit and truth.json.
    progress : callable, optional
        Called with (index, unit, bag) after each unit.

    Returns
    -------
    dict
        The truth (as written to truth.json).

    Raises
    ------
    OSError
        `out` cannot be written.
    ParameterError
        The scatter's valid domain is never hit.
    """
    out = ensure_directory(str(out))
    nominal, scatter = settings.population_params, settings.population_sd
    prior, prior_scatter = settings.prior
    rng = np.random.default_rng(settings.seed)
    units = []
    for k in range(settings.units):
        unit_rng, record_rng = (np.random.default_rng(s) for s in rng.integers(2**63, size=2))
        unit = simulate_unit(settings, k, unit_rng, nominal, scatter)
        bag, sound = write_unit(settings, unit, out, prior, prior_scatter, record_rng)
        if progress:
            progress(k, unit, bag)
        units.append(
            {
                "unit_id": unit.unit_id,
                "log": bag.name,
                "params": {name: getattr(unit.params, name) for name in scatter.names},
                "stroke": {f.name: getattr(unit.stroke, f.name) for f in fields(unit.stroke)},
                "squeak_s": float(unit.squeaks.sum() / settings.input_rate_hz),
                "squeak_intervals": _intervals(unit.times_s, unit.squeaks, unit.squeak_hz),
                **(
                    {"stroke_start_s": unit.stroke_start_s, "sound": _sound_truth(sound)}
                    if sound
                    else {}
                ),
            }
        )
    truth = {
        "formulation": settings.formulation,
        "seed": settings.seed,
        "settings": asdict(settings),
        "nominal": nominal.as_dict(),
        "scatter": dict(scatter.sd),
        "prior": {"nominal": prior.as_dict(), "scatter": dict(prior_scatter.sd)},
        "audio": {
            "topic": MIC_TOPIC,
            "info_topic": MIC_INFO_TOPIC,
            "sample_format": "S16LE",
            "squeak_amplitude_fs": settings.squeak_amplitude_fs,
            "squeak_spl_db": settings.squeak_spl_db,
            "audio_scale_pa_per_fs": settings.audio_scale_pa_per_fs,
            "t0_s": 0.0,
        },
        "sound": _sound_settings(settings),
        "units": units,
    }
    (out / TRUTH).write_text(json.dumps(truth, indent=1, sort_keys=True) + "\n")
    return truth
