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

import numpy as np

from ..model import SqueakModel
from ..model.studies.stability_map import stability_map
from ..model.studies.sweep import sweep
from .plots import new_figure, plot_frequencies, plot_map
from .replay import ReplayResult, attach

TIMELINE_FILE = "timeline.png"
MAP_FILE = "map_speed_load.png"
FREQUENCY_FILE = "frequency_vs_speed.png"
SQUEAK_COLOR = "orange"
WARN_COLOR, ERROR_COLOR = "goldenrod", "tab:red"
BAR_HEIGHT = 0.07            # P(squeak) panel: the P >= WARN / ERROR bars under the curve
NUT_BAND_MIN_M = 0.01        # nut travel below this: one map at the median nut position
NUT_BAND_M = 0.025           # band width aimed at, 2 to 4 bands
BAND_COLORS = ("tab:blue", "tab:green", "tab:purple", "tab:brown")


@dataclass(frozen=True)
class ReportGrids:
    """Grid sizes and resolution of the report's figures."""

    map_loads: int
    map_speeds: int
    sweep_speeds: int
    dpi: int


FULL = ReportGrids(map_loads=41, map_speeds=51, sweep_speeds=300, dpi=110)
QUICK = ReportGrids(map_loads=7, map_speeds=9, sweep_speeds=40, dpi=60)


def _held(last: np.ndarray, count: np.ndarray) -> np.ndarray:
    """`last` with empty bins (count 0) holding the previous bin's value, as a published
    value holds until the next one."""
    idx = np.where(count > 0, np.arange(count.size), 0)
    np.maximum.accumulate(idx, out=idx)
    out = last[idx]
    out[: np.argmax(count > 0) if count.any() else count.size] = np.nan
    return out


def _filled(lo: np.ndarray, hi: np.ndarray, last: np.ndarray,
            count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A binned series' (lo, hi) with empty bins holding the last value before them (`_held`),
    so that a log sampled more sparsely than the bins is drawn as a line, not as dots."""
    held = _held(last, count)
    empty = count[:, None] == 0
    return np.where(empty, held, lo), np.fmax(np.where(empty, held, hi), held)


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True."""
    edges = np.diff(np.r_[0, flags.astype(np.int8), 0])
    return list(zip(np.flatnonzero(edges == 1).tolist(), (np.flatnonzero(edges == -1) - 1).tolist(), strict=True))


def _probability_panel(result: ReplayResult, axes) -> None:
    """P(squeak) over time on the last of `axes`, with the WARN and ERROR probabilities
    (dashed) and bars under the curve where P was at or above them; squeak at the nominal
    parameters shaded on all of `axes`."""
    ax = axes[-1]
    envelope = result.plot.probability
    t, lo, hi, last, count = envelope.series()
    lo, hi = _filled(lo, hi, last, count)
    half = envelope.bin_s / 2
    thresholds = ((result.warn_probability, "WARN", WARN_COLOR),
                  (result.error_probability, "ERROR", ERROR_COLOR))
    ylim = (-0.05 - BAR_HEIGHT * len(thresholds), 1.05)

    def fraction(y: float) -> float:             # of the axes' height
        return (y - ylim[0]) / (ylim[1] - ylim[0])

    handles = []
    if t.size:
        handles.append(ax.fill_between(t, lo[:, 0], hi[:, 0], step="mid", color="tab:blue",
                                       edgecolor="tab:blue", lw=0.8, label="P(squeak)"))
        for k, (a, b) in enumerate(_runs(np.nan_to_num(hi[:, 1]) > 0)):
            for other in axes:
                span = other.axvspan(t[a] - half, t[b] + half, color=SQUEAK_COLOR, alpha=0.3,
                                     lw=0, label="squeak (nominal)")
            handles += [span] if k == 0 else []
        for i, (level, name, color) in enumerate(thresholds):
            bottom = ylim[0] + BAR_HEIGHT * i
            for k, (a, b) in enumerate(_runs(np.nan_to_num(hi[:, 0], nan=-1.0) >= level)):
                span = ax.axvspan(t[a] - half, t[b] + half, fraction(bottom + 0.1 * BAR_HEIGHT),
                                  fraction(bottom + 0.9 * BAR_HEIGHT), color=color, lw=0,
                                  label=f"P >= {name}")
                handles += [span] if k == 0 else []
    for level, name, color in thresholds:
        handles.append(ax.axhline(level, color=color, ls="--", lw=1.0,
                                  label=f"{name} {level:g}"))
    pt = result.probability
    if pt.peak is not None:
        handles += ax.plot([pt.peak_t_s], [pt.peak], "v", color="k", ms=5, label="peak")
    ax.set_ylim(*ylim)
    ax.set_yticks([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    ax.set_ylabel("P(squeak)")
    ax.set_title(result.probability_text(), fontsize=9)
    ax.legend(handles=handles, loc="center left", bbox_to_anchor=(1.005, 0.5), fontsize=7)
    ax.set_xlabel("time since the log's first message [s]")


def plot_timeline(result: ReplayResult, path: Path, grids: ReportGrids) -> None:
    """Draw the inputs and P(squeak) over the log's time to `path`."""
    tl = result.timeline
    t, lo, hi, last, count = tl.trace.series()
    lo, hi = _filled(lo, hi, last, count)         # an input value holds until the next
    panels = [(0, "speed [rad/s]", 1.0), (1, "axial load [N]", 1.0)]
    if tl.nut_measured:
        panels.append((2, "nut position [mm]", 1e3))
    fig = new_figure(figsize=(10, 2.1 * (len(panels) + 1) + 0.2), layout="constrained")
    axes = fig.subplots(len(panels) + 1, 1, sharex=True)
    for ax, (k, label, factor) in zip(axes, panels, strict=False):
        ax.fill_between(t, lo[:, k] * factor, hi[:, k] * factor, step="mid", color="tab:blue",
                        edgecolor="tab:blue", lw=0.7)
        ax.set_ylabel(label)
    _probability_panel(result, axes)
    for ax in axes:
        ax.grid(alpha=0.3)
    nut = "" if tl.nut_measured else (
        f"; no nut input: model nut at {tl.nut * 1e3:.0f} mm (parameter nut_position_m)")
    axes[0].set_title(f"Replay of {result.log.name}: {result.episode_count} squeak episodes "
                      f"(shaded), {result.time_in_squeak_s:.1f} s in squeak{nut}", fontsize=10)
    fig.savefig(path, dpi=grids.dpi)


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


def write_report(result: ReplayResult, model: SqueakModel, out: Path | str,
                 grids: ReportGrids = FULL) -> list[Path]:
    """Write the three PNGs into `out` and attach them to the annotated log, if it is there
    (`replay.attach`); returns their paths."""
    out = Path(out)
    paths = [out / TIMELINE_FILE, out / MAP_FILE, out / FREQUENCY_FILE]
    plot_timeline(result, paths[0], grids)

    points = result.plot.points.sample()
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
    home = int(np.clip(np.searchsorted(edges, median_nut, side="right") - 1, 0,
                       max(bands - 1, 0)))

    def at_band(k: int) -> float:
        inside = nuts[band == k]
        return float(np.median(inside)) if inside.size else float(edges[k:k + 2].mean())

    map_nut = at_band(home) if bands > 1 else median_nut

    def band_text(k: int) -> str:
        return f"nut {edges[k] * 1e3:.0f}-{edges[k + 1] * 1e3:.0f} mm"

    def trajectory(ax) -> list:
        handles = []
        for k in range(max(bands, 1)):
            sel = band == k
            if not sel.any():
                continue
            color = "0.15" if bands <= 1 else BAND_COLORS[k]
            label = "replayed operating points" if bands <= 1 else band_text(k)
            handles += ax.plot(load[sel], speed[sel], ".", ms=2, color=color, alpha=0.6,
                               label=label)
            if bands > 1 and k != home:
                other = stability_map(model.with_params(nut_position_m=at_band(k)), "load_n",
                                      loads, "speed_rad_s", speeds)
                g = np.nan_to_num(other.field.max_growth_rate, nan=-1.0)
                if g.min() < 0 < g.max():
                    ax.contour(loads, speeds, g, levels=[0.0], colors=[color], linewidths=1.4)
        if active.any():
            handles += ax.plot(load[active], speed[active], "o", ms=3, mfc=SQUEAK_COLOR,
                               mec="k", mew=0.3, ls="none", label="squeak predicted")
        return handles

    result_map = stability_map(model.with_params(nut_position_m=map_nut), "load_n", loads,
                               "speed_rad_s", speeds)
    where = (f"nut at {map_nut * 1e3:.0f} mm (median of the run)" if bands <= 1 else
             f"filled: {band_text(home)}; lines: squeak boundary of each other nut band")
    plot_map(result_map, paths[1], f"Replay on the speed-load stability map (Fig. 7 style)\n"
             f"{where}; |speed|, |load|", grids.dpi, p.formulation, overlay=trajectory)

    squeak = result.plot.squeak.sample()

    def squeak_points(ax) -> list:
        if not squeak.size:
            return []
        return ax.plot(np.abs(squeak[:, 0]), squeak[:, 3], "o", ms=3, mfc=SQUEAK_COLOR,
                       mec="k", mew=0.3, ls="none", label="replayed squeak predictions")

    median_load = float(np.median(load)) if load.size else p.axial_load_n
    speed_sweep = sweep(model.with_params(nut_position_m=median_nut), "speed_rad_s",
                        np.geomspace(p.min_speed_rad_s, speed_hi, grids.sweep_speeds),
                        load_n=median_load)
    plot_frequencies(speed_sweep, paths[2], f"Replayed squeak frequencies on the modes vs speed "
                     f"(Fig. 11 style)\nload {median_load:.0f} N, nut {median_nut * 1e3:.0f} mm "
                     f"(medians of the run; points at their own load and nut)", grids.dpi,
                     overlay=squeak_points)
    if result.annotated.exists():        # unless the caller removed it (summaries only)
        attach(result, paths)
    return paths
