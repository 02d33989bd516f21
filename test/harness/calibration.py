# SPDX-License-Identifier: Apache-2.0
"""Synthetic units for the calibration tests: a drive drawn from a population, one seat stroke
of it (the virtual bench's stroke draw), its exact verdict at every detector frame (the bench's
`squeak_frequencies`: the model at the unit's parameters, no scatter), and what a detector with
the error model heard: errors in blocks of one correlation time (`DetectionErrors`), as the
likelihood's effective count assumes."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from leadscrew_ros.bag.virtual_bench import (
    BenchSettings,
    draw_params,
    draw_stroke,
    squeak_frequencies,
)
from leadscrew_ros.model import ScrewParameters
from leadscrew_ros.model.calibration import DetectionErrors, Observations, thin
from leadscrew_ros.model.uncertainty.scatter import Scatter

HOP_S = 0.01  # the detector's default hop
# A population unlike the default prior (Table 1 friction, damping 3e-3): a larger friction
# drop (0.07 rather than 0.05) and a smaller damping (2e-3), the default scatter around it.
POPULATION = ScrewParameters().with_(mu_static=0.265, mu_kinetic=0.195, modal_damping=0.002)


# A 3-unit bench of 5-s strokes (consistent formulation) of the documentation's fleet
# (tools/calibration_example.py), and sampler options that calibrate it in seconds.
SMALL_BENCH = BenchSettings(
    units=3,
    duration_s=5.0,
    formulation="consistent",
    seed=3,
    population={"mu_static": 0.27, "mu_kinetic": 0.19, "modal_damping": 0.002},
)
QUICK_SAMPLER = [
    "--steps",
    "160",
    "--first-steps",
    "100",
    "--burn",
    "60",
    "--hyper-steps",
    "300",
    "--hyper-burn",
    "100",
]


class SyntheticUnit(NamedTuple):
    """A unit's truth and observations."""

    truth: ScrewParameters
    obs: Observations
    squeaks: np.ndarray  # exact verdict per frame: a squeak the detector can hear


def frames_of(
    truth: ScrewParameters, duration_s: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Frame centres of one drawn stroke of `truth` and the operating point (3, n) there."""
    stroke = draw_stroke(BenchSettings(duration_s=duration_s), truth, rng)
    times = np.arange(HOP_S / 2, duration_s, HOP_S)
    return times, np.array([stroke.state(t)[:3] for t in times.tolist()]).T


def heard_by(squeaks: np.ndarray, errors: DetectionErrors, rng: np.random.Generator) -> np.ndarray:
    """What the detector heard: the verdicts flipped in blocks of one correlation time."""
    block = max(int(round(errors.correlation_s / HOP_S)), 1)
    count = -(-len(squeaks) // block)
    miss = np.repeat(rng.random(count) < errors.miss, block)[: len(squeaks)]
    false_alarm = np.repeat(rng.random(count) < errors.false_alarm, block)[: len(squeaks)]
    return np.where(squeaks, ~miss, false_alarm)


def synthetic_unit(
    unit_id: str,
    rng: np.random.Generator,
    population: ScrewParameters = POPULATION,
    scatter: Scatter | None = None,
    errors: DetectionErrors | None = None,
    duration_s: float = 12.0,
) -> SyntheticUnit:
    """One unit drawn from `population` with `scatter` (the default scatter when None)."""
    truth = draw_params(population, Scatter() if scatter is None else scatter, rng)
    times, (speed, load, nut) = frames_of(truth, duration_s, rng)
    errors = errors or DetectionErrors()
    hz = squeak_frequencies(truth, speed, load, nut)  # of the most unstable mode, as the bench
    squeaks = (hz >= errors.band_lo_hz) & (hz <= errors.band_hi_hz)  # nan: no squeak
    heard = heard_by(squeaks, errors, rng)
    obs = thin(
        unit_id, [f"{unit_id}.mcap"], times, speed, load, nut, heard,
        np.where(heard, 224.0, np.nan), HOP_S,
    )  # fmt: skip
    # heard where it squeaks, at once: the frames without their order, which the likelihood
    # then takes as heard where the model squeaks (`GrowthLikelihood`), as they were made
    return SyntheticUnit(truth, unordered(obs), squeaks)


def unordered(obs: Observations) -> Observations:
    """The observations without their frame sequence."""
    return Observations(
        obs.unit_id, obs.logs, obs.speed_rad_s, obs.load_n, obs.nut_position_m, obs.frames,
        obs.heard, obs.heard_hz, obs.frame_s,
    )  # fmt: skip
