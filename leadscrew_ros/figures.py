"""Plots of sweeps and stability maps, and the paper's Figs. 4-11 with a computed summary.

`plot_sweep` and `plot_map` are shared by the `figures` command and by `sweep --plot` /
`map --plot` of the CLI. `make_figures` writes fig04..fig11 PNGs and `summary.txt`, whose
sentences are computed from the plotted data (nothing is hard-coded).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from functools import cached_property, partial
from pathlib import Path
from typing import Callable, NamedTuple, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap, TwoSlopeNorm  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from scipy.optimize import linear_sum_assignment  # noqa: E402

from .model.friction import friction_coefficient, sliding_speed  # noqa: E402
from .model.parameters import ScrewParameters, field_info  # noqa: E402
from .model.predictor import Prediction, SqueakModel  # noqa: E402
from .model.sweep import (REFERENCE_SPEED_RAD_S, MapResult, SweepResult, Work,  # noqa: E402
                          map_work, stability_map, sweep, sweep_work)
from .progress import progress_bar  # noqa: E402

GROWTH_LABEL = r"growth rate Re($\lambda$) [1/s]"
Overlay = Callable[[plt.Axes], list]     # draws on a finished plot, returns legend handles


class Display(NamedTuple):
    label: str      # axis label (matplotlib mathtext)
    symbol: str     # plain-text symbol for summary.txt
    unit: str       # display unit
    factor: float   # SI value * factor = display value


_DISPLAY = {
    "speed_rad_s": Display(r"rotation speed $\Omega$", "Omega", "rad/s", 1.0),
    "load_n": Display("axial load $F_z$", "F_z", "N", 1.0),
    "axial_load_n": Display("axial load $F_z$", "F_z", "N", 1.0),
    "radius_m": Display("effective radius $R$", "R", "mm", 1e3),
    "nut_position_m": Display("nut location $z_o$", "z_o", "mm", 1e3),
    "nut_length_m": Display("nut length $b$", "b", "mm", 1e3),
    "length_m": Display("screw length $L$", "L", "mm", 1e3),
    "thread_height_m": Display("thread height $h$", "h", "mm", 1e3),
    "helix_angle_rad": Display(r"helix angle $\beta$", "beta", "deg", 180.0 / math.pi),
}


def axis_display(name: str) -> Display:
    """How a sweep axis is labelled and in which unit it is shown."""
    if name in _DISPLAY:
        return _DISPLAY[name]
    info = field_info(name)
    return Display(info["description"], name, info["unit"] or "1", 1.0)


def axis_label(name: str) -> str:
    d = axis_display(name)
    return f"{d.label} [{d.unit}]"


def fmt(name: str, value: float) -> str:
    """A value of an axis in its display unit, e.g. `5 mm`, `20.3 rad/s`."""
    d = axis_display(name)
    return f"{value * d.factor:.3g} {d.unit}" if math.isfinite(value) else "n/a"


def at(name: str, value: float) -> str:
    """`R = 5 mm`."""
    return f"{axis_display(name).symbol} = {fmt(name, value)}"


def _is_geometric(values: np.ndarray) -> bool:
    """True for a geomspace grid (plotted on a log axis)."""
    if len(values) < 3 or np.any(values <= 0):
        return False
    step = np.diff(np.log(values))
    return bool(np.allclose(step, step[0], rtol=1e-6) and values[-1] / values[0] > 20)


def _scale_axis(ax, which: str, values: np.ndarray) -> None:
    if _is_geometric(values):
        getattr(ax, f"set_{which}scale")("log")


def _stability_cmap() -> ListedColormap:
    """Blues below zero, reds above, with a visible step at zero (the stability boundary)."""
    return ListedColormap(np.vstack([plt.get_cmap("Blues_r")(np.linspace(0.0, 0.7, 128)),
                                     plt.get_cmap("Reds")(np.linspace(0.3, 1.0, 128))]),
                          name="stability")


STABILITY_CMAP = _stability_cmap()


def _save(fig, path: Path, dpi: int) -> None:
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


# --------------------------------------------------------------------------- mode tracking
@dataclass
class Branch:
    """One oscillatory mode followed along a sweep; NaN where it does not exist."""

    growth: np.ndarray                 # Re(lambda), 1/s
    frequency_hz: np.ndarray           # Im(lambda) / 2 pi
    labels: Counter = field(default_factory=Counter)

    @property
    def label(self) -> str:
        return self.labels.most_common(1)[0][0]

    @property
    def peak_growth(self) -> float:
        return float(np.nanmax(self.growth))

    @property
    def typical_frequency_hz(self) -> float:
        return float(np.nanmedian(self.frequency_hz))


def _eigenvalues(p: Prediction) -> np.ndarray:
    return np.array([complex(m.growth_rate, 2 * math.pi * m.frequency_hz) for m in p.modes])


def track_modes(predictions: Sequence[Prediction], max_jump: float = 0.15) -> list[Branch]:
    """Follow the oscillatory eigenvalues from point to point by nearest-neighbour assignment
    (relative distance below `max_jump`); a mode that appears or has jumped starts a branch.
    Labels alone cannot do this: the dominant coordinate of a whirl pair is ambiguous."""
    size, branches, alive, last = len(predictions), [], [], np.empty(0, complex)
    for i, p in enumerate(predictions):
        lam = _eigenvalues(p)
        owner = [-1] * len(lam)
        if len(last) and len(lam):
            cost = np.abs(last[:, None] - lam[None, :]) / np.maximum(
                np.abs(last)[:, None], np.abs(lam)[None, :])
            for r, c in zip(*linear_sum_assignment(cost)):
                if cost[r, c] < max_jump:
                    owner[c] = alive[r]
        for j, m in enumerate(p.modes):
            if owner[j] < 0:
                branches.append(Branch(np.full(size, np.nan), np.full(size, np.nan)))
                owner[j] = len(branches) - 1
            b = branches[owner[j]]
            b.growth[i], b.frequency_hz[i] = m.growth_rate, m.frequency_hz
            b.labels[m.label] += 1
        alive, last = owner, lam
    return branches


# --------------------------------------------------------------------------- shared plots
def plot_sweep(result: SweepResult, path: Path, title: str = "", top: int = 6,
               dpi: int = 120) -> None:
    """Largest growth rate and Re(lambda) of the `top` least stable modes along the axis, with
    the unstable bands shaded (the paper's Fig. 5 for a speed sweep)."""
    k = axis_display(result.axis).factor
    x = result.values * k
    branches = sorted(sorted(track_modes(result.predictions), key=lambda b: -b.peak_growth)[:top],
                      key=lambda b: b.typical_frequency_hz)
    fig, ax = plt.subplots(figsize=(7.5, 4.8), constrained_layout=True)
    ax.plot(x, result.max_growth_rate, color="0.75", lw=5, label=r"largest Re($\lambda$)")
    for b in branches:
        ax.plot(x, b.growth, lw=1.4, label=f"{b.label} ({b.typical_frequency_hz:.4g} Hz)")
    for i, (lo, hi) in enumerate(result.unstable_bands):
        ax.axvspan(lo * k, hi * k, color="tab:red", alpha=0.12,
                   label="unstable (squeak)" if i == 0 else None)
    ax.axhline(0.0, color="k", lw=0.8)
    _scale_axis(ax, "x", result.values)
    shown = np.concatenate([result.max_growth_rate] + [b.growth for b in branches])
    if np.isfinite(shown).any():
        hi = max(float(np.nanmax(shown)), 1.0)
        ax.set_ylim(max(float(np.nanmin(shown)), -2.5 * hi) * 1.05, hi * 1.1)
    ax.set_xlabel(axis_label(result.axis))
    ax.set_ylabel(GROWTH_LABEL)
    ax.set_title(title or f"Squeak propensity vs {axis_display(result.axis).label}\n"
                          f"({_fixed_text(result.fixed)}; {_formulation(result)} formulation)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    _save(fig, path, dpi)


def plot_map(result: MapResult, path: Path, title: str = "", dpi: int = 120,
             formulation: str = "", overlay: Overlay | None = None) -> None:
    """Filled contour of the largest growth rate (red: squeak, blue: stable), the zero contour,
    the root-refined boundary points, and hatching where the model is not valid; `overlay`
    draws more (in display units) and returns its legend handles."""
    kx, ky = axis_display(result.x_axis).factor, axis_display(result.y_axis).factor
    x, y, g = result.x * kx, result.y * ky, np.ma.masked_invalid(result.field.max_growth_rate)
    fig, ax = plt.subplots(figsize=(7, 5.2), constrained_layout=True)
    if g.count():
        lo, hi = min(float(g.min()), -1e-6), max(float(g.max()), 1e-6)
        levels = np.concatenate([np.linspace(lo, 0, 12)[:-1], np.linspace(0, hi, 16)])
        cs = ax.contourf(x, y, g, levels=levels, cmap=STABILITY_CMAP,
                         norm=TwoSlopeNorm(0, lo, hi))
        fig.colorbar(cs, ax=ax, label=r"largest growth rate Re($\lambda$) [1/s]")
        if lo < 0 < hi and g.count() > 3:
            ax.contour(x, y, g, levels=[0.0], colors="k", linewidths=1.2)
    handles = [Patch(facecolor=STABILITY_CMAP(0.8), label="unstable (squeak)"),
               Patch(facecolor=STABILITY_CMAP(0.2), label="stable")]
    invalid = ~result.field.valid
    if invalid.any():
        ax.contourf(x, y, invalid.astype(float), levels=[0.5, 1.5], colors="none",
                    hatches=["///"])
        handles.append(Patch(facecolor="white", edgecolor="0.3", hatch="///",
                             label="outside model validity"))
    if result.boundary:
        bx, by = np.array(result.boundary).T
        handles += ax.plot(bx * kx, by * ky, "k.", ms=3, label="stability boundary (refined)")
    if overlay is not None:
        handles += overlay(ax)
    _scale_axis(ax, "x", result.x)
    _scale_axis(ax, "y", result.y)
    ax.set_xlim(x[0], x[-1])
    ax.set_ylim(y[0], y[-1])
    ax.set_xlabel(axis_label(result.x_axis))
    ax.set_ylabel(axis_label(result.y_axis))
    default = "; ".join(filter(None, (_fixed_text(result.fixed),
                                      formulation and f"{formulation} formulation")))
    ax.set_title(title or f"Stability map ({default})", fontsize=10)
    fig.legend(handles=handles, fontsize=8, loc="outside lower center",
               ncols=min(len(handles), 4))
    _save(fig, path, dpi)


def _fixed_text(fixed: dict[str, float]) -> str:
    return ", ".join(at(n, v) for n, v in fixed.items())


def _formulation(result: SweepResult) -> str:
    return result.predictions[0].formulation if result.predictions else "?"


def plot_frequencies(result: SweepResult, path: Path, title: str = "", dpi: int = 120,
                     overlay: Overlay | None = None) -> None:
    """Frequency of every oscillatory mode along the axis: thin line, thick where Re > 0;
    `overlay` draws more (in display units) and returns its legend handles."""
    k = axis_display(result.axis).factor
    x = result.values * k
    fig, ax = plt.subplots(figsize=(7.5, 5.2), constrained_layout=True)
    for b in track_modes(result.predictions):
        ax.plot(x, b.frequency_hz, color="0.25", lw=0.8)
        squeak = np.where(b.growth > 0, b.frequency_hz, np.nan)
        if np.isfinite(squeak).any():
            ax.plot(x, squeak, color="tab:red", lw=4, solid_capstyle="butt")
            i = int(np.nanargmax(np.where(b.growth > 0, b.growth, np.nan)))
            ax.annotate(f"{b.label} {squeak[i]:.0f} Hz", (x[i], squeak[i]),
                        xytext=(4, 6), textcoords="offset points", color="tab:red",
                        fontsize=9, fontweight="bold")
    _scale_axis(ax, "x", result.values)
    ax.set_yscale("log")
    ax.set_xlabel(axis_label(result.axis))
    ax.set_ylabel("frequency Im($\\lambda$)/2$\\pi$ [Hz]")
    ax.set_title(title or "Mode frequencies; thick: Re($\\lambda$) > 0 (squeak)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(handles=[plt.Line2D([], [], color="0.25", lw=0.8, label=r"Re($\lambda$) $\leq$ 0"),
                       plt.Line2D([], [], color="tab:red", lw=4,
                                  label=r"Re($\lambda$) > 0 (squeak)")]
              + (overlay(ax) if overlay is not None else []), fontsize=8)
    _save(fig, path, dpi)


# --------------------------------------------------------------------------- data summaries
def _envelope(values: np.ndarray, growth: np.ndarray, roots: list[float]) -> tuple[float, float]:
    """Lowest and highest value of the unstable part of one grid line: refined roots, plus grid
    points that are unstable at the grid edge or next to an invalid point. NaN if stable."""
    unstable = np.nan_to_num(growth, nan=-1.0) > 0
    if not unstable.any():
        return math.nan, math.nan
    ok = np.concatenate([[False], np.isfinite(growth), [False]])
    ends = list(roots) + values[unstable & ~(ok[:-2] & ok[2:])].tolist()
    return min(ends), max(ends)


def envelopes(result: MapResult, along: str) -> np.ndarray:
    """(n, 2): lowest and highest unstable value along `along` ('x' or 'y') on each grid line
    across it (each column for 'y', each row for 'x'); NaN where the line is stable."""
    g, pts = result.field.max_growth_rate, result.boundary
    if along == "y":
        rows = [_envelope(result.y, g[:, i], [r for xv, r in pts if xv == v])
                for i, v in enumerate(result.x.tolist())]
    else:
        rows = [_envelope(result.x, g[j], [r for r, yv in pts if yv == v])
                for j, v in enumerate(result.y.tolist())]
    return np.array(rows, float).reshape(-1, 2)


def _bound_text(axis: str, v: float, grid_end: float) -> str:
    if not math.isfinite(v):
        return "none (no squeak)"
    return (">= " if v >= grid_end else "") + fmt(axis, v)


def _trend(what: str, bound: np.ndarray, bound_axis: str, grid_end: float,
           x_axis: str, x: np.ndarray) -> str:
    """'<what> falls from A at R = 2 mm to B at R = 10 mm'."""
    a, b = bound[0], bound[-1]
    verb = "goes" if not np.isfinite([a, b]).all() else (
        "falls" if a > b else "rises" if a < b else "stays")
    return (f"{what} {verb} from {_bound_text(bound_axis, a, grid_end)} at {at(x_axis, x[0])} "
            f"to {_bound_text(bound_axis, b, grid_end)} at {at(x_axis, x[-1])}")


def _extreme(what: str, bound: np.ndarray, bound_axis: str, grid_end: float,
             x_axis: str, x: np.ndarray, largest: bool, params: ScrewParameters) -> str:
    """'<what> is largest, A, at R = 2 mm' (with the nut centre for a nut-location axis)."""
    if not np.isfinite(bound).any():
        return f"{what}: none on the grid (no squeak)"
    i = int(np.nanargmax(bound) if largest else np.nanargmin(bound))
    note = ""
    if x_axis == "nut_position_m":
        note = (f" (nut centre z_o + b/2 = {fmt(x_axis, x[i] + params.nut_length_m / 2)}; "
                f"screw centre L/2 = {fmt(x_axis, params.length_m / 2)})")
    return (f"{what} is {'largest' if largest else 'smallest'}, "
            f"{_bound_text(bound_axis, bound[i], grid_end)}, at {at(x_axis, x[i])}{note}")


def _peak(result: MapResult) -> str:
    g = result.field.max_growth_rate
    if not np.isfinite(g).any():
        return "no valid point on the grid"
    j, i = np.unravel_index(np.nanargmax(g), g.shape)
    frac = np.mean(g[np.isfinite(g)] > 0)
    return (f"{100 * frac:.0f} % of the valid grid squeaks, most unstable grid point "
            f"{at(result.x_axis, result.x[i])}, {at(result.y_axis, result.y[j])} "
            f"(growth {g[j, i]:.1f} 1/s)")


def _nominal(result: MapResult, env: np.ndarray, params: ScrewParameters) -> str:
    """The unstable y-range on the grid column nearest the nominal parameter value."""
    nominal = getattr(params, "axial_load_n" if result.x_axis == "load_n" else result.x_axis)
    i = int(np.argmin(np.abs(result.x - nominal)))
    lo, hi = env[i]
    span = "no squeak" if math.isnan(lo) else (
        f"squeak for {_bound_text(result.y_axis, lo, math.inf)} to "
        f"{_bound_text(result.y_axis, hi, float(result.y[-1]))}")
    return f"nearest the nominal value, at {at(result.x_axis, result.x[i])}: {span}"


def describe_speed_map(result: MapResult, params: ScrewParameters) -> str:
    """Figs. 6-8: the unstable speed band for each parameter value (columns)."""
    env, top = envelopes(result, "y"), float(result.y[-1])
    args = ("speed_rad_s", top, result.x_axis, result.x)
    return (f"{_trend('upper speed bound of squeak', env[:, 1], *args)}; "
            f"{_trend('lower speed bound', env[:, 0], *args)}; "
            f"{_extreme('upper speed bound', env[:, 1], *args, True, params)}; "
            f"{_nominal(result, env, params)}; {_peak(result)}.")


def describe_load_speed_map(result: MapResult, params: ScrewParameters) -> str:
    """Fig. 7: also the load below which no speed squeaks (rows)."""
    low = envelopes(result, "x")[:, 0]
    lowest = _extreme("lowest unstable load", low, "load_n", math.inf, "speed_rad_s", result.y,
                      False, params)
    return f"{describe_speed_map(result, params)} Lower load bound of squeak: {lowest}."


def describe_load_map(result: MapResult, params: ScrewParameters) -> str:
    """Figs. 9-10: the lowest unstable load for each parameter value at a fixed speed."""
    env = envelopes(result, "y")
    args = ("load_n", float(result.y[-1]), result.x_axis, result.x)
    return (f"at {_fixed_text(result.fixed)}: "
            f"{_trend('lowest unstable load', env[:, 0], *args)}; "
            f"{_extreme('lowest unstable load', env[:, 0], *args, False, params)}; "
            f"{_nominal(result, env, params)}; {_peak(result)}.")


def describe_speed_sweep(result: SweepResult) -> str:
    """Fig. 5: band, peak and squeak modes."""
    g = result.max_growth_rate
    if not np.isfinite(g).any():
        return "no valid point in the sweep."
    bands = ", ".join(f"{lo:.3g}-{hi:.3g} rad/s" for lo, hi in result.unstable_bands) or "none"
    freqs: dict[str, list[float]] = {}
    for p in result.predictions:
        for m in p.squeak_modes:
            freqs.setdefault(m.label, []).append(m.frequency_hz)
    modes = ", ".join(f"{lab} {np.median(f):.0f} Hz" for lab, f in
                      sorted(freqs.items(), key=lambda kv: np.median(kv[1]))) or "none"
    i = int(np.nanargmax(g))
    return (f"unstable band {bands} (refined boundaries; stable elsewhere on "
            f"{fmt('speed_rad_s', result.values[0])}-{fmt('speed_rad_s', result.values[-1])}); "
            f"largest growth {g[i]:.1f} 1/s at {at('speed_rad_s', result.values[i])}; "
            f"squeak modes {modes}.")


def describe_frequencies(result: SweepResult) -> str:
    """Fig. 11: which mode frequencies are thick (Re > 0) and over which speeds."""
    branches = track_modes(result.predictions)
    parts = []
    for b in sorted(branches, key=lambda b: b.typical_frequency_hz):
        unstable = b.growth > 0
        if unstable.any():
            v = result.values[unstable]
            parts.append(f"{b.label} at {np.median(b.frequency_hz[unstable]):.0f} Hz for "
                         f"{v.min():.3g}-{fmt('speed_rad_s', v.max())}")
    return (f"thick (squeak) lines: {'; '.join(parts) or 'none'}; all other "
            f"{len(branches) - len(parts)} traced mode branches stay at Re <= 0.")


def describe_friction(p: ScrewParameters, v: np.ndarray, mu: np.ndarray) -> str:
    v_ref = float(sliding_speed(p, REFERENCE_SPEED_RAD_S))
    mu_ref = float(friction_coefficient(p, v_ref))
    slope = np.gradient(mu, v)
    return (f"mu falls from {mu[0]:.3f} (mu_s) at rest to {mu[-1]:.3f} at |Vc| = {v[-1]:.2f} m/s "
            f"(mu_k = {p.mu_kinetic:.3f}), steepest slope {slope.min():.3f} s/m at rest; at "
            f"{at('speed_rad_s', REFERENCE_SPEED_RAD_S)} (|Vc| = {v_ref:.3f} m/s) "
            f"mu_o = {mu_ref:.3f}.")


# --------------------------------------------------------------------------- the figure set
@dataclass(frozen=True)
class Grids:
    sweep_points: int
    map_x: int
    map_y: int
    dpi: int


FULL = Grids(sweep_points=500, map_x=81, map_y=101, dpi=130)
QUICK = Grids(sweep_points=60, map_x=7, map_y=9, dpi=60)

SWEEP_SPEEDS_RAD_S = (0.5, 120.0)    # Figs. 5 and 11: the whole band (~0.8-55 rad/s at Table 1)
RADIUS_RANGE_M = (0.002, 0.010)
LOAD_RANGE_N = (0.0, 600.0)
FRICTION_FILE = "fig04_friction.png"
GROWTH_FILE = "fig05_growth_vs_speed.png"
FREQUENCY_FILE = "fig11_frequency_vs_speed.png"


@dataclass(frozen=True)
class MapSpec:
    """One stability-map figure: x from a parameter range, y speed (geometric grid) or load."""

    file: str
    title: str
    x_axis: str
    x_range: Callable[[ScrewParameters], tuple[float, float]]
    y_axis: str
    y_range: tuple[float, float]
    speed_rad_s: float | None
    describe: Callable[[MapResult, ScrewParameters], str]


def _nut_range(p: ScrewParameters) -> tuple[float, float]:
    """z_o from 0 to L - b (the nut stays on the screw)."""
    return 0.0, p.length_m - p.nut_length_m


def _radius_range(p: ScrewParameters) -> tuple[float, float]:
    return RADIUS_RANGE_M


def _load_range(p: ScrewParameters) -> tuple[float, float]:
    return LOAD_RANGE_N


MAPS = (
    MapSpec("fig06_speed_radius.png", "Fig. 6: stability boundary, speed vs effective radius",
            "radius_m", _radius_range, "speed_rad_s", (0.5, 600.0), None,
            describe_speed_map),
    MapSpec("fig07_speed_load.png", "Fig. 7: stability boundary, speed vs axial load",
            "load_n", _load_range, "speed_rad_s", (0.5, 200.0), None,
            describe_load_speed_map),
    MapSpec("fig08_speed_location.png", "Fig. 8: stability boundary, speed vs nut location",
            "nut_position_m", _nut_range, "speed_rad_s", (0.5, 200.0), None, describe_speed_map),
    MapSpec("fig09_load_radius.png", "Fig. 9: stability boundary, axial load vs effective radius",
            "radius_m", _radius_range, "load_n", LOAD_RANGE_N, REFERENCE_SPEED_RAD_S,
            describe_load_map),
    MapSpec("fig10_load_location.png", "Fig. 10: stability boundary, axial load vs nut location",
            "nut_position_m", _nut_range, "load_n", LOAD_RANGE_N, REFERENCE_SPEED_RAD_S,
            describe_load_map),
)


def _grid(axis: str, lo: float, hi: float, n: int) -> np.ndarray:
    """Speed on a geometric grid (both boundaries of the band are visible), others linear."""
    return np.geomspace(lo, hi, n) if axis == "speed_rad_s" else np.linspace(lo, hi, n)


def run_map(model: SqueakModel, x_axis: str, x: np.ndarray, y_axis: str, y: np.ndarray,
            speed_rad_s: float | None = None, load_n: float | None = None,
            desc: str = "map") -> MapResult:
    """`stability_map` with a progress bar over the grid points (after the work check)."""
    map_work(model, x_axis, x, y_axis, y).check()
    with progress_bar(x.size * y.size, desc) as update:
        return stability_map(model, x_axis, x, y_axis, y, speed_rad_s, load_n, progress=update)


@dataclass
class FigureSet:
    model: SqueakModel
    out: Path
    grids: Grids

    def _title(self, text: str) -> str:
        return f"{text}\n({self.model.params.formulation} formulation)"

    @cached_property
    def speed_sweep(self) -> SweepResult:
        speeds = np.geomspace(*SWEEP_SPEEDS_RAD_S, self.grids.sweep_points)
        return sweep(self.model, "speed_rad_s", speeds)

    def friction(self, path: Path) -> str:
        p = self.model.params
        v = np.linspace(0.0, float(sliding_speed(p, SWEEP_SPEEDS_RAD_S[1])), 400)
        mu = friction_coefficient(p, v)
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        ax.plot(v, mu, lw=2, label=r"$\mu = \mu_k + (\mu_s - \mu_k)\,e^{-d|V_c|}$ (12)")
        for value, name in ((p.mu_static, r"$\mu_s$"), (p.mu_kinetic, r"$\mu_k$")):
            ax.axhline(value, color="0.5", ls=":", lw=1)
            ax.annotate(f"{name} = {value:g}", (v[-1], value), ha="right", va="bottom")
        top = ax.secondary_xaxis("top", functions=(
            lambda s: s * math.cos(p.helix_angle_rad) / p.radius_m,
            lambda w: w * p.radius_m / math.cos(p.helix_angle_rad)))
        top.set_xlabel(r"rotation speed $\Omega = |V_c| \cos\beta / R$ [rad/s]")
        ax.set_xlabel(r"sliding speed $|V_c|$ [m/s]")
        ax.set_ylabel(r"friction coefficient $\mu$ [-]")
        ax.set_title(f"Fig. 4: friction-velocity curve ($d$ = {p.friction_decay_s_m:g} s/m)")
        ax.grid(alpha=0.3)
        ax.legend()
        _save(fig, path, self.grids.dpi)
        return describe_friction(p, v, mu)

    def growth(self, path: Path) -> str:
        plot_sweep(self.speed_sweep, path,
                   self._title("Fig. 5: squeak propensity vs rotation speed"), dpi=self.grids.dpi)
        return describe_speed_sweep(self.speed_sweep)

    def frequencies(self, path: Path) -> str:
        plot_frequencies(self.speed_sweep, path,
                         self._title("Fig. 11: squeak frequencies vs rotation speed "
                                     r"(thick: Re($\lambda$) > 0)"), dpi=self.grids.dpi)
        return describe_frequencies(self.speed_sweep)

    def stability(self, spec: MapSpec, path: Path) -> str:
        x = _grid(spec.x_axis, *spec.x_range(self.model.params), self.grids.map_x)
        y = _grid(spec.y_axis, *spec.y_range, self.grids.map_y)
        result = run_map(self.model, spec.x_axis, x, spec.y_axis, y, spec.speed_rad_s,
                         desc=spec.file.split("_")[0])
        title = self._title("\n".join(filter(None, (spec.title, _fixed_text(result.fixed)))))
        plot_map(result, path, title, dpi=self.grids.dpi)
        return spec.describe(result, self.model.params)

    def work(self) -> Work:
        """All the predictions of the figures, as one batch (checked before the first)."""
        speeds = sweep_work(self.model, "speed_rad_s", np.zeros(self.grids.sweep_points))
        maps = [map_work(self.model, s.x_axis, np.zeros(self.grids.map_x), s.y_axis,
                         np.zeros(self.grids.map_y)) for s in MAPS]
        return Work(f"figures: {len(maps)} maps of {self.grids.map_x} x {self.grids.map_y} and "
                    f"a sweep of {self.grids.sweep_points}",
                    speeds.points + sum(m.points for m in maps), speeds.state_size,
                    speeds.bytes_per_point, "use --quick or fewer modes")

    def jobs(self) -> dict[str, Callable[[Path], str]]:
        """File name -> function that draws it and returns its summary sentence."""
        jobs = {FRICTION_FILE: self.friction, GROWTH_FILE: self.growth,
                FREQUENCY_FILE: self.frequencies}
        jobs.update({s.file: partial(self.stability, s) for s in MAPS})
        return {name: jobs[name] for name in FIGURE_FILES}


FIGURE_FILES = (FRICTION_FILE, GROWTH_FILE, *(s.file for s in MAPS), FREQUENCY_FILE)


def _header(params: ScrewParameters) -> str:
    default = ScrewParameters()
    changed = [f"{k} = {v!r}" for k, v in params.as_dict().items()
               if v != getattr(default, k) and k != "formulation"]
    base = "Table 1 defaults" + (" except " + ", ".join(changed) if changed else "")
    return f"leadscrew-squeak figures: {params.formulation} formulation, {base}"


def make_figures(model: SqueakModel, out: Path, quick: bool = False) -> str:
    """Write the eight PNGs and summary.txt into `out`; return the summary text. Raises
    WorkSizeError, before anything is written, if the model is too large for the grids."""
    figures = FigureSet(model, out, QUICK if quick else FULL)
    figures.work().check()
    out.mkdir(parents=True, exist_ok=True)
    lines = [_header(model.params)]
    jobs = figures.jobs()
    with progress_bar(len(jobs), "figures", unit="fig", leave=True) as update:
        for name, job in jobs.items():
            lines.append(f"{name}: {job(out / name)}")
            update(1)
    summary = "\n".join(lines) + "\n"
    (out / "summary.txt").write_text(summary, encoding="utf-8")
    return summary
