#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Numbers for doc/theory/transient.md, "Nonlinear time-domain check" (issue 13).

    .venv/bin/python tools/transient_table.py [--plot [doc/images/transient.png]]  # ~5 min, 2 cores

Simulates the nonlinear equations (`model.nonlinear.transient`, Table 1, all 18 modes, default
settings) at (20 rad/s, 200 N), (5 rad/s, 200 N), (40 rad/s, 300 N) and (60 rad/s, 200 N) (above the
band of both formulations) and prints, as Markdown:

1. the growth rate and frequency fitted in the linear regime against the eigenvalue of the
   same mode in both formulations, and each formulation's least stable mode;
2. the limit cycle of each run that saturates;
3. the --modes effect at (20 rad/s, 200 N): 6, 12 and 18 modes;
4. the run at 0.2 rad/s (below min_speed_rad_s): a small and a large perturbation, with the
   least stable eigenvalue of the run's own linearisation and the lowest sliding speed;
5. a diagnosis of the printed appendix (no simulation): the `paper` matrices with only the
   torsion block of W3 multiplied by R^2 (the factor NOTES.md finds missing from
   W3[Phi^0 Phi^0]), against `paper` and `consistent`: the least stable modes, and B1y.

`--plot` also writes the time history and spectrogram of the (20 rad/s, 200 N) run (default
doc/images/transient.png, the figure of that page).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from leadscrew_ros.model import ScrewParameters
from leadscrew_ros.model.nonlinear.transient import TransientSettings, simulate
from leadscrew_ros.model.nonlinear.transient_analysis import analyse, linear_counterparts
from leadscrew_ros.model.physics.assembly import build_geometry
from leadscrew_ros.model.physics.modes import KIND_T
from leadscrew_ros.review.plots import plot_transient

POINTS = ((20.0, 200.0, 0.2), (5.0, 200.0, 0.1), (40.0, 300.0, 0.35), (60.0, 200.0, 0.1))
MODES = (6, 12, 0)
PLOT = Path(__file__).resolve().parents[1] / "doc" / "images" / "transient.png"
SLOW = ((0.2, 200.0, 1e-6), (0.2, 200.0, 1.0))  # speed, load, perturbation
SLOW_DURATION_S = 0.05


def _run(params: ScrewParameters, speed: float, load: float, **settings):
    run = simulate(params, speed, load, TransientSettings(**settings))
    return run, analyse(run)


def _oscillatory(stiffness: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """Eigenvalues with Im > 0 of qdd + D qd + K q = 0, least stable first."""
    n = len(stiffness)
    lam = np.linalg.eigvals(np.block([[np.zeros((n, n)), np.eye(n)], [-stiffness, -damping]]))
    lam = lam[lam.imag > 0]
    return lam[np.argsort(-lam.real)]


def _show(lam: np.ndarray, count: int = 2) -> str:
    return ", ".join(f"{x.real:+.1f} / {x.imag / (2 * math.pi):.1f}" for x in lam[:count])


def appendix_rows(points) -> list[str]:
    """Table 5: paper, paper with R^2 in W3[0,0], consistent (least stable two; B1y)."""
    rows = []
    for speed, load, _ in points:
        out = {}
        for name in ("paper", "consistent"):
            g = build_geometry(ScrewParameters(formulation=name))
            m = g.matrices(speed, load)
            out[name] = _oscillatory(m.stiffness, m.damping)
            if name == "paper":
                torsion = np.ix_(g.basis.kind == KIND_T, g.basis.kind == KIND_T)
                fixed = m.damping.copy()
                fixed[torsion] += (g.params.radius_m**2 - 1) * m.W["W3"][torsion]
                out["fixed"] = _oscillatory(m.stiffness, fixed)
        near = {k: v[np.argmin(np.abs(v.imag / (2 * math.pi) - 224.0))] for k, v in out.items()}
        rows.append(
            f"| {speed:g} rad/s, {load:g} N | {_show(out['paper'])} | "
            f"{_show(out['fixed'])} | {_show(out['consistent'])} | "
            f"{near['paper'].real:+.1f} / {near['fixed'].real:+.1f} / "
            f"{near['consistent'].real:+.1f} |"
        )
    return rows


def _rel(a: float | None, b: float | None) -> str:
    return "–" if a is None or b is None else f"{(a - b) / abs(b):+.1e}"


def _eig(entry: dict) -> str:
    if entry["growth_rate"] is None:
        return "refused"
    return f"{entry['mode']} {entry['growth_rate']:+.2f} / {entry['frequency_hz']:.2f}"


def _least(entry: dict) -> str:
    top = entry["most_unstable"]
    return (
        "–"
        if top is None
        else (f"{top['mode']} {top['growth_rate']:+.2f} / {top['frequency_hz']:.2f}")
    )


def _cycle_row(label: str, result) -> str:
    c = result.limit_cycle
    harm = ", ".join(f"{k}: {v:.0f}" for k, v in c.harmonics_db.items())
    return (
        f"| {label} | {c.time_to_saturation_s * 1e3:.1f} | {c.surface_velocity_m_s:.3g} "
        f"({c.surface_velocity_rms_m_s:.3g}) | {c.radial_velocity_m_s:.2g} | "
        f"{c.torsion_rad:.3g} | {c.lateral_m:.2g} | {c.min_sliding_m_s:.3g} | "
        f"{c.fundamental_hz:.1f} | {harm} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--plot",
        type=Path,
        nargs="?",
        const=PLOT,
        help="PNG of the (20 rad/s, 200 N) run (default doc/images/transient.png)",
    )
    args = parser.parse_args()
    params = ScrewParameters()
    runs = {}
    print(
        "| point | regime | fit: mode growth [1/s] / frequency [Hz] | consistent, same "
        "mode | fit - consistent (growth, frequency) | paper, same label | paper least "
        "stable | consistent least stable |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for speed, load, duration in POINTS:
        run, result = runs[(speed, load)] = _run(params, speed, load, duration_s=duration)
        fit = result.linear_fit
        lin = linear_counterparts(params, speed, load, fit)
        c, p = lin["consistent"], lin["paper"]
        print(
            f"| {speed:g} rad/s, {load:g} N | {result.regime} | {fit.mode} "
            f"{fit.growth_rate:+.2f} / {fit.frequency_hz:.2f} | {_eig(c)} | "
            f"{_rel(fit.growth_rate, c['growth_rate'])}, "
            f"{_rel(fit.frequency_hz, c['frequency_hz'])} | {_eig(p)} | {_least(p)} | "
            f"{_least(c)} |"
        )
    print(
        "\n| limit cycle | saturation [ms] | tangential surface velocity peak (rms) [m/s] | "
        "radial [m/s] | torsion [rad] | lateral [m] | lowest sliding speed [m/s] | "
        "fundamental [Hz] | harmonics 2..6 [dB] |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for (speed, load), (run, result) in runs.items():
        if result.limit_cycle is not None:
            print(
                _cycle_row(
                    f"{speed:g} rad/s, {load:g} N (steady sliding "
                    f"{run.steady_sliding_m_s:.3g} m/s)",
                    result,
                )
            )
    print(
        "\n| modes at 20 rad/s, 200 N | regime | fit: mode growth [1/s] / frequency [Hz] | "
        "saturation [ms] | surface velocity peak [m/s] | torsion [rad] | fundamental [Hz] | "
        "harmonics 3, 5 [dB] |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for k in MODES:
        run, result = runs[(20.0, 200.0)] if k == 0 else _run(params, 20.0, 200.0, modes=k)
        fit, c = result.linear_fit, result.limit_cycle
        tail = (
            "– | – | – | – | –"
            if c is None
            else f"{c.time_to_saturation_s * 1e3:.1f} | {c.surface_velocity_m_s:.3g} | "
            f"{c.torsion_rad:.3g} | {c.fundamental_hz:.1f} | "
            f"{c.harmonics_db['3']:.0f}, {c.harmonics_db['5']:.0f}"
        )
        print(
            f"| {len(run.labels)} | {result.regime} | {fit.mode} {fit.growth_rate:+.2f} / "
            f"{fit.frequency_hz:.2f} | {tail} |"
        )
    print(
        f"\n| 0.2 rad/s, 200 N, {SLOW_DURATION_S * 1e3:g} ms | regime | least stable "
        "eigenvalue of the run's linearisation [1/s] / [Hz] | amplitude end / start | "
        "lowest sliding speed at the nut [m/s] (steady) |"
    )
    print("|---|---|---|---|---|")
    for speed, load, perturbation in SLOW:
        run, result = _run(
            params, speed, load, duration_s=SLOW_DURATION_S, perturbation=perturbation
        )
        lam = run.jacobian_eigenvalues
        top = lam[np.argmax(lam.real)]
        print(
            f"| perturbation {perturbation:g} | {result.regime} | {top.real:+.2f} / "
            f"{abs(top.imag) / (2 * math.pi):.3g} | "
            f"{result.amplitude[-1] / result.amplitude[0]:.2g} | "
            f"{run.sliding_speed_m_s.min():.3g} ({run.steady_sliding_m_s:.3g}) |"
        )
    print(
        "\n| printed appendix | paper: least stable [1/s] / [Hz] | paper with R^2 in "
        "W3[0,0] | consistent | growth of the 224 Hz mode (B1): paper / with R^2 / "
        "consistent [1/s] |"
    )
    print("|---|---|---|---|---|")
    print("\n".join(appendix_rows(POINTS)))
    if args.plot:
        run, result = runs[(20.0, 200.0)]
        plot_transient(
            run, result, title="20 rad/s, 200 N, Table 1, 18 modes: nonlinear simulation"
        ).savefig(args.plot, dpi=120)  # as `transient --plot`


if __name__ == "__main__":
    main()
