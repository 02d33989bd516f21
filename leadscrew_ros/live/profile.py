# SPDX-License-Identifier: Apache-2.0
"""Seat-stroke profile: motor speed, axial load, nut position and screw angle of a power-seat
adjuster stroke as functions of time (pure and deterministic; `ros.simulator` publishes it).

The stroke (fractions of `duration_s`): the motor rests, ramps up quadratically from 0 through
the squeak band (about 0.8-55 rad/s at Table 1, paper formulation) to `peak_speed_rad_s`
beyond it, holds, ramps back down (mirror image) and rests. The quadratic ramps spend most of
their time at low and moderate speed, i.e. in the band, while moving the nut less than linear
ramps would: the nut advances `lead` = R tan(beta) per radian of screw rotation and must stay on
the screw (0 <= z_o <= L - b; a default stroke travels 0.20 m of the 0.24 m available). The
axial load grows with the travel (seat spring) plus one slow weight shift of the occupant,
always within [load_min_n, load_max_n].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..model import ScrewParameters, SqueakModel
from .settings import JointSettings

# Phases as fractions of the stroke duration: rest, ramp up, hold, ramp down (RAMP again), and
# rest for the remaining 0.15.
REST_START, RAMP, HOLD = 0.05, 0.36, 0.08
SPRING_SHARE = 0.8  # share of the load range that follows the travel (the rest: occupant)
_DEFAULTS = ScrewParameters()


class ProfileError(ValueError):
    """A stroke that cannot be simulated (bad numbers, or the nut would leave the screw)."""


class ActuatorState(NamedTuple):
    """The actuator at one time of a stroke.

    Attributes
    ----------
    speed_rad_s : float
        Motor (screw) speed [rad/s], negative on a return stroke.
    load_n : float
        Axial load [N].
    nut_position_m : float
        Nut position z_o [m].
    screw_angle_rad : float
        Screw angle [rad], 0 at `nut_position_at_zero_angle_m`.
    """

    speed_rad_s: float
    load_n: float
    nut_position_m: float
    screw_angle_rad: float


@dataclass(frozen=True)
class StrokeProfile:
    """A power-seat adjuster stroke (the module's shape); raises `ProfileError` when it cannot
    be simulated.

    Attributes
    ----------
    duration_s : float
        Length of one stroke [s].
    peak_speed_rad_s : float
        Motor speed of the hold phase [rad/s].
    load_min_n, load_max_n : float
        Range of the axial load [N].
    start_nut_position_m : float
        Nut position at the start [m].
    lead_m_per_rad : float
        Nut travel per radian of screw rotation, R tan(beta) [m/rad].
    max_nut_position_m : float
        Highest nut position on the screw, L - b [m].
    nut_position_at_zero_angle_m : float
        Nut position at screw angle 0 [m] (the node's default, so that joint_states and
        nut_position describe the same nut).
    """

    duration_s: float = 12.0
    peak_speed_rad_s: float = 120.0
    load_min_n: float = 120.0
    load_max_n: float = 350.0
    start_nut_position_m: float = 0.02
    lead_m_per_rad: float = _DEFAULTS.lead_per_rad_m
    max_nut_position_m: float = _DEFAULTS.nut_travel_m
    nut_position_at_zero_angle_m: float = JointSettings.nut_position_at_zero_angle_m

    @classmethod
    def for_params(cls, params: ScrewParameters, **changes: Any) -> StrokeProfile:
        """A profile for this screw: lead R tan(beta) and travel limit L - b from `params`.

        Parameters
        ----------
        params : ScrewParameters
            The screw.
        **changes
            Other fields of the profile.

        Returns
        -------
        StrokeProfile
            The profile.
        """
        return cls(
            lead_m_per_rad=params.lead_per_rad_m, max_nut_position_m=params.nut_travel_m, **changes
        )

    def __post_init__(self) -> None:
        for name in ("duration_s", "peak_speed_rad_s", "lead_m_per_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ProfileError(f"{name} must be a finite number > 0, got {value!r}")
        for name in (
            "load_min_n",
            "load_max_n",
            "start_nut_position_m",
            "max_nut_position_m",
            "nut_position_at_zero_angle_m",
        ):
            if not math.isfinite(getattr(self, name)):
                raise ProfileError(f"{name} must be finite, got {getattr(self, name)!r}")
        if not 0 <= self.load_min_n <= self.load_max_n:
            raise ProfileError(
                f"need 0 <= load_min_n <= load_max_n, got {self.load_min_n:g} "
                f"and {self.load_max_n:g} N"
            )
        end = self.start_nut_position_m + self.travel_m
        if not 0 <= self.start_nut_position_m <= end <= self.max_nut_position_m:
            longest = (self.max_nut_position_m - self.start_nut_position_m) / (
                self.travel_m / self.duration_s
            )
            raise ProfileError(
                f"a {self.duration_s:g} s stroke at {self.peak_speed_rad_s:g} rad/s moves the nut "
                f"{self.travel_m:.3g} m from {self.start_nut_position_m:g} m, off the screw "
                f"(nut positions 0..{self.max_nut_position_m:g} m); the longest stroke at this "
                f"speed is {max(longest, 0):.3g} s (use --loop to keep going)"
            )

    # ---------------------------------------------------------------- shape
    @property
    def travel_m(self) -> float:
        """Nut travel of one stroke: lead times the screw angle turned."""
        return self.lead_m_per_rad * self._angle_of_stroke(1.0)

    @property
    def end_nut_position_m(self) -> float:
        """Nut position at the end of a forward stroke [m]."""
        return self.start_nut_position_m + self.travel_m

    def _speed_fraction(self, tau: float) -> float:
        """Speed / peak at normalised time tau in [0, 1]."""
        up = tau - REST_START
        down = tau - (REST_START + RAMP + HOLD)
        if up <= 0 or down >= RAMP:
            return 0.0
        if up < RAMP:
            return (up / RAMP) ** 2
        if down <= 0:
            return 1.0
        return (1.0 - down / RAMP) ** 2

    def _angle_of_stroke(self, tau: float) -> float:
        """Screw angle turned since the start (rad), exact integral of the speed."""
        w, d = self.peak_speed_rad_s, self.duration_s
        up = min(max(tau - REST_START, 0.0), RAMP) / RAMP
        hold = min(max(tau - REST_START - RAMP, 0.0), HOLD)
        down = min(max(tau - REST_START - RAMP - HOLD, 0.0), RAMP) / RAMP
        return w * d * (RAMP * up**3 / 3 + hold + RAMP * (1 - (1 - down) ** 3) / 3)

    def state(self, t: float, loop: bool = False) -> ActuatorState:
        """Speed, load, nut position and screw angle at a time of the stroke.

        Parameters
        ----------
        t : float
            Time since the start [s].
        loop : bool
            Repeat the stroke forever, every second one backwards (negative speed, the nut
            returning), so the nut never jumps. Without it the stroke holds its end state (at
            rest) after `duration_s` and its start state before 0.

        Returns
        -------
        ActuatorState
            The actuator at `t`.
        """
        d = self.duration_s
        t = max(float(t), 0.0)
        k = int(t // d) if loop else 0
        tau = (t - k * d) / d if loop else min(t / d, 1.0)
        sign = -1.0 if k % 2 else 1.0
        travel = self.lead_m_per_rad * self._angle_of_stroke(tau)
        nut = self.start_nut_position_m + travel if sign > 0 else self.end_nut_position_m - travel
        nut = min(max(nut, 0.0), self.max_nut_position_m)  # guards rounding only
        u = (nut - self.start_nut_position_m) / self.travel_m  # 0..1
        occupant = 0.5 * (1.0 - math.cos(2.0 * math.pi * tau))  # 0..1..0
        load = self.load_min_n + (self.load_max_n - self.load_min_n) * (
            SPRING_SHARE * min(max(u, 0.0), 1.0) + (1.0 - SPRING_SHARE) * occupant
        )
        angle = (nut - self.nut_position_at_zero_angle_m) / self.lead_m_per_rad
        return ActuatorState(
            sign * self.peak_speed_rad_s * self._speed_fraction(tau), load, nut, angle
        )

    def sampled(self, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The stroke at `rate_hz` from its start to its end, both included.

        Parameters
        ----------
        rate_hz : float
            Sample rate [Hz].

        Returns
        -------
        times, speed, load, nut : numpy.ndarray
            Times [s], speed [rad/s], load [N] and nut position [m] of `state` at them.
        """
        times = np.arange(int(round(self.duration_s * rate_hz)) + 1) / rate_hz
        speed, load, nut, _ = (
            np.array(a) for a in zip(*(self.state(t) for t in times.tolist()), strict=True)
        )
        return times, speed, load, nut


def state(t: float, profile: StrokeProfile | None = None, loop: bool = False) -> ActuatorState:
    """`StrokeProfile.state` of the default profile (or of `profile`)."""
    return (profile or StrokeProfile()).state(t, loop)


def expected_squeak(
    profile: StrokeProfile, model: SqueakModel | None = None, samples: int = 241
) -> tuple[np.ndarray, np.ndarray]:
    """The model along the stroke, at `samples` evenly spaced times: (times [s], squeak flags).

    What an ideal, lag-free predictor would say; the demo compares the node's output with it."""
    model = model or SqueakModel()
    times = np.linspace(0.0, profile.duration_s, samples)
    flags = np.zeros(samples, bool)
    for i, t in enumerate(times):
        s = profile.state(t)
        if abs(s.speed_rad_s) < model.params.min_speed_rad_s:
            continue  # at rest: no squeak
        p = model.with_params(nut_position_m=s.nut_position_m).predict(s.speed_rad_s, s.load_n)
        flags[i] = bool(p.valid and p.squeak_modes)
    return times, flags
