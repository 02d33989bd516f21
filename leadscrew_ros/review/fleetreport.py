# SPDX-License-Identifier: Apache-2.0
"""The fleet review's report: fleet.csv (one row per log), fleet.json (the same rows and the
run's parameters) and fleet.png (share of logs that squeak, squeak frequencies, time in squeak
per log, where in speed x load the fleet squeaked: `plots.plot_fleet`).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from .fleet import FleetRun
from .jsonsafe import json_safe
from .plots import plot_fleet

CSV_FILE, JSON_FILE, PNG_FILE = "fleet.csv", "fleet.json", "fleet.png"
COLUMNS = [
    "log",
    "unit_id",
    "status",
    "error",
    "note",
    "duration_s",
    "time_in_squeak_s",
    "squeak_share",
    "episodes",
    "peak_growth_rate",
    "squeak_frequencies_hz",
    "peak_probability",
    "time_above_warn_s",
    "time_above_error_s",
    "heard_status",
    "sound_share",
    "heard_s",
    "recall",
    "precision",
    "brier",
    "heard_frequencies_hz",
    "messages",
    "predictions",
    "formulation",
    "name",
    "wall_s",
]


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
    doc = {
        "parameters": parameters,
        "logs": len(run.rows),
        "ok": len(run.rows) - run.failed,
        "errors": run.failed,
        "reviewed": run.reviewed,
        "skipped": run.skipped,
        "wall_s": run.wall_s,
        "rows": [{c: row.get(c) for c in COLUMNS} for row in run.rows],
    }
    paths[1].write_text(
        json.dumps(json_safe(doc), indent=1, allow_nan=False) + "\n", encoding="utf-8"
    )
    plot_fleet(run).savefig(paths[2], dpi=100)
    return paths
