# SPDX-License-Identifier: Apache-2.0
"""What heard / not-heard frames can tell: the known limit of doc/user/calibration.md.

    .venv/bin/python tools/calibration_ridge.py BENCH [CALIBRATION ...] [--units N] [--band-hi-hz F]

BENCH is a `leadscrew-squeak bench` output (its truth.json); each CALIBRATION a `calibrate
--out` directory of that bench. For the first N units, the exact model (the bench's own,
`virtual_bench.squeak_frequencies`) along each unit's stroke at the bench's input rate decides
where it squeaks in the detector's band, at its true parameters and at changed ones:

- along the ratio: the friction drop mu_s - mu_k and the damping scaled by one factor (mu_k
  kept), and each of them alone;
- at each calibration's posterior mean of the unit.

and, per calibration, its fleet mean of the drop against the units', how many of the units'
90 % intervals of the drop cover their truths, and its held-out Brier scores.

It prints the share of the stroke whose verdict changes and that change per squeak edge in ms,
to set beside the detector's frame (`DetectorSettings.frame_s`) and the collar of frames not
scored around a heard edge (`listen.COLLAR_S`): a change that moves the edges by less than the
collar leaves every scored frame as it was.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from leadscrew_ros.bag.virtual_bench import squeak_frequencies
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.model import ScrewParameters
from leadscrew_ros.model.acoustics.settings import DetectorSettings
from leadscrew_ros.review.listen import COLLAR_S

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibration_example import widths  # noqa: E402  (a tool beside this one)

STROKE = ("duration_s", "peak_speed_rad_s", "load_min_n", "load_max_n", "start_nut_position_m")
NAMES = ("mu_static", "mu_kinetic", "friction_decay_s_m", "modal_damping")
#: (label, factor on the drop, factor on the damping)
CHANGES = (
    ("drop and damping x 0.8", 0.8, 0.8),
    ("drop and damping x 1.25", 1.25, 1.25),
    ("drop and damping x 1.5", 1.5, 1.5),
    ("drop x 1.25 alone", 1.25, 1.0),
    ("damping x 1.25 alone", 1.0, 1.25),
)


def heard(params: ScrewParameters, stroke: dict[str, float], rate_hz: float, hi_hz: float) -> Any:
    """Where a stroke (`STROKE` fields) squeaks at a frequency the detector hears (bool per
    sample at `rate_hz`)."""
    _, speed, load, nut = StrokeProfile.for_params(params, **stroke).sampled(rate_hz)
    f = squeak_frequencies(params, speed, load, nut)
    return np.isfinite(f) & (f >= DetectorSettings.f_lo_hz) & (f <= hi_hz)


def ratio_variants(params: ScrewParameters) -> dict[str, ScrewParameters]:
    """`params` changed as each of `CHANGES` says, by label (mu_k kept)."""
    drop = params.mu_static - params.mu_kinetic
    return {
        label: params.with_(
            mu_static=params.mu_kinetic + f_drop * drop,
            modal_damping=f_damping * params.modal_damping,
        )
        for label, f_drop, f_damping in CHANGES
    }


def changes(
    params: ScrewParameters,
    variants: dict[str, ScrewParameters],
    stroke: dict[str, float],
    rate_hz: float,
    hi_hz: float,
) -> dict[str, tuple[float, float]]:
    """Per variant: the share of the stroke whose verdict differs from that of `params`, and
    that time per squeak edge of `params` [ms]."""
    base = heard(params, stroke, rate_hz, hi_hz)
    edges = max(int(np.count_nonzero(np.diff(base.astype(int)))), 1)
    out = {}
    for label, q in variants.items():
        changed = float(np.mean(base != heard(q, stroke, rate_hz, hi_hz)))
        out[label] = changed, 1e3 * changed * len(base) / rate_hz / edges
    return out


def row(label: str, changed: list[float], edge_ms: list[float]) -> str:
    """One Markdown row: mean (max) share of the stroke changed, mean change per edge."""
    c = 100 * np.asarray(changed)
    return f"| {label} | {c.mean():.2f} ({c.max():.2f}) | {np.mean(edge_ms):.0f} |"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bench", type=Path)
    ap.add_argument("calibrations", type=Path, nargs="*")
    ap.add_argument("--units", type=int, default=20)
    ap.add_argument("--band-hi-hz", type=float, default=DetectorSettings.f_hi_hz)
    args = ap.parse_args(argv)
    truth = json.loads((args.bench / "truth.json").read_text())
    rate = float(truth["settings"]["input_rate_hz"])
    units = truth["units"][: args.units]
    docs = [json.loads((c / "calibration.json").read_text()) for c in args.calibrations]
    posteriors = [{u["unit_id"]: u["posterior"] for u in doc["units"]} for doc in docs]
    rows: dict[str, tuple[list[float], list[float]]] = {}
    for unit in units:
        p = ScrewParameters(formulation=truth["formulation"], **unit["params"])
        variants = ratio_variants(p)
        for c, post in zip(args.calibrations, posteriors, strict=True):
            if mean := post[unit["unit_id"]]:
                variants[f"the posterior mean of `{c.name}`"] = p.with_(
                    **{n: mean[n]["mean"] for n in NAMES}
                )
        stroke = {k: unit["stroke"][k] for k in STROKE}
        for label, (changed, edge_ms) in changes(
            p, variants, stroke, rate, args.band_hi_hz
        ).items():
            shares, per_edge = rows.setdefault(label, ([], []))
            shares.append(changed)
            per_edge.append(edge_ms)
    print(
        f"{truth['formulation']} bench, {len(units)} units: the heard verdict along the stroke "
        f"at the truth vs changed parameters (detector frame {DetectorSettings.frame_s:g} s, "
        f"collar {1e3 * COLLAR_S:.0f} ms)\n"
    )
    print("| change from each unit's truth | stroke changed, % mean (max) | per squeak edge, ms |")
    print("|---|---:|---:|")
    for label, (changed, edge_ms) in rows.items():
        print(row(label, changed, edge_ms))
    drops = {u["unit_id"]: u["params"]["mu_static"] - u["params"]["mu_kinetic"] for u in units}
    print(f"\nThe {len(units)} units' mean friction drop is {np.mean(list(drops.values())):.4g}.")
    for c, doc, post in zip(args.calibrations, docs, posteriors, strict=True):
        fleet = doc["population"]["friction_drop"]
        hits = [
            post[k]["friction_drop"]["q05"] <= v <= post[k]["friction_drop"]["q95"]
            for k, v in drops.items()
            if post[k]
        ]
        m = fleet["mean"]
        print(
            f"- `{c.name}`: fleet mean drop {m['mean']:.4g} [{m['q05']:.4g}, {m['q95']:.4g}], "
            f"{widths(doc)[1]:.2f} of the prior's 90 % interval of a unit's drop; the units' "
            f"90 % intervals cover their drops in {sum(hits)} of {len(hits)}; held-out Brier "
            f"score {doc['held_out']['brier_prior']:.4f} with the prior, "
            f"{doc['held_out']['brier_calibrated']:.4f} calibrated."
        )


if __name__ == "__main__":
    main()
