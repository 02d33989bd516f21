"""PNG report of a replay: the run over time, and its trajectory on the stability maps.

- `timeline.png`: speed, load, nut position and squeak risk over time, episodes shaded;
- `map_speed_load.png`: the run's operating points on the speed-load stability map (the
  paper's Fig. 7), squeak predictions highlighted;
- `frequency_vs_speed.png`: the predicted squeak frequencies over the mode frequencies vs speed
  (the paper's Fig. 11).
The maps are drawn at the run's median nut position and (Fig. 11) median load, as |speed| and
|load| (a negative speed is the screw turning the other way); the figures module draws them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .figures import plot_frequencies, plot_map, plt
from .model import SqueakModel
from .model.sweep import stability_map, sweep
from .replay import ReplayResult

TIMELINE_FILE = "timeline.png"
MAP_FILE = "map_speed_load.png"
FREQUENCY_FILE = "frequency_vs_speed.png"
SQUEAK_COLOR = "orange"


@dataclass(frozen=True)
class ReportGrids:
    map_loads: int
    map_speeds: int
    sweep_speeds: int
    dpi: int
    max_points: int          # time-series samples drawn per curve (min/max per bin beyond)


FULL = ReportGrids(map_loads=41, map_speeds=51, sweep_speeds=300, dpi=110, max_points=20_000)
QUICK = ReportGrids(map_loads=7, map_speeds=9, sweep_speeds=40, dpi=60, max_points=2_000)


def _decimate(t: np.ndarray, y: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ~max_points samples that keep each bin's minimum and maximum (spikes stay)."""
    if t.size <= max_points:
        return t, y
    bins = max_points // 2
    edges = np.linspace(0, t.size, bins + 1).astype(int)
    keep = []
    for a, b in zip(edges[:-1], edges[1:]):
        part = y[a:b]
        if np.isnan(part).all():
            keep.append(a)
            continue
        keep += sorted({a + int(np.nanargmin(part)), a + int(np.nanargmax(part))})
    idx = np.array(keep)
    return t[idx], y[idx]


def plot_timeline(result: ReplayResult, path: Path, grids: ReportGrids) -> None:
    tl, s = result.timeline, result.series
    t = (np.frombuffer(tl.time_ns, np.int64) - result.start_ns) / 1e9
    fig, axes = plt.subplots(4, 1, figsize=(10, 8.5), sharex=True, constrained_layout=True)
    for ax, values, label in zip(axes, (tl.speeds, tl.loads, tl.nuts),
                                 ("speed [rad/s]", "axial load [N]", "nut position [mm]")):
        y = np.frombuffer(values, float) * (1e3 if "mm" in label else 1.0)
        ax.plot(*_decimate(t, y, grids.max_points), lw=0.7, color="tab:blue")
        ax.set_ylabel(label)
    risk = axes[3]
    if s.time_s:
        # The published risk holds until the next prediction.
        risk.step(s.time_s, s.risk, where="post", lw=0.8, color="tab:red")
    risk.set_ylim(-0.05, 1.05)
    risk.set_ylabel("squeak risk [0..1]")
    risk.set_xlabel("time since the log's first message [s]")
    for ax in axes:
        for e in result.episodes:
            ax.axvspan(e.start_s, e.end_s, color=SQUEAK_COLOR, alpha=0.3, lw=0)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"Replay of {result.log.name}: {len(result.episodes)} squeak episodes "
                      f"(shaded), {result.time_in_squeak_s:.1f} s in squeak")
    fig.savefig(path, dpi=grids.dpi)
    plt.close(fig)


def _median_abs(values: list[float], default: float) -> float:
    return float(np.median(np.abs(values))) if values else default


def write_report(result: ReplayResult, model: SqueakModel, out: Path | str,
                 grids: ReportGrids = FULL) -> list[Path]:
    """Write the three PNGs into `out`; returns their paths."""
    out, s = Path(out), result.series
    paths = [out / TIMELINE_FILE, out / MAP_FILE, out / FREQUENCY_FILE]
    plot_timeline(result, paths[0], grids)

    nut = float(np.median(s.nut_position_m)) if s.nut_position_m else model.params.nut_position_m
    at_nut = model.with_params(nut_position_m=nut)
    speed = np.abs(s.speed_rad_s)
    load = np.abs(s.load_n)
    active = np.array(s.active, bool)
    p = model.params
    speed_hi = min(max(200.0, 1.1 * speed.max(initial=0.0)), 0.99 * model.critical_speed_rad_s)
    speeds = np.geomspace(p.min_speed_rad_s, speed_hi, grids.map_speeds)
    loads = np.linspace(0.0, max(600.0, 1.1 * load.max(initial=0.0)), grids.map_loads)

    def trajectory(ax) -> list:
        if not speed.size:
            return []
        handles = ax.plot(load, speed, "-", color="0.15", lw=0.6, alpha=0.6,
                          label="replayed operating points")
        return handles + ax.plot(load[active], speed[active], "o", ms=3, mfc=SQUEAK_COLOR,
                                 mec="k", mew=0.3, ls="none", label="squeak predicted")

    result_map = stability_map(at_nut, "load_n", loads, "speed_rad_s", speeds)
    plot_map(result_map, paths[1], f"Replay on the speed-load stability map (Fig. 7 style)\n"
             f"nut at {nut * 1e3:.0f} mm (median of the run); |speed|, |load|", grids.dpi,
             p.formulation, overlay=trajectory)

    def squeak_points(ax) -> list:
        if not s.squeak_hz:
            return []
        return ax.plot(speed[np.array(s.squeak_rows)], s.squeak_hz, "o", ms=3, mfc=SQUEAK_COLOR, mec="k", mew=0.3,
                       ls="none", label="replayed squeak predictions")

    median_load = _median_abs(s.load_n, p.axial_load_n)
    speed_sweep = sweep(at_nut, "speed_rad_s",
                        np.geomspace(p.min_speed_rad_s, speed_hi, grids.sweep_speeds),
                        load_n=median_load)
    plot_frequencies(speed_sweep, paths[2], f"Replayed squeak frequencies on the modes vs speed "
                     f"(Fig. 11 style)\nload {median_load:.0f} N, nut {nut * 1e3:.0f} mm "
                     f"(medians of the run; points at their own load)", grids.dpi,
                     overlay=squeak_points)
    return paths
