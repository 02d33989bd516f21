# SPDX-License-Identifier: Apache-2.0
"""The fleet review's report: fleet.csv (one row per log), fleet.json (the same rows and the
run's parameters) and fleet.png (share of logs that squeak, squeak frequencies, time in squeak
per log, where in speed x load the fleet squeaked).

matplotlib is imported where the figure is drawn (matplotlib.figure.Figure, no pyplot).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np

from .fleet import FleetRun
from .jsonsafe import json_safe

CSV_FILE, JSON_FILE, PNG_FILE = "fleet.csv", "fleet.json", "fleet.png"
COLUMNS = ["log", "unit_id", "status", "error", "note", "duration_s", "time_in_squeak_s",
           "squeak_share", "episodes", "peak_growth_rate", "squeak_frequencies_hz",
           "peak_probability", "time_above_warn_s", "time_above_error_s", "messages",
           "predictions", "formulation", "name", "wall_s"]
_NAMED_BARS = 40          # up to this many logs the time-in-squeak panel names each one


def _cell(value: Any) -> str:
    """A CSV cell: '' for none, lists joined by ';', floats as repr (exact round trip)."""
    if value is None:
        return ""
    if isinstance(value, list):
        return ";".join(_cell(v) for v in value)
    return repr(value) if isinstance(value, float) else str(value)


def write_fleet(run: FleetRun, out_dir: Path | str, parameters: dict[str, Any]) -> list[Path]:
    """Write fleet.csv, fleet.json and fleet.png of `run` into `out_dir`.

    Parameters
    ----------
    run : FleetRun
        The review's rows and squeak points.
    out_dir : path
        The review's output directory.
    parameters : dict
        The run's parameters for fleet.json (inputs, settings, cluster).

    Returns
    -------
    list of Path
        The files written.
    """
    out = Path(out_dir)
    paths = [out / CSV_FILE, out / JSON_FILE, out / PNG_FILE]
    with open(paths[0], "w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for row in run.rows:
            w.writerow([_cell(row.get(c)) for c in COLUMNS])
    doc = {"parameters": parameters, "logs": len(run.rows), "ok": len(run.rows) - run.failed,
           "errors": run.failed, "reviewed": run.reviewed, "skipped": run.skipped,
           "wall_s": run.wall_s, "rows": [{c: row.get(c) for c in COLUMNS} for row in run.rows]}
    paths[1].write_text(json.dumps(json_safe(doc), indent=1, allow_nan=False) + "\n",
                        encoding="utf-8")
    plot_fleet(run, paths[2])
    return paths


def plot_fleet(run: FleetRun, path: Path) -> None:
    """fleet.png: four panels of the fleet's squeak."""
    from matplotlib.figure import Figure

    ok = [r for r in run.rows if r["status"] == "ok"]
    squeaks = [r for r in ok if r["episodes"]]
    fig = Figure(figsize=(12, 8.5), layout="constrained")
    (a, b), (c, d) = fig.subplots(2, 2)
    counts = [len(squeaks), len(ok) - len(squeaks), run.failed]
    bars = a.bar(["squeak", "no squeak", "error"], counts, color=["C3", "C2", "0.6"])
    a.bar_label(bars, [f"{n} ({100 * n / max(len(run.rows), 1):.0f} %)" for n in counts])
    a.set_ylabel("logs")
    a.set_title(f"{len(squeaks)} of {len(ok)} reviewed logs squeak")
    pts = np.array(run.points, dtype=float).reshape(-1, 3)
    if len(pts):
        b.hist(pts[:, 2], bins=min(50, max(5, len(pts) // 20)), color="C3")
    b.set_xlabel("squeak frequency [Hz]")
    b.set_ylabel("predictions (sample)")
    b.set_title("squeak frequencies over the fleet")
    ranked = sorted(ok, key=lambda r: -r["time_in_squeak_s"])
    times = [r["time_in_squeak_s"] for r in ranked]
    if len(ranked) <= _NAMED_BARS:
        c.barh([r["unit_id"] for r in ranked][::-1], times[::-1], color="C3")
        c.tick_params(axis="y", labelsize=7)
    else:
        c.plot(np.arange(1, len(times) + 1), times, color="C3")
        c.set_xlabel("logs, ranked")
    c.set_title("time in squeak per log [s]")
    if len(pts):
        sc = d.scatter(np.abs(pts[:, 0]), np.abs(pts[:, 1]), c=pts[:, 2], s=6, cmap="viridis")
        fig.colorbar(sc, ax=d, label="squeak frequency [Hz]")
    d.set_xlabel(r"rotation speed $|\Omega|$ [rad/s]")
    d.set_ylabel("axial load $|F_z|$ [N]")
    d.set_title("where the fleet squeaked (sample of predictions)")
    fig.suptitle(f"fleet review: {len(run.rows)} logs, {run.failed} errors")
    fig.savefig(path, dpi=100)
