# SPDX-License-Identifier: Apache-2.0
"""Numbers for doc/user/calibration.md: a virtual-bench fleet that the prior does not describe,
calibrated, the calibrated params file at one operating point, and the same fleet calibrated
with both formulations.

    .venv/bin/python tools/calibration_example.py [--keep DIR]

Makes the bench of `BENCH` (`leadscrew-squeak bench`, `bench_command`) and calibrates it
(`leadscrew-squeak calibrate BENCH --out OUT` with `CALIBRATE`) in a temp directory (or DIR),
then prints the page's Markdown between its `calibration_example` markers from what the run
wrote (calibration.json, calibration.txt, calibrated.yaml) and the truth; then calibrates the
bench again with `BOTH` and prints the Markdown between its `calibration_formulations`
markers. test_calibrate runs the first bench and calibration (its fleet fixture uses `make`)
and checks the page shows `markdown` of them; the second is this tool's only.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from leadscrew_ros.bag.virtual_bench import BenchSettings, run
from leadscrew_ros.cli import main as cli
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.calibration import AmplitudeLikelihood, GrowthLikelihood, Prior
from leadscrew_ros.model.calibration.posterior import PRIOR_ALONE_SD_RATIO
from leadscrew_ros.model.uncertainty.scatter import LOG_NORMAL, Scatter, draw
from leadscrew_ros.review.calibration.gather import observe_replay
from leadscrew_ros.review.plots import plot_amplitude

ROOT = Path(__file__).resolve().parents[1]

POPULATION = {"mu_static": 0.27, "mu_kinetic": 0.19, "modal_damping": 0.002}
# the realistic bench (`--realistic`): the squeak grows from its floor by the amplitude
# equation, with harmonics, a geared motor, a fan, mains hum and a room
BENCH = BenchSettings(units=16, seed=11, population=POPULATION, realistic=True)
FIGURE = ROOT / "doc" / "images" / "calibration_amplitude.png"
CALIBRATE = ["--workers", "2"]
BOTH = ["--formulation", "both", "--workers", "2"]
SPEED, LOAD = 60.0, 200.0  # the operating point of the last line: near the prior's band edge
DROP = "friction_drop"


def bench_command(out: str = "bench") -> str:
    """The `bench` command line of `BENCH`."""
    population = " ".join(f"--population {k}={v:g}" for k, v in BENCH.population.items())
    return (
        f"leadscrew-squeak bench --units {BENCH.units} --formulation {BENCH.formulation} "
        f"--seed {BENCH.seed} {population} --realistic --out {out}"
    )


def make(tmp: Path) -> tuple[dict[str, Any], Path, int]:
    """The bench and its calibration in `tmp`: (truth, output directory, exit status)."""
    truth = run(BENCH, tmp / "bench")
    out = tmp / "calibration"
    code = cli(["calibrate", str(tmp / "bench"), "--out", str(out), *CALIBRATE, "--quiet"])
    return truth, out, code


def make_both(tmp: Path) -> tuple[Path, int]:
    """The bench of `make` in `tmp` calibrated with both formulations: (output directory,
    exit status)."""
    out = tmp / "both"
    return out, cli(["calibrate", str(tmp / "bench"), "--out", str(out), *BOTH, "--quiet"])


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def _interval(s: dict[str, float]) -> str:
    return f"{_fmt(s['mean'])} [{_fmt(s['q05'])}, {_fmt(s['q95'])}]"


def _spread(name: str, params: dict[str, Any], scatter: dict[str, float]) -> str:
    """A population's nominal value and SD as the scatter means it."""
    sd = scatter.get(name, 0.0)
    if name in LOG_NORMAL:
        return f"{_fmt(params[name])} (SD of ln {sd:.3g})"
    return f"{_fmt(params[name])} (SD {_fmt(sd * params[name])})"


def _drops(params: dict[str, Any], scatter: dict[str, float]) -> np.ndarray:
    values = draw(ScrewParameters(**params), Scatter(scatter), 8192).values
    return values["mu_static"] - values["mu_kinetic"]


def _drop(params: dict[str, Any], scatter: dict[str, float]) -> str:
    d = _drops(params, scatter)
    q05, q95 = np.quantile(d, [0.05, 0.95])
    return f"{_fmt(float(d.mean()))} (90 % of units {_fmt(q05)}-{_fmt(q95)})"


def widths(doc: dict[str, Any]) -> tuple[float, float, float]:
    """The 90 % width of the fleet mean's drop, and its ratios to the prior's 90 % width of a
    unit's drop and to the hierarchical prior's of the fleet mean (the population centre's
    hyper-prior: the prior's SDs widened by prior_widen)."""
    mean = doc["population"][DROP]["mean"]
    width = mean["q95"] - mean["q05"]
    prior = doc["settings"]["prior"]
    p, s = prior["params"], prior["scatter"]
    q05, q95 = np.quantile(_drops(p, s), [0.05, 0.95])
    hyper = doc["settings"]["sampler"]["prior_widen"] * np.hypot(
        p["mu_static"] * s["mu_static"], p["mu_kinetic"] * s["mu_kinetic"]
    )
    return width, width / (q95 - q05), width / (2 * 1.6448536269514722 * hyper)


def markdown(truth: dict[str, Any], out: Path, code: int) -> str:
    """The page's Markdown from a run's outputs and the bench's truth."""
    doc = json.loads((out / "calibration.json").read_text())
    text = (out / "calibration.txt").read_text().splitlines()
    values = yaml.safe_load((out / "calibrated.yaml").read_text())["/**"]["ros__parameters"]
    prior = doc["settings"]["prior"]
    names = doc["settings"]["names"]
    rows = []
    for name in [*names, DROP]:
        pop = doc["population"][name]
        if name == DROP:
            true, before = (
                _drop(truth["nominal"], truth["scatter"]),
                _drop(prior["params"], prior["scatter"]),
            )
        else:
            true = _spread(name, truth["nominal"], truth["scatter"])
            before = _spread(name, prior["params"], prior["scatter"])
        rows.append(
            f"| {name} | {true} | {before} | {_interval(pop['mean'])} | {_interval(pop['sd'])} |"
        )
    drops = {
        u["unit_id"]: u["params"]["mu_static"] - u["params"]["mu_kinetic"] for u in truth["units"]
    }
    covered = sum(
        u["posterior"][DROP]["q05"] <= drops[u["unit_id"]] <= u["posterior"][DROP]["q95"]
        for u in doc["units"]
    )
    posts = [(u["posterior"][DROP], drops[u["unit_id"]]) for u in doc["units"]]
    above = sum(post["mean"] > true for post, true in posts)
    z = float(np.mean([(true - post["mean"]) / post["sd"] for post, true in posts]))
    h = doc["held_out"]
    calibrated = SqueakModel(
        ScrewParameters(**{k: v for k, v in values.items() if k != "scatter"}),
        Scatter({k: v for k, v in values["scatter"].items() if k != "samples"}),
        values["scatter"]["samples"],
    )
    before = SqueakModel(ScrewParameters(**prior["params"]), Scatter(prior["scatter"]))
    p_prior = before.predict(SPEED, LOAD).probability
    p_cal = calibrated.predict(SPEED, LOAD).probability
    # what each unit's own data identified (calibration.json's `identifiability`)
    idents = [u["identifiability"] for u in doc["units"] if u["identifiability"] is not None]
    alone = {n: sum(n in i["prior_alone"] for i in idents) for n in [*names, DROP]}
    r = [i["drop_damping_correlation"] for i in idents]
    identified = ", ".join(f"{n} {k}" for n, k in alone.items())
    # up to the per-unit lines (the rest: units, paths and the wall time)
    shown = text[: next((k for k, line in enumerate(text) if line.startswith("per unit")), -1)]
    width, to_unit, to_hyper = widths(doc)
    return "\n".join(
        [
            f"The bench draws its units from mu_static {_fmt(truth['nominal']['mu_static'])}, "
            f"mu_kinetic {_fmt(truth['nominal']['mu_kinetic'])} and modal_damping "
            f"{_fmt(truth['nominal']['modal_damping'])} with the default scatter "
            f"(truth.json's `nominal` and `scatter`); its logs carry the package's nominal "
            f"values (the prior).",
            "",
            "| parameter | fleet (truth) | prior | calibrated fleet mean [90 %] | "
            "calibrated fleet SD [90 %] |",
            "|---|---|---|---|---|",
            *rows,
            "",
            f"Per unit, the 90 % interval of the friction drop covers the unit's own drop "
            f"(truth.json) in {covered} of {len(doc['units'])} units. The fleet mean's 90 % "
            f"interval of the drop is {_fmt(width)} wide: {to_unit:.2f} of the prior's 90 % "
            f"interval of a unit's drop, {to_hyper:.2f} of the hierarchical model's prior of "
            f"the fleet mean (the population centre's hyper-prior). The held-out check "
            f"({len(h['units'])} units, {h['frames']} frames): Brier score "
            f"{h['brier_prior']:.4f} with the prior, {h['brier_calibrated']:.4f} with the "
            f"calibrated fleet. Exit status {code}.",
            "",
            f"The units' posterior means of the drop lie above their own drops in {above} of "
            f"{len(posts)} units (mean of (truth - mean) / SD: {z:+.2f}).",
            "",
            f"What the units' own data identified (`identifiability`, on each unit's line of "
            f"calibration.txt): of the {len(idents)} units, learned from the prior alone "
            f"(posterior SD at {PRIOR_ALONE_SD_RATIO:.2f} of the prior's or more): "
            f"{identified}. The posterior correlation of the drop and the damping is "
            f"{min(r):+.2f} to {max(r):+.2f} (median {float(np.median(r)):+.2f})"
            + (
                ": the frames fix the drop mu_s - mu_k, not mu_s and mu_k each."
                if alone[DROP] == 0 and alone["mu_static"] and alone["mu_kinetic"]
                else "."
            ),
            "",
            "calibration.txt begins:",
            "",
            "```text",
            *shown,
            "```",
            "",
            f"At {SPEED:g} rad/s and {LOAD:g} N, `squeak/risk` (P(squeak), the node's live "
            f"estimate, = predict's `probability_live`) is {p_prior:.4f} with the prior and "
            f"{p_cal:.4f} with calibrated.yaml.",
        ]
    )


def figure(out: Path, unit: int = 0, path: Path = FIGURE) -> Path:
    """doc/images/calibration_amplitude.png: one unit's heard frames with the model's
    amplitude at its posterior mean and the bench's grid posterior (`plots.plot_amplitude`)."""
    doc = json.loads((out / "calibration.json").read_text())
    replay = sorted((out / "replays").iterdir())[unit]
    obs = observe_replay(replay).observations
    assert obs is not None, replay
    entry = next(u for u in doc["units"] if u["unit_id"] == obs.unit_id)
    prior = doc["settings"]["prior"]
    names = tuple(doc["settings"]["names"])
    model = SqueakModel(ScrewParameters(**prior["params"]), Scatter(prior["scatter"]))
    reach = Prior(model.params, model.scatter, names).widened(
        doc["settings"]["sampler"]["prior_widen"]
    )
    theta = np.array([entry["posterior"][n]["mean"] for n in names])
    centre = SqueakModel(
        model.params.with_(**dict(zip(names, theta.tolist(), strict=True))), model.scatter
    )
    likelihood = AmplitudeLikelihood(GrowthLikelihood(centre, obs, names, reach=reach))
    grid = doc["hearing"]["log_posterior"]
    weight = np.array([[-np.inf if v is None else v for v in row] for row in grid])
    fig = plot_amplitude(likelihood, theta, weight)
    fig.savefig(path, dpi=110)
    return path


def formulations(out: Path, code: int) -> str:
    """The Markdown of the calibration with both formulations (`make_both`)."""
    doc = json.loads((out / "calibration.json").read_text())
    f = doc["formulations"]
    rows = [
        f"| {name} | {f[name]['frequency_match']:.3f} | {f[name]['score']:.4f} | "
        f"{f[name]['brier_prior']:.4f} | {_interval(f[name]['population'][DROP]['mean'])} |"
        for name in ("paper", "consistent")
    ]
    return "\n".join(
        [
            "| formulation | frequency match | held-out Brier, calibrated | held-out Brier, prior "
            "| fleet mean friction drop [90 %] |",
            "|---|---:|---:|---:|---|",
            *rows,
            "",
            f"{f['supported']} supported {f['strength']} by the {f['decided_by']}"
            + (f" (held-out z = {f['z']:.1f})" if f["z"] is not None else "")
            + f"; exit status {code}. The rule: {f['rule']}.",
        ]
    )


def example(tmp: Path) -> tuple[str, str]:
    """The page's two blocks (the bench and the calibrations made in `tmp`)."""
    truth, out, code = make(tmp)
    first = markdown(truth, out, code)
    figure(out)
    return first, formulations(*make_both(tmp))


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args[:1] == ["--keep"] and len(args) == 2:  # the runs kept, for `markdown` again
        keep = Path(args[1])
        keep.mkdir(parents=True, exist_ok=True)
        first, second = example(keep)
    else:
        with tempfile.TemporaryDirectory(prefix="calibration_example_") as tmp:
            first, second = example(Path(tmp))
    print(f"% calibration_example: begin\n{first}\n% calibration_example: end\n")
    print(f"% calibration_formulations: begin\n{second}\n% calibration_formulations: end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
