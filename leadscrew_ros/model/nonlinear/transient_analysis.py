# SPDX-License-Identifier: Apache-2.0
"""What a simulated run (`transient.simulate`) shows: the growth in the linear regime, and
the limit cycle that the friction nonlinearity bounds it to.

The vibration amplitude of the run is its modal energy norm a(t) = sqrt(sum qdot_i^2 +
omega_i^2 q_i^2) (the q deviation from steady sliding): constant over a period for one
undamped mode, so no envelope detector is needed.

- Regime: `limit cycle` when a changes by less than 10 % over the last fifth of the run
  and the vibration velocity at the nut centre there reaches 1 % of the steady sliding speed
  (the friction nonlinearity engaged), saturated at a_sat = the median of a over the last
  fifth; otherwise `growing` or `decaying` by the trend of a over the last fifth.
- Linear fit: in the linear regime (a below 1 % of a_sat; in a growing run, the vibration
  velocity at the nut centre below 1e-4 of the steady sliding speed; in a decaying run, a
  above 1e-3 of its start; the whole run if that never ends), over its second half (where
  the other eigenmodes have decayed or fallen behind), the modal coordinate with the largest
  RMS displacement (the labelling rule of `stability.classify`) is fitted by least squares
  with one exponentially growing sinusoid e^{sigma t} (a cos(w t) + b sin(w t)): growth
  sigma [1/s], frequency w / 2 pi [Hz]. The fit uses no eigenvector of any formulation: it
  is an independent measurement of the run.
- Limit cycle: over the second half of the run after saturation (a first reaches 90 % of
  a_sat): peak lateral displacement and torsion angle at the nut centre, peak and RMS surface
  velocity, the lowest sliding speed at the nut centre, and the spectrum of the tangential
  surface velocity (Hann window): fundamental and the levels of its harmonics 2..6 relative
  to it [dB].
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ..physics.parameters import FORMULATIONS, ScrewParameters
from ..squeak_model import SqueakModel
from ..uncertainty.scatter import Scatter
from .transient import TransientResult

LINEAR_FRACTION = 0.01  # linear regime: amplitude below this fraction of saturation
SATURATED_FRACTION = 0.9  # saturation time: amplitude first reaches this fraction
TAIL = 0.2  # last fraction of the run that decides the regime
STEADY_CHANGE = 0.1  # limit cycle: the amplitude changes less over the tail
ENGAGED_FRACTION = 0.01  # ... and the vibration velocity is at least this fraction of
#                             the steady sliding speed (the friction nonlinearity engaged)
DECAY_FLOOR = 1e-3  # a decaying run is fitted while a stays above this fraction of
#                             its start (the integrator's absolute tolerance is 1e-6 of it)
MIN_FIT_SAMPLES = 64  # fewest samples of the linear fit window
HARMONICS = range(2, 7)
_PAD = 8  # zero padding of the spectra


@dataclass(frozen=True)
class LinearFit:
    """The dominant component of the run in its linear regime.

    Attributes
    ----------
    growth_rate : float
        Fitted sigma [1/s] (> 0 grows).
    frequency_hz : float
        Fitted frequency [Hz].
    mode : str
        Label of the modal coordinate fitted (largest RMS displacement).
    start_s : float
        Start of the fit window [s].
    end_s : float
        Its end [s].
    residual : float
        RMS residual over RMS signal of the fit (dimensionless).
    """

    growth_rate: float
    frequency_hz: float
    mode: str
    start_s: float
    end_s: float
    residual: float


@dataclass(frozen=True)
class LimitCycle:
    """The saturated motion.

    Attributes
    ----------
    time_to_saturation_s : float
        Time from the start until the amplitude first reaches 90 % of saturation [s].
    lateral_m : float
        Peak lateral displacement at the nut centre [m].
    torsion_rad : float
        Peak torsion angle at the nut centre [rad].
    surface_velocity_m_s : float
        Peak tangential surface velocity at the nut centre [m/s].
    surface_velocity_rms_m_s : float
        Its RMS [m/s].
    radial_velocity_m_s : float
        Peak radial surface velocity at the nut centre [m/s].
    min_sliding_m_s : float
        Lowest sliding speed |Vc| at the nut centre [m/s] (never below R |Omega| tan(beta):
        the axial sliding is not perturbed, `transient`).
    fundamental_hz : float
        Largest spectral peak of the tangential surface velocity [Hz].
    harmonics_db : dict
        Level of harmonic k (2..6) relative to the fundamental [dB].
    """

    time_to_saturation_s: float
    lateral_m: float
    torsion_rad: float
    surface_velocity_m_s: float
    surface_velocity_rms_m_s: float
    radial_velocity_m_s: float
    min_sliding_m_s: float
    fundamental_hz: float
    harmonics_db: dict


@dataclass(frozen=True)
class TransientAnalysis:
    """Regime, linear fit and limit cycle of one run (`analyse`).

    Attributes
    ----------
    regime : str
        'decaying', 'growing' (not saturated within the run) or 'limit cycle'.
    linear_fit : LinearFit
        The dominant component in the linear regime.
    limit_cycle : LimitCycle or None
        The saturated motion; None unless the regime is 'limit cycle'.
    amplitude : numpy.ndarray
        The modal energy norm a(t) per sample (unit sqrt(J) per sqrt(kg): m/s).
    """

    regime: str
    linear_fit: LinearFit
    limit_cycle: LimitCycle | None
    amplitude: np.ndarray

    def as_dict(self) -> dict:
        """JSON-ready: regime, linear_fit, limit_cycle (None unless saturated).

        Returns
        -------
        dict
            Field name to value, units as in Attributes (without the amplitude series).
        """
        return {
            "regime": self.regime,
            "linear_fit": asdict(self.linear_fit),
            "limit_cycle": None if self.limit_cycle is None else asdict(self.limit_cycle),
        }


def amplitude(run: TransientResult) -> np.ndarray:
    """The modal energy norm a(t) of the module docstring, per sample."""
    return np.sqrt((run.qdot**2).sum(1) + ((run.q * run.omega_rad_s) ** 2).sum(1))


def fit_growth(t: np.ndarray, x: np.ndarray) -> tuple[float, float, float]:
    """(sigma [1/s], frequency [Hz], relative RMS residual) of the least-squares fit
    x ~ e^{sigma t} (a cos(w t) + b sin(w t)) over samples (t, x).

    Parameters
    ----------
    t : numpy.ndarray
        Sample times [s], evenly spaced.
    x : numpy.ndarray
        Signal.

    Returns
    -------
    tuple of float
        Growth rate, frequency, residual.
    """
    tc = t - t.mean()
    scale = np.abs(x).max() or 1.0
    y = x / scale
    dt = t[1] - t[0]
    spectrum = np.abs(np.fft.rfft(y * np.hanning(len(y)), _PAD * len(y)))
    w0 = 2 * math.pi * np.fft.rfftfreq(_PAD * len(y), dt)[spectrum[1:].argmax() + 1]
    half = len(y) // 2
    s0 = math.log(
        max(np.sqrt(np.mean(y[half:] ** 2)), 1e-300) / max(np.sqrt(np.mean(y[:half] ** 2)), 1e-300)
    ) / (tc[half] - tc[0] or 1)
    basis = np.stack((np.cos(w0 * tc), np.sin(w0 * tc))) * np.exp(s0 * tc)
    ab = np.linalg.lstsq(basis.T, y, rcond=None)[0]

    def residual(v: np.ndarray) -> np.ndarray:
        return np.exp(v[0] * tc) * (v[2] * np.cos(v[1] * tc) + v[3] * np.sin(v[1] * tc)) - y

    sol = least_squares(
        residual, np.array([s0, w0, *ab]), x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14
    )
    rel = float(np.sqrt(np.mean(sol.fun**2) / np.mean(y**2)))
    return float(sol.x[0]), float(abs(sol.x[1]) / (2 * math.pi)), rel


def _spectrum_peaks(t: np.ndarray, x: np.ndarray) -> tuple[float, dict]:
    """Fundamental [Hz] and harmonic levels [dB] of x (its largest peak above 0 Hz)."""
    n = len(x)
    mag = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(n), _PAD * n))
    freq = np.fft.rfftfreq(_PAD * n, t[1] - t[0])
    k0 = mag[1:].argmax() + 1
    f0, level = freq[k0], mag[k0]
    out = {}
    for k in HARMONICS:
        band = (freq > (k - 0.25) * f0) & (freq < (k + 0.25) * f0)
        if band.any():
            out[str(k)] = 20 * math.log10(max(mag[band].max(), 1e-300) / level)
    return float(f0), out


def analyse(run: TransientResult) -> TransientAnalysis:
    """Regime, linear fit and limit cycle of a run (module docstring).

    Parameters
    ----------
    run : TransientResult
        A simulated run.

    Returns
    -------
    TransientAnalysis
        What the run shows.
    """
    t, a = run.time_s, amplitude(run)
    tail = t >= t[-1] * (1 - TAIL)
    change = np.polyfit(t[tail], np.log(a[tail]), 1)[0] * (t[-1] - t[tail][0])
    vibration = np.abs(run.surface_velocity_m_s).max(1)
    engaged = vibration[tail].max() >= ENGAGED_FRACTION * run.steady_sliding_m_s
    regime = (
        "limit cycle"
        if engaged and abs(change) < math.log1p(STEADY_CHANGE)
        else "growing"
        if change > 0
        else "decaying"
    )
    a_sat = float(np.median(a[tail]))
    if regime == "limit cycle":
        linear = a < LINEAR_FRACTION * a_sat
    elif regime == "growing":
        linear = vibration < LINEAR_FRACTION * ENGAGED_FRACTION * run.steady_sliding_m_s
    else:  # down to where the integrator's tolerance shows
        linear = a >= DECAY_FLOOR * a[0]
    end = int(np.argmin(linear)) if linear[0] and not linear.all() else len(t)
    end = max(end, min(len(t), MIN_FIT_SAMPLES))
    window = slice(end // 2, end)
    q = run.q[window]
    j = int(np.sqrt((q**2).mean(0)).argmax())
    growth, freq, residual = fit_growth(t[window], q[:, j])
    fit = LinearFit(
        growth, freq, run.labels[j], float(t[window][0]), float(t[window][-1]), residual
    )
    if regime != "limit cycle":
        return TransientAnalysis(regime, fit, None, a)
    sat = int(np.argmax(a >= SATURATED_FRACTION * a_sat))
    steady = slice(sat + (len(t) - sat) // 2, len(t))
    v = run.surface_velocity_m_s[steady]
    f0, harmonics = _spectrum_peaks(t[steady], v[:, 1])
    cycle = LimitCycle(
        time_to_saturation_s=float(t[sat]),
        lateral_m=float(np.hypot(*run.lateral_m[steady].T).max()),
        torsion_rad=float(np.abs(run.torsion_rad[steady]).max()),
        surface_velocity_m_s=float(np.abs(v[:, 1]).max()),
        surface_velocity_rms_m_s=float(np.sqrt(np.mean(v[:, 1] ** 2))),
        radial_velocity_m_s=float(np.abs(v[:, 0]).max()),
        min_sliding_m_s=float(run.sliding_speed_m_s[steady].min()),
        fundamental_hz=f0,
        harmonics_db=harmonics,
    )
    return TransientAnalysis(regime, fit, cycle, a)


def linear_counterparts(
    params: ScrewParameters, speed_rad_s: float, load_n: float, fit: LinearFit
) -> dict[str, dict]:
    """The eigenvalue of the fitted mode from each formulation at the same point.

    The mode with the fit's label closest in frequency (any mode closest in frequency when
    none has the label), and the formulation's most unstable mode.

    Parameters
    ----------
    params : ScrewParameters
        The parameters of the run (its formulation is replaced by each in turn).
    speed_rad_s : float
        Screw speed Omega [rad/s].
    load_n : float
        Axial load F_z [N].
    fit : LinearFit
        The run's linear fit.

    Returns
    -------
    dict
        Per formulation: growth_rate [1/s], frequency_hz, mode, unstable, most_unstable
        {mode, frequency_hz, growth_rate} and reason ('' when valid; the rest None when the
        linear model refuses the point, e.g. below min_speed_rad_s).
    """
    out: dict[str, dict[str, Any]] = {}
    for name in FORMULATIONS:
        pred = SqueakModel(params.with_(formulation=name), Scatter({})).predict(speed_rad_s, load_n)
        if not pred.valid or not pred.modes:
            out[name] = {
                "growth_rate": None,
                "frequency_hz": None,
                "mode": None,
                "unstable": None,
                "most_unstable": None,
                "reason": pred.reason,
            }
            continue
        same = [m for m in pred.modes if m.label == fit.mode] or list(pred.modes)
        m = min(same, key=lambda m: abs(m.frequency_hz - fit.frequency_hz))
        top = pred.modes[0]
        out[name] = {
            "growth_rate": m.growth_rate,
            "frequency_hz": m.frequency_hz,
            "mode": m.label,
            "unstable": m.unstable,
            "most_unstable": {
                "mode": top.label,
                "frequency_hz": top.frequency_hz,
                "growth_rate": top.growth_rate,
            },
            "reason": "",
        }
    return out
