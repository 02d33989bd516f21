# SPDX-License-Identifier: Apache-2.0
"""What a calibration writes into its output directory.

- calibration.json: `units` (unit_id, logs, status, posterior {name: {mean, sd, q05, q50, q95}}
  with friction_drop, held_out, convergence), `population` ({name: {mean: {mean, q05, q95}, sd:
  {...}}} with friction_drop; null without one) and `population_convergence`, `held_out` (units,
  brier_prior, brier_calibrated, frames, per_unit, reliability), `formulations` (with both:
  paper and consistent {score, frequency_match, brier_prior, population_status, not_converged,
  population}, supported, strength, decided_by, z, rule),
  `inputs` (each input's unit and what it gave), `settings` (what the run was made with;
  `settings.run` holds what differs between identical runs: date, output path, wall times);
  strict JSON (`jsonsafe`);
- calibration.txt: the run on one screen;
- calibration.png: `plots.plot_calibration`;
- calibrated.yaml: the calibrated population as a ROS parameter file keyed `/**:` (every model
  parameter and every `scatter.*`, as config/leadscrew.yaml holds them), which the node,
  `predict`, `replay` and `review` load as they are, with the data it came from in a comment
  header; written only when there is a population.
"""

from __future__ import annotations

import datetime
import json
from pathlib import Path
from typing import Any

from ... import __version__
from ...model.calibration.posterior import DROP, PRIOR_ALONE_SD_RATIO
from ...model.calibration.prior import DAMPING
from ...model.physics.display import yaml_value
from ...model.uncertainty.scatter import LOG_NORMAL, scatterable
from ..jsonsafe import json_safe
from ..listen import FULL_SHARE
from .run import (
    FREQUENCY_DECISIVE,
    STRONG_Z,
    WEAK_Z,
    CalibrationResult,
    FormulationRun,
    UnitResult,
)

JSON_FILE, TEXT_FILE, PNG_FILE, YAML_FILE = (
    "calibration.json",
    "calibration.txt",
    "calibration.png",
    "calibrated.yaml",
)
RULE = (
    f"frequency match (share of the heard frames at an unstable mode predicted at the units' "
    f"posterior means) differing by {FREQUENCY_DECISIVE:g} or more decides, strongly unless "
    f"the held-out Brier score favours the other by {WEAK_Z:g} standard errors; then the "
    f"growth-rate match (share of the onsets' measured growth rates within two SDs of "
    f"Re(lambda) there) the same way; otherwise the "
    f"lower held-out Brier score, strongly at a mean paired difference over the held-out units "
    f"of {STRONG_Z:g} standard errors or more, weakly at {WEAK_Z:g}, else not distinguishably"
)
_LISTED = 12  # units and logs named in the text and the YAML header


def _run_dict(run: FormulationRun) -> dict[str, Any]:
    h = run.held_out
    return {
        "units": h.units,
        "brier_prior": h.brier_prior,
        "brier_calibrated": h.brier_calibrated,
        "frames": h.frames,
        "per_unit": {u: {"prior": a, "calibrated": b} for u, (a, b) in h.per_unit.items()},
        "frequency_match": {"prior": h.frequency_match[0], "calibrated": h.frequency_match[1]},
        "motor_off": {"heard": h.background[0], "frames": h.background[1]},
        "warnings": h.warnings(),
    }


def _calibrated(run: FormulationRun) -> dict[str, Any] | None:
    """calibrated.yaml's values of the calibrated names (the predictive centre and SD, after
    clipping) and what was clipped; None without a population."""
    if run.params is None or run.scatter is None or run.population is None:
        return None
    names = run.population.names
    sd = dict(run.scatter.sd)
    return {
        "params": {n: getattr(run.params, n) for n in names},
        "scatter": {n: sd.get(n, 0.0) for n in names},
        "notes": run.notes,
    }


def document(result: CalibrationResult, context: dict[str, Any]) -> dict[str, Any]:
    """calibration.json (the module's keys).

    Parameters
    ----------
    result : CalibrationResult
        The run.
    context : dict
        What the run was made with beyond `result.settings` (inputs, prior, replay inputs,
        cluster, ...), for `settings`; its key `run` goes to `settings.run`.

    Returns
    -------
    dict
        JSON-safe.
    """
    run = result.run
    pop = run.population
    doc: dict[str, Any] = {
        "units": [u.as_dict() for u in run.units],
        "population": pop.summary() if pop is not None else None,
        "population_convergence": {
            "status": run.population_status,
            "converged": None if pop is None else pop.converged,
            "ess": None if pop is None else pop.ess,
            "units": sum(u.hierarchical is not None for u in run.units),
        },
        "calibrated": _calibrated(run),
        "hearing": None if run.hearing is None else result.settings.hearing.summary(run.hearing),
        "held_out": {
            **_run_dict(run),
            "reliability": run.held_out.reliability(result.settings.reliability_bins),
        },
    }
    if result.comparison is not None:
        c = result.comparison
        doc["formulations"] = {
            **{
                name: {
                    "score": r.score,
                    "frequency_match": r.frequency_match,
                    "growth_match": r.growth_match,
                    "brier_prior": r.held_out.brier_prior,
                    "population_status": r.population_status,
                    "not_converged": [
                        u.unit_id for u in r.units if u.status.startswith("not converged")
                    ],
                    "population": r.population.summary() if r.population is not None else None,
                }
                for name, r in result.runs.items()
            },
            "supported": c.supported,
            "strength": c.strength,
            "decided_by": c.decided_by,
            "z": c.z,
            "rule": RULE,
        }
    doc["inputs"] = [
        {
            "source": g.source,
            "log": g.log,
            "unit_id": g.unit_id,
            "status": "ok" if g.observations is not None else g.reason,
            "heard_s": g.heard_s,
            "sound_share": g.sound_share,
            "episodes": g.episodes,
            "points": None if g.observations is None else int(g.observations.frames.size),
            "frames": None if g.observations is None else int(g.observations.frames.sum()),
        }
        for g in result.gathered
    ]
    extra = dict(context)
    timing = {
        "wall_s": result.wall_s,
        "unit_s": {u.unit_id: u.posterior.seconds for u in run.units if u.posterior is not None},
        **extra.pop("run", {}),
    }
    doc["settings"] = {
        **result.settings.as_dict(),
        "reported_formulation": result.chosen,
        **extra,
        "package_version": __version__,
        "run": timing,
    }
    return json_safe(doc)


def _interval(s: dict[str, float]) -> str:
    return f"{s['mean']:.4g} [{s['q05']:.4g}, {s['q95']:.4g}]"


def _score(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def _sd(name: str, sd: float) -> str:
    """A `scatter.*` SD as it means it: of ln for a log-normal name, else relative."""
    if name in LOG_NORMAL:
        return f"SD of ln {sd:.3g}"
    return f"SD {sd:.3g} rel."


# Why calibrated.yaml differs from the population printed (and the page says the same)
PREDICTIVE = (
    f"{YAML_FILE}: a new unit's predictive distribution, not the population above: the centre "
    "and spread averaged over their uncertainty (SD^2 = mean SD^2 + variance of the mean), "
    "as the node draws units from its nominal values and scatter.*"
)


def _identified(u: UnitResult) -> str:
    """A unit's identifiability on its line: r(drop, damping) and the names learned from the
    prior alone ('' when it learned nothing)."""
    ident = u.identifiability()
    if ident is None:
        return ""
    r = ident["drop_damping_correlation"]
    alone = ident["prior_alone"]
    return ("" if r is None else f"  r {r:+.2f}") + (
        f"  prior alone: {', '.join(alone)}" if alone else ""
    )


def text(result: CalibrationResult, out: Path | None = None) -> str:
    """calibration.txt: the run on one screen (no final newline).

    Parameters
    ----------
    result : CalibrationResult
        The run.
    out : Path, optional
        The output directory (named in the last line).

    Returns
    -------
    str
    """
    run = result.run
    units = run.units
    by_status: dict[str, int] = {}
    for u in units:
        key = u.status.split(":")[0].split(" (")[0]
        by_status[key] = by_status.get(key, 0) + 1
    prior = run.prior
    lines = [
        f"calibration of {len(units)} units from {len(result.gathered)} inputs "
        f"({len(result.unusable)} without observations), formulation {run.formulation}, "
        f"{len(run.held_out.units)} units held out; parameters "
        f"{', '.join(result.settings.names)}",
        "units: " + ", ".join(f"{n} {k}" for k, n in sorted(by_status.items())),
    ]
    pop = run.population
    if pop is None:
        lines.append(f"population: {run.population_status}")
    else:
        summary = pop.summary()
        scatter = dict(prior.scatter)
        lines.append(
            f"fleet population ({run.population_status}): mean [90 %], SD [90 %] vs the prior"
        )
        for name, s in summary.items():
            p0 = getattr(prior.params, name, None)
            shown = "" if p0 is None else f"   prior {p0:.4g}, {_sd(name, scatter.get(name, 0.0))}"
            lines.append(f"  {name:<20} {_interval(s['mean'])}  SD {_interval(s['sd'])}{shown}")
    written = _calibrated(run)
    if written is not None:
        lines.append(PREDICTIVE + ":")
        lines.append(
            "  "
            + ", ".join(
                f"{n} {v:.4g} ({_sd(n, written['scatter'][n])})"
                for n, v in written["params"].items()
            )
        )
        lines += [f"  clipped: {note}" for note in written["notes"]]
    if run.hearing is not None:
        g = result.settings.hearing.summary(run.hearing)
        lines.append(
            "bench hearing (the observation model's grid, from the units of the population; "
            "prior mean +- SD): "
            + "; ".join(
                f"{label} {v['mean']:.0f} dB [{v['q05']:.0f}, {v['q95']:.0f}] "
                f"(prior {v['prior_mean']:.0f} +- {v['prior_sd']:.0f})"
                for label, v in (
                    ("detection threshold over the floor", g["threshold_db"]),
                    ("limit cycle over the floor", g["depth_db"]),
                )
            )
        )
    h = run.held_out
    lines.append(
        f"held-out check ({len(h.units)} units, {h.frames} frames): Brier score prior "
        f"{_score(h.brier_prior)}, calibrated {_score(h.brier_calibrated)}"
    )
    m_prior, m_cal = h.frequency_match
    if m_prior is not None and m_cal is not None:
        lines.append(
            f"  frequency match of the held-out units' heard frames: prior {m_prior:.3f}, "
            f"calibrated {m_cal:.3f}"
        )
    heard_off, off = h.background
    if off:
        lines.append(
            f"  heard with the motor off (the detector's own false alarms): {heard_off} of "
            f"{off} frames ({100 * heard_off / off:.1f} %)"
        )
    lines += [f"  warning: {w}" for w in h.warnings()]
    c = result.comparison
    if c is not None:
        scores = "; ".join(
            f"{k}: held-out Brier {_score(r.score)}, frequency match {_score(r.frequency_match)}"
            f", growth-rate match {_score(r.growth_match)}"
            for k, r in result.runs.items()
        )
        lines.append(
            f"formulations: {c.supported or 'none'} supported {c.strength}"
            + (f" by the {c.decided_by}" if c.decided_by else "")
            + (f" (held-out z = {c.z:.1f})" if c.z is not None else "")
            + f"; {scores}"
        )
        for name, other in result.runs.items():
            stuck = sum(u.status.startswith("not converged") for u in other.units)
            if name != result.chosen and not other.converged:
                lines.append(
                    f"{name}: {stuck} units not converged; population: {other.population_status}"
                    + (
                        " (not the supported formulation: reported, not an error)"
                        if c.supported is not None
                        else ""
                    )
                )
    part = [
        (g.name, g.sound_share)
        for g in result.gathered
        if g.sound_share is not None and g.sound_share < FULL_SHARE
    ]
    if part:
        lines.append(
            f"{len(part)} inputs heard in part only: "
            + ", ".join(f"{name} {100 * share:.0f} %" for name, share in part[:_LISTED])
            + (f", ... ({len(part) - _LISTED} more in {JSON_FILE})" if len(part) > _LISTED else "")
        )
    listed = [u for u in units if u.reported is not None][:_LISTED]
    if listed:
        names = set(result.settings.names)
        r = (
            f"; r: posterior correlation of {DROP} and {DAMPING}"
            if DAMPING in names and {"mu_static", "mu_kinetic"} & names
            else ""
        )
        lines.append(
            f"per unit, {DROP} mean [90 %]{r}; prior alone: its own posterior SD at "
            f"{PRIOR_ALONE_SD_RATIO:.2f} of the prior's or more (less information in the "
            "data than in the prior):"
        )
        for u in listed:
            post = u.reported
            assert post is not None
            own = post.summary().get(DROP)
            drop = _interval(own) if own else "n/a"
            flag = " (held out)" if u.held_out else ""
            state = "" if u.calibrated else f"  {u.status}"
            lines.append(f"  {u.unit_id:<20} {drop}{flag}{_identified(u)}{state}")
    rest = [u for u in units if u.reported is None]
    for u in rest[:_LISTED]:
        lines.append(f"  {u.unit_id:<20} {u.status}")
    more = len(units) - len(listed) - min(len(rest), _LISTED)
    if more > 0:
        lines.append(f"  ... {more} more units in {JSON_FILE}")
    where = f"{out}/" if out is not None else ""
    lines.append(
        f"wrote {where}{JSON_FILE}, {TEXT_FILE}, {PNG_FILE}"
        + (f", {YAML_FILE}" if run.params is not None else f" (no {YAML_FILE}: no population)")
        + f" ({result.wall_s:.1f} s)"
    )
    return "\n".join(lines)


def _listed(items: list[str]) -> list[str]:
    shown = [f"#   {x}" for x in items[:_LISTED]]
    if len(items) > _LISTED:
        shown.append(f"#   ... and {len(items) - _LISTED} more")
    return shown


def calibrated_yaml(result: CalibrationResult, date: str) -> str:
    """calibrated.yaml: every model parameter and `scatter.*` of the calibrated population,
    keyed `/**:` under `ros__parameters:`, with a comment header (package version, date,
    logs, units, population, held-out check).

    Parameters
    ----------
    result : CalibrationResult
        A run with a population (`result.run.params`).
    date : str
        When it was made (UTC, ISO 8601).

    Returns
    -------
    str
    """
    run = result.run
    params, scatter = run.params, run.scatter
    assert params is not None and scatter is not None  # only with a population
    used = [u for u in run.units if u.hierarchical is not None]
    logs = [log for u in used for log in u.logs]
    h = run.held_out
    header = [
        f"# Calibrated by `leadscrew-squeak calibrate` (leadscrew_ros {__version__}) on {date}:",
        f"# the fleet population of {', '.join(result.settings.names)} from {len(logs)} logs of "
        f"{len(used)} units (formulation {run.formulation}"
        + (
            f", supported {result.comparison.strength}"
            if result.comparison is not None and result.comparison.supported
            else ""
        )
        + f"); held-out check on {len(h.units)} units: Brier score prior "
        f"{_score(h.brier_prior)}, calibrated {_score(h.brier_calibrated)}.",
        "# Nominal values are the population's predictive centre, scatter.* its predictive",
        "# spread (a new unit's distribution: the population's centre and unit-to-unit SD",
        "# averaged over their uncertainty, so not calibration.txt's population mean and SD;",
        "# the prior's for the parameters not calibrated).",
        *[f"# Clipped to the valid ranges: {note}." for note in run.notes],
        "# Keyed `/**:` as config/leadscrew.yaml: for the node in any namespace (squeak_node",
        "# --ros-args --params-file calibrated.yaml) and for --params-file of predict, replay",
        "# and review.",
        "# units:",
        *_listed([u.unit_id for u in used]),
        "# logs:",
        *_listed(logs),
    ]
    lines = ["/**:", "  ros__parameters:"]
    lines += [f"    {k}: {yaml_value(v)}" for k, v in params.as_dict().items()]
    lines.append("    scatter:")
    sd = dict(scatter.sd)
    lines += [f"      {name}: {yaml_value(float(sd.get(name, 0.0)))}" for name in scatterable()]
    lines.append(f"      samples: {yaml_value(run.prior.samples)}")
    return "\n".join(header + lines) + "\n"


def write(
    result: CalibrationResult, out: Path, context: dict[str, Any], plot: bool = True
) -> list[Path]:
    """Write the module's files into `out` (created if needed).

    Parameters
    ----------
    result : CalibrationResult
        The run.
    out : Path
        The output directory.
    context : dict
        For calibration.json's settings (`document`).
    plot : bool
        Write calibration.png (False: an earlier one is removed).

    Returns
    -------
    list of Path
        The files written.
    """
    out.mkdir(parents=True, exist_ok=True)
    date = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()
    context = {**context, "run": {**context.get("run", {}), "date": date}}
    paths = [out / JSON_FILE, out / TEXT_FILE]
    paths[0].write_text(
        json.dumps(document(result, context), indent=1, allow_nan=False) + "\n",
        encoding="utf-8",
    )
    paths[1].write_text(text(result, out) + "\n", encoding="utf-8")
    # files of an earlier run into `out` that this one does not write go: never stale
    for name, keep in ((PNG_FILE, plot), (YAML_FILE, result.run.params is not None)):
        if keep:
            paths.append(out / name)
        else:
            (out / name).unlink(missing_ok=True)
    if plot:
        result.plot().savefig(out / PNG_FILE, dpi=100)
    if result.run.params is not None:
        (out / YAML_FILE).write_text(calibrated_yaml(result, date), encoding="utf-8")
    return paths
