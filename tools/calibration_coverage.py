# SPDX-License-Identifier: Apache-2.0
"""Does the calibration find the truth? Realistic benches made from populations unlike the
prior, each calibrated with both formulations: per calibrated name, how many units' reported
90 % intervals cover their own value, the fleet mean [90 %] against the units' mean and the
population's, the held-out Brier scores and the formulation picked.

    .venv/bin/python tools/calibration_coverage.py [--keep DIR] [NAME ...]
    .venv/bin/python tools/calibration_coverage.py [--keep DIR] --seeds SEED [SEED ...]

NAME picks rows of `BENCHES` (all by default). Each row runs `leadscrew-squeak bench` and
`leadscrew-squeak calibrate --formulation both` (minutes per row on 2 cores) and prints one
Markdown table; the truth stays in the bench's truth.json. The numbers of issue 31's closing
note and of doc/user/calibration.md's "Coverage on other benches" come from this tool.

With `--seeds`, the documentation example's bench (`calibration_example.BENCH`) is made once
and calibrated as the example is, once per sampler seed (`--seed`): one row per seed, the
coverage of each name and the fleet mean damping. The spread over the seeds is what the
sampling adds to one calibration's coverage (doc/user/calibration.md, "Over the sampler's
seeds").
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from calibration_example import BENCH, CALIBRATE, widths  # tools/: the doc's example
from leadscrew_ros.bag.virtual_bench import run
from leadscrew_ros.cli import main as cli

NAMES = ("friction_drop", "mu_static", "mu_kinetic", "friction_decay_s_m", "modal_damping")
# name: (bench options, the formulation that made it); populations unlike the prior
# (Table 1: mu_static 0.25, mu_kinetic 0.2, damping 0.003), seeds other than the example's
BENCHES: dict[str, tuple[list[str], str]] = {
    "paper, 12-s strokes": (
        ["--formulation", "paper", "--seed", "31", "--population", "mu_static=0.27",
         "--population", "mu_kinetic=0.185", "--population", "modal_damping=0.0022"],
        "paper",
    ),
    "consistent, 12-s strokes": (
        ["--formulation", "consistent", "--seed", "23", "--population", "mu_static=0.26",
         "--population", "mu_kinetic=0.175", "--population", "modal_damping=0.0025"],
        "consistent",
    ),
    "paper, 30-s strokes (slow band-edge crossings)": (
        ["--formulation", "paper", "--seed", "5", "--duration", "30", "--population",
         "mu_static=0.28", "--population", "mu_kinetic=0.2", "--population",
         "modal_damping=0.0018"],
        "paper",
    ),
}  # fmt: skip
UNITS = 16


def _value(params: dict[str, float], name: str) -> float:
    if name == "friction_drop":
        return params["mu_static"] - params["mu_kinetic"]
    return params[name]


def _population(truth: dict[str, Any], name: str) -> float:
    return _value(truth["nominal"], name)


def _covered(doc: dict[str, Any], truth: dict[str, Any], n: str) -> tuple[int, int, np.ndarray]:
    """(units whose reported 90 % interval of `n` covers their own value, the same of their
    own posteriors, those values) over the calibrated units of `doc`."""
    own = {u["unit_id"]: u["params"] for u in truth["units"]}
    units = [u for u in doc["units"] if u.get("posterior")]
    values = np.array([_value(own[u["unit_id"]], n) for u in units])
    cover = sum(
        u["posterior"][n]["q05"] <= v <= u["posterior"][n]["q95"]
        for u, v in zip(units, values, strict=True)
    )
    cover_own = sum(
        u["own"][n]["q05"] <= v <= u["own"][n]["q95"]
        for u, v in zip(units, values, strict=True)
        if u.get("own")
    )
    return cover, cover_own, values


def table(name: str, truth: dict[str, Any], out: Path, code: int, made_by: str) -> str:
    """One bench's Markdown: coverage and fleet mean per name, then the verdicts."""
    doc = json.loads((out / "calibration.json").read_text())
    units = [u for u in doc["units"] if u.get("posterior")]
    lines = [
        f"**{name}** ({len(units)} units, made with `{made_by}`; exit status {code})",
        "",
        "| parameter | units covered (own posterior) | prior alone | units' mean | population | "
        "fleet mean [90 %] |",
        "|---|---:|---:|---:|---:|---|",
    ]
    for n in NAMES:
        cover, cover_own, values = _covered(doc, truth, n)
        alone = sum(n in u["identifiability"]["prior_alone"] for u in units)
        m = doc["population"][n]["mean"]
        lines.append(
            f"| {n} | {cover} of {len(units)} ({cover_own}) | {alone} | {values.mean():.4g} | "
            f"{_population(truth, n):.4g} | {m['mean']:.4g} [{m['q05']:.4g}, {m['q95']:.4g}] |"
        )
    _, of_prior, _ = widths(doc)
    held = doc["held_out"]
    verdict = doc["formulations"]
    lines += [
        "",
        f"The fleet mean drop's 90 % interval is {of_prior:.2f} of the prior's 90 % interval "
        "of a unit's drop. "
        f"Held-out Brier score ({len(held['units'])} units): prior {held['brier_prior']:.3f}, "
        f"calibrated {held['brier_calibrated']:.3f}. Formulation picked: "
        f"`{verdict['supported']}` ({verdict['strength']}, by the {verdict['decided_by']}).",
    ]
    return "\n".join(lines)


def seed_table(truth: dict[str, Any], runs: list[tuple[int, Path, int]]) -> str:
    """The example bench calibrated once per sampler seed ((seed, output, exit status) each):
    a row per seed, the units covered per name (own posteriors in brackets)."""
    units = len(truth["units"])
    head = " | ".join(NAMES)
    lines = [
        f"| seed | exit | {head} | fleet mean damping [90 %] |",
        "|---:|---:|" + "---:|" * len(NAMES) + "---|",
    ]
    for seed, out, code in runs:
        doc = json.loads((out / "calibration.json").read_text())
        cells = []
        for n in NAMES:
            cover, cover_own, _ = _covered(doc, truth, n)
            cells.append(f"{cover} ({cover_own})")
        m = doc["population"]["modal_damping"]["mean"]
        lines.append(
            f"| {seed} | {code} | {' | '.join(cells)} | "
            f"{m['mean']:.4g} [{m['q05']:.4g}, {m['q95']:.4g}] |"
        )
    mean = np.exp(np.mean(np.log([u["params"]["modal_damping"] for u in truth["units"]])))
    lines += ["", f"Units covered of {units}; the units' geometric mean damping is {mean:.4g}."]
    return "\n".join(lines)


def seeds(root: Path, chosen: list[int]) -> str:
    """`seed_table` of the example's bench, made in `root` unless it is there already."""
    bench = root / "example"
    if not (bench / "truth.json").exists():
        run(BENCH, bench)
    runs = []
    for seed in chosen:
        out = root / f"seed{seed}"
        code = cli(["calibrate", str(bench), "--out", str(out), *CALIBRATE, "--seed", str(seed),
                    "--quiet"])  # fmt: skip
        runs.append((seed, out, code))
    return seed_table(json.loads((bench / "truth.json").read_text()), runs)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    keep = None
    if args[:1] == ["--keep"]:
        keep, args = Path(args[1]), args[2:]
    if args[:1] == ["--seeds"]:
        with tempfile.TemporaryDirectory() as tmp:
            print(seeds(keep or Path(tmp), [int(a) for a in args[1:]]))
        return 0
    picked = {n: BENCHES[n] for n in args} if args else BENCHES
    with tempfile.TemporaryDirectory() as tmp:
        root = keep or Path(tmp)
        for i, (name, (options, made_by)) in enumerate(picked.items()):
            bench, out = root / f"bench{i}", root / f"calibration{i}"
            if not (bench / "truth.json").exists():
                cli(["bench", "--units", str(UNITS), "--realistic", "--quiet", "--force",
                     "--out", str(bench), *options])  # fmt: skip
            code = cli(["calibrate", str(bench), "--out", str(out), "--formulation", "both",
                        "--workers", "2", "--quiet"])  # fmt: skip
            truth = json.loads((bench / "truth.json").read_text())
            print(table(name, truth, out, code, made_by), end="\n\n", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
