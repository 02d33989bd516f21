# SPDX-License-Identifier: Apache-2.0
"""PNG report of a replay: the run over time, and its trajectory on the stability maps.

- `timeline.png`: speed, load, nut position (only when the log has a nut input: a nut topic
  or joint positions) and P(squeak) over time, squeak at the nominal parameters shaded; the
  P(squeak) panel has the WARN and ERROR probabilities as dashed lines, bars under the curve
  where P was at or above them and the peak marked, with their numbers (exact, from the
  replay) in its title.
  Drawn from the replay's binned series (`decimation.Envelope`: min-max band per bin), so an
  hour-long log is as readable and as cheap as a minute;
- `map_speed_load.png`: the run's operating points (a fixed-size sample) on the speed-load
  stability map (the paper's Fig. 7), squeak predictions highlighted. When the nut travels
  (more than `NUT_BAND_MIN_M`), the points are split into 2-4 nut-position bands: the map is
  filled for the band holding the median nut position and the squeak boundary of every other
  band is overlaid in that band's colour, with its points in the same colour;
- `frequency_vs_speed.png`: the predicted squeak frequencies over the mode frequencies vs speed
  (the paper's Fig. 11), at the run's median nut position and load.

Maps use |speed| and |load| (a negative speed is the screw turning the other way).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..model import SqueakModel
from ..model.studies.stability_map import stability_map
from ..model.studies.sweep import sweep
from .plots import SQUEAK_COLOR, plot_frequencies, plot_map
from .replay import ReplayResult, attach

if TYPE_CHECKING:
    from matplotlib.axes import Axes

TIMELINE_FILE = "timeline.png"
MAP_FILE = "map_speed_load.png"
FREQUENCY_FILE = "frequency_vs_speed.png"
NUT_BAND_MIN_M = 0.01  # nut travel below this: one map at the median nut position
NUT_BAND_M = 0.025  # band width aimed at, 2 to 4 bands
BAND_COLORS = ("tab:blue", "tab:green", "tab:purple", "tab:brown")


@dataclass(frozen=True)
class ReportGrids:
    """Resolution of the replay report: map and sweep points, and the PNGs' dots per inch."""

    map_loads: int
    map_speeds: int
    sweep_speeds: int
    dpi: int


FULL = ReportGrids(map_loads=41, map_speeds=51, sweep_speeds=300, dpi=110)
QUICK = ReportGrids(map_loads=7, map_speeds=9, sweep_speeds=40, dpi=60)


def nut_bands(nuts: np.ndarray) -> np.ndarray:
    """Edges of the nut-position bands of a run: one band if the nut barely moves, else 2-4
    equal bands over its range."""
    if not nuts.size:
        return np.array([])
    lo, hi = float(nuts.min()), float(nuts.max())
    if hi - lo <= NUT_BAND_MIN_M:
        return np.array([lo, hi])
    n = int(np.clip(math.ceil((hi - lo) / NUT_BAND_M), 2, 4))
    return np.linspace(lo, hi, n + 1)


def write_report(
    result: ReplayResult, model: SqueakModel, out: Path | str, grids: ReportGrids = FULL
) -> list[Path]:
    """Write the three PNGs (the module's) into `out` and attach them to the annotated log,
    if it is there (`replay.attach`).

    Parameters
    ----------
    result : ReplayResult
        The replay.
    model : SqueakModel
        The model it was replayed with (the maps and the sweep).
    out : path
        An existing directory.
    grids : ReportGrids
        Map and sweep resolution, dots per inch.

    Returns
    -------
    list of Path
        timeline.png, map_speed_load.png, frequency_vs_speed.png.
    """
    out = Path(out)
    paths = [out / TIMELINE_FILE, out / MAP_FILE, out / FREQUENCY_FILE]
    result.plot().savefig(paths[0], dpi=grids.dpi)

    points = result.plot_data.points.sample()
    speed, load, nuts = np.abs(points[:, 0]), np.abs(points[:, 1]), points[:, 2]
    active = points[:, 3] > 0
    p = model.params
    median_nut = float(np.median(nuts)) if nuts.size else p.nut_position_m
    speed_hi = min(max(200.0, 1.1 * speed.max(initial=0.0)), 0.99 * model.critical_speed_rad_s)
    speeds = np.geomspace(p.min_speed_rad_s, speed_hi, grids.map_speeds)
    loads = np.linspace(0.0, max(600.0, 1.1 * load.max(initial=0.0)), grids.map_loads)

    edges = nut_bands(nuts)
    bands = len(edges) - 1
    band = np.clip(np.searchsorted(edges, nuts, side="right") - 1, 0, max(bands - 1, 0))
    home = int(np.clip(np.searchsorted(edges, median_nut, side="right") - 1, 0, max(bands - 1, 0)))

    def at_band(k: int) -> float:
        inside = nuts[band == k]
        return float(np.median(inside)) if inside.size else float(edges[k : k + 2].mean())

    map_nut = at_band(home) if bands > 1 else median_nut

    def band_text(k: int) -> str:
        return f"nut {edges[k] * 1e3:.0f}-{edges[k + 1] * 1e3:.0f} mm"

    def trajectory(ax: Axes) -> list:
        handles = []
        for k in range(max(bands, 1)):
            sel = band == k
            if not sel.any():
                continue
            color = "0.15" if bands <= 1 else BAND_COLORS[k]
            label = "replayed operating points" if bands <= 1 else band_text(k)
            handles += ax.plot(
                load[sel], speed[sel], ".", ms=2, color=color, alpha=0.6, label=label
            )
            if bands > 1 and k != home:
                other = stability_map(
                    model.with_params(nut_position_m=at_band(k)),
                    "load_n",
                    loads,
                    "speed_rad_s",
                    speeds,
                )
                g = np.nan_to_num(other.field.max_growth_rate, nan=-1.0)
                if g.min() < 0 < g.max():
                    ax.contour(loads, speeds, g, levels=[0.0], colors=[color], linewidths=1.4)
        if active.any():
            handles += ax.plot(
                load[active],
                speed[active],
                "o",
                ms=3,
                mfc=SQUEAK_COLOR,
                mec="k",
                mew=0.3,
                ls="none",
                label="squeak predicted",
            )
        return handles

    result_map = stability_map(
        model.with_params(nut_position_m=map_nut), "load_n", loads, "speed_rad_s", speeds
    )
    where = (
        f"nut at {map_nut * 1e3:.0f} mm (median of the run)"
        if bands <= 1
        else f"filled: {band_text(home)}; lines: squeak boundary of each other nut band"
    )
    plot_map(
        result_map,
        title=f"Replay on the stability map (Fig. 7 style), either sign of speed and load\n{where}",
        formulation=p.formulation,
        overlay=trajectory,
    ).savefig(paths[1], dpi=grids.dpi)

    squeak = result.plot_data.squeak.sample()

    def squeak_points(ax: Axes) -> list:
        if not squeak.size:
            return []
        return ax.plot(
            np.abs(squeak[:, 0]),
            squeak[:, 3],
            "o",
            ms=3,
            mfc=SQUEAK_COLOR,
            mec="k",
            mew=0.3,
            ls="none",
            label="replayed squeak predictions",
        )

    median_load = float(np.median(load)) if load.size else p.axial_load_n
    speed_sweep = sweep(
        model.with_params(nut_position_m=median_nut),
        "speed_rad_s",
        np.geomspace(p.min_speed_rad_s, speed_hi, grids.sweep_speeds),
        load_n=median_load,
    )
    plot_frequencies(
        speed_sweep,
        title=f"Replayed squeak frequencies on the modes vs speed "
        f"(Fig. 11 style)\nload {median_load:.0f} N, nut {median_nut * 1e3:.0f} mm "
        f"(medians of the run; points at their own load and nut)",
        overlay=squeak_points,
    ).savefig(paths[2], dpi=grids.dpi)
    if result.annotated.exists():  # unless the caller removed it (summaries only)
        attach(result, paths)
    return paths
