# SPDX-License-Identifier: Apache-2.0
"""`transient`: the nonlinear time-domain simulation at one operating point (issue 13): the
growth fitted in the linear regime against both formulations' eigenvalues, the limit cycle,
the squeak as a WAV file and a plot of the time history and spectrogram.

The simulated force is the nonlinear friction of `model.nonlinear.friction_force`, whose
linearisation is the `consistent` formulation whatever --formulation says; --formulation picks
the eigenvalue the text output compares with (JSON has both). The eigenvalues are those of the
full model
(all modes of the parameters), also when --modes keeps fewer in the simulation.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import fields
from pathlib import Path

import numpy as np

from ..model.nonlinear.transient import TransientResult, TransientSettings, simulate
from ..model.nonlinear.transient_analysis import TransientAnalysis, analyse, linear_counterparts
from ..model.physics.metadata import help_text
from ..model.physics.parameters import FORMULATIONS, ScrewParameters
from .args import Parser, build_model, finite, output_file, plot_file, print_json

WAV_RATE_HZ = 48000
WAV_FULL_SCALE = 32767  # int16 code of the largest |surface velocity|
_SETTINGS = {f.name: f for f in fields(TransientSettings)}
_OPTIONS = ("duration_s", "modes", "regularisation_m_s", "seed")  # the settings with options


def audio(run: TransientResult) -> tuple[np.ndarray, float]:
    """The tangential surface velocity at the nut centre resampled to 48 kHz as int16 and the
    velocity of full scale [m/s] (code 32767), the normalisation factor."""
    from scipy.signal import resample_poly

    rate = int(round(1 / (run.time_s[1] - run.time_s[0])))
    g = math.gcd(rate, WAV_RATE_HZ)
    x = resample_poly(run.surface_velocity_m_s[:, 1], WAV_RATE_HZ // g, rate // g)
    peak = float(np.abs(x).max()) or 1.0
    return np.round(x * (WAV_FULL_SCALE / peak)).astype(np.int16), peak


def write_wav(path: Path, samples: np.ndarray) -> None:
    """16-bit mono PCM at 48 kHz."""
    from scipy.io import wavfile

    wavfile.write(path, WAV_RATE_HZ, samples)


def _text(args: argparse.Namespace, result: TransientAnalysis, linear: dict, elapsed: str) -> str:
    fit, cycle = result.linear_fit, result.limit_cycle
    lines = [
        f"speed {args.speed:g} rad/s, load {args.load_n:g} N: {result.regime}",
        f"linear regime ({fit.start_s * 1e3:.1f}-{fit.end_s * 1e3:.1f} ms): {fit.mode} "
        f"{fit.frequency_hz:.2f} Hz, growth {fit.growth_rate:+.2f} 1/s",
    ]
    chosen = linear[args.shown]
    if chosen["growth_rate"] is None:
        lines.append(f"{args.shown} eigenvalue: none ({chosen['reason']})")
    else:
        top = chosen["most_unstable"]
        lines.append(
            f"{args.shown} eigenvalue of {chosen['mode']}: "
            f"{chosen['frequency_hz']:.2f} Hz, growth {chosen['growth_rate']:+.2f} 1/s; "
            f"least stable {top['mode']} {top['frequency_hz']:.2f} Hz, growth "
            f"{top['growth_rate']:+.2f} 1/s"
        )
    if cycle is not None:
        harm = ", ".join(f"{k}: {v:.0f} dB" for k, v in cycle.harmonics_db.items())
        lines += [
            f"limit cycle after {cycle.time_to_saturation_s * 1e3:.1f} ms: surface "
            f"velocity {cycle.surface_velocity_m_s:.3g} m/s peak "
            f"({cycle.surface_velocity_rms_m_s:.3g} rms), torsion "
            f"{cycle.torsion_rad:.3g} rad, lateral {cycle.lateral_m:.3g} m, lowest "
            f"sliding speed {cycle.min_sliding_m_s:.3g} m/s",
            f"fundamental {cycle.fundamental_hz:.1f} Hz; harmonics {harm}",
        ]
    return "\n".join(lines + [elapsed])


def cmd_transient(args: argparse.Namespace) -> int:
    """`transient`: simulate the nonlinear transient and analyse it; exit status."""
    model = build_model(args)
    params: ScrewParameters = model.params
    args.load_n = params.axial_load_n if args.load is None else args.load
    args.shown = params.formulation
    settings = TransientSettings(
        **{k: getattr(args, k) for k in _OPTIONS if getattr(args, k) is not None}
    )
    wav, plot = output_file(args.wav, "--wav", ("wav",)), plot_file(args.plot)
    start = time.perf_counter()
    run = simulate(params, args.speed, args.load_n, settings)
    elapsed = time.perf_counter() - start
    result = analyse(run)
    linear = linear_counterparts(params, args.speed, args.load_n, result.linear_fit)
    out = {
        "speed_rad_s": args.speed,
        "load_n": args.load_n,
        **result.as_dict(),
        "linear_model": linear,
        "settings": {k: getattr(settings, k) for k in _SETTINGS},
        "run_time_s": elapsed,
        "wav": None,
    }
    if wav:
        samples, full_scale = audio(run)
        write_wav(wav, samples)
        out["wav"] = {"file": args.wav, "rate_hz": WAV_RATE_HZ, "full_scale_m_s": full_scale}
    if plot:
        from ..review.plots import plot_transient

        plot_transient(
            run, result, title=f"{args.speed:g} rad/s, {args.load_n:g} N, {run.q.shape[1]} modes"
        ).savefig(plot, dpi=120)
    if args.json:
        print_json(out)
    else:
        print(
            _text(args, result, linear, f"simulated {settings.duration_s:g} s in {elapsed:.1f} s")
        )
    return 0


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `transient` to `sub`; `common`: the model options."""
    p = sub.add_parser(
        "transient", parents=common, help="nonlinear time-domain simulation at one operating point"
    )
    p.add_argument(
        "--speed",
        type=finite,
        required=True,
        metavar="RAD_S",
        help="rotation speed Omega [rad/s], nonzero (also below min_speed_rad_s, "
        "where the linear model gives no eigenvalues)",
    )
    p.add_argument(
        "--load",
        type=finite,
        metavar="N",
        help="axial load F_z [N] (default: parameter axial_load_n)",
    )
    p.add_argument(
        "--duration",
        dest="duration_s",
        type=finite,
        metavar="S",
        help=help_text(_SETTINGS["duration_s"]),
    )
    p.add_argument("--modes", type=int, metavar="K", help=help_text(_SETTINGS["modes"]))
    p.add_argument(
        "--regularisation",
        dest="regularisation_m_s",
        type=finite,
        metavar="M_S",
        help=help_text(_SETTINGS["regularisation_m_s"]),
    )
    p.add_argument("--seed", type=int, metavar="N", help=help_text(_SETTINGS["seed"]))
    p.add_argument(
        "--wav",
        metavar="FILE.wav",
        help="tangential surface velocity at the nut centre as 16-bit mono audio "
        f"at {WAV_RATE_HZ} Hz, normalised (full scale in the JSON)",
    )
    p.add_argument("--plot", metavar="FILE.png", help="amplitude, surface velocity and spectrogram")
    p.add_argument(
        "--json",
        action="store_true",
        help="print JSON: regime, linear_fit {growth_rate, frequency_hz, mode}, "
        f"linear_model {{{', '.join(FORMULATIONS)}}}, limit_cycle or null, "
        "wav {file, rate_hz, full_scale_m_s} or null",
    )
    p.set_defaults(run=cmd_transient)
