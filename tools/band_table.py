# SPDX-License-Identifier: Apache-2.0
"""Numbers for doc/theory/formulations.md: per-mode squeak speed ranges and the nut-position trend.

    .venv/bin/python tools/band_table.py

prints, for both formulations at Table 1, the page's rows computed from the model:

- every oscillatory mode that is unstable somewhere below the first critical speed, with the
  speed range where it squeaks: the branch is followed along a fine geometric speed grid
  (`model.studies.tracking.track_modes`) and each of its sign changes refined by bisection on that
  branch (its eigenvalue is followed by continuation, so a crossing of another mode does not confuse
  it); an end at the grid start is marked as the validity limit min_speed_rad_s;
- the lowest unstable load at the reference speed (Fig. 10's data, refined by root finding)
  against the nut position z_o, and whether it falls or rises monotonically.

test/test_band_table.py runs it and checks the numbers against independent references.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.studies.fields import REFERENCE_SPEED_RAD_S
from leadscrew_ros.model.studies.sweep import sweep
from leadscrew_ros.model.studies.tracking import track_modes
from leadscrew_ros.review.plots import fmt

FORMULATIONS = ("paper", "consistent")
SPEED_POINTS = 1500
NUT_POINTS = 49  # z_o every 5 mm at Table 1
LOADS_N = np.linspace(0.0, 600.0, 121)


@dataclass(frozen=True)
class ModeRange:
    """Where one mode branch squeaks: (lo, hi) speed intervals in rad/s."""

    label: str
    frequency_hz: float
    intervals: list[tuple[float, float]]
    starts_at_min_speed: bool  # unstable at the lowest valid speed: lo is no boundary

    def text(self) -> str:
        parts = [f"{lo:.3g}-{hi:.3g}" for lo, hi in self.intervals]
        if self.starts_at_min_speed:
            parts[0] = "<= " + parts[0]
        return f"{self.label} ({', '.join(parts)} rad/s)"


def _nearest(model: SqueakModel, speed: float, load: float, lam: complex) -> complex:
    modes = model.predict(speed, load).modes
    eig = np.array([complex(m.growth_rate, 2 * math.pi * m.frequency_hz) for m in modes])
    return complex(eig[np.argmin(np.abs(eig - lam) / np.maximum(abs(lam), np.abs(eig)))])


def _refine(
    model: SqueakModel, load: float, a: float, lam_a: complex, b: float, lam_b: complex
) -> float:
    """Speed in (a, b) where the branch through lam_a (at a) and lam_b (at b) has Re = 0."""
    while b - a > 1e-10 * b:
        mid = math.sqrt(a * b)
        lam = _nearest(model, mid, load, lam_a)
        if (lam.real > 0) == (lam_a.real > 0):
            a, lam_a = mid, lam
        else:
            b = mid
    return math.sqrt(a * b)


def mode_ranges(model: SqueakModel, points: int = SPEED_POINTS) -> list[ModeRange]:
    """Every mode branch that squeaks between min_speed_rad_s and the first critical speed,
    by frequency, at the model's axial load."""
    p = model.params
    speeds = np.geomspace(p.min_speed_rad_s, model.critical_speed_rad_s * (1 - 1e-6), points)
    branches = track_modes(model.predict_many(speeds, p.axial_load_n))
    out = []
    for b in branches:
        lam = b.growth + 2j * math.pi * b.frequency_hz
        unstable = np.nan_to_num(b.growth, nan=-1.0) > 0
        if not unstable.any():
            continue
        edges = []
        for i in range(points - 1):
            if unstable[i] != unstable[i + 1] and np.isfinite(lam[[i, i + 1]]).all():
                edges.append(
                    _refine(model, p.axial_load_n, speeds[i], lam[i], speeds[i + 1], lam[i + 1])
                )
            elif unstable[i] != unstable[i + 1]:
                raise RuntimeError(f"branch {b.label} appears unstable: refine the grid")
        if unstable[0]:
            edges.insert(0, float(speeds[0]))
        if unstable[-1]:
            raise RuntimeError(f"branch {b.label} unstable up to the critical speed")
        out.append(
            ModeRange(
                b.label,
                b.squeak_frequency_hz,
                list(zip(edges[::2], edges[1::2], strict=True)),
                bool(unstable[0]),
            )
        )
    return sorted(out, key=lambda r: r.frequency_hz)


def lowest_unstable_load(model: SqueakModel, nut_positions_m: np.ndarray) -> np.ndarray:
    """Refined lowest unstable load at the reference speed for each nut position, N."""
    out = []
    for z in nut_positions_m.tolist():
        bands = sweep(
            model.with_params(nut_position_m=z),
            "load_n",
            LOADS_N,
            speed_rad_s=REFERENCE_SPEED_RAD_S,
        ).unstable_bands
        out.append(bands[0][0] if bands else math.nan)
    return np.array(out)


def nut_trend(model: SqueakModel, points: int = NUT_POINTS) -> str:
    """The lowest unstable load against z_o: its ends, its smallest value and every interior
    local minimum (a nut position where squeak is easier than on both sides)."""
    p = model.params
    z = np.linspace(0.0, p.nut_travel_m, points)
    load = lowest_unstable_load(model, z)
    step = np.diff(load)
    shape = (
        "falls monotonically"
        if (step < 0).all()
        else "rises monotonically"
        if (step > 0).all()
        else "is not monotonic"
    )
    i = int(np.nanargmin(load))
    dips = [
        f"{load[k]:.3g} N at z_o = {fmt('nut_position_m', z[k])}"
        for k in range(1, points - 1)
        if load[k] < min(load[k - 1], load[k + 1])
    ]
    return (
        f"{p.formulation}: the lowest unstable load at "
        f"{fmt('speed_rad_s', REFERENCE_SPEED_RAD_S)} {shape}: {load[0]:.3g} N at z_o = "
        f"{fmt('nut_position_m', z[0])}, {load[-1]:.3g} N at z_o = "
        f"{fmt('nut_position_m', z[-1])}; smallest {load[i]:.3g} N at z_o = "
        f"{fmt('nut_position_m', z[i])}; interior local minima: {'; '.join(dips) or 'none'} "
        f"({points} positions)"
    )


def table_row(models: dict[str, SqueakModel]) -> str:
    cells = [", ".join(r.text() for r in mode_ranges(models[f])) for f in FORMULATIONS]
    return f"| squeak modes anywhere in the band | {cells[0]} | {cells[1]} |"


def main() -> None:
    models = {f: SqueakModel(ScrewParameters(formulation=f)) for f in FORMULATIONS}
    print(table_row(models))
    for f in FORMULATIONS:
        print(nut_trend(models[f]))


if __name__ == "__main__":
    main()
