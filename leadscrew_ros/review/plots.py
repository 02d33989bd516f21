# SPDX-License-Identifier: Apache-2.0
"""Plotting primitives shared by the offline report and the paper's figures: axis display
(labels, display units, log scale of geometric grids), the stability colormap, and the plots
of a stability map and of the mode frequencies along a sweep.

matplotlib is imported where a figure is drawn, never at import: importing this module (e.g.
for `map --json`) neither loads matplotlib nor selects a backend. Figures are made with
matplotlib.figure.Figure, which renders PNGs without pyplot or any GUI backend.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable, NamedTuple

import numpy as np

from ..model.parameters import field_info
from ..model.sweep import PROBABILITY_LEVELS, MapResult, SweepResult
from ..model.tracking import track_modes

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.colors import Colormap
    from matplotlib.figure import Figure

Overlay = Callable[["Axes"], list]     # draws on a finished plot, returns legend handles


class Display(NamedTuple):
    """How values of an axis are shown in plots and in summary sentences."""

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
    """Axis label with its display unit, e.g. 'effective radius $R$ [mm]'."""
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


def scale_axis(ax: "Axes", which: str, values: np.ndarray) -> None:
    """A log scale on axis `which` ('x' or 'y') when `values` are a geometric grid."""
    if _is_geometric(values):
        getattr(ax, f"set_{which}scale")("log")


def stability_cmap() -> "Colormap":
    """Blues below zero, reds above, with a visible step at zero (the stability boundary)."""
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap
    return ListedColormap(np.vstack([colormaps["Blues_r"](np.linspace(0.0, 0.7, 128)),
                                     colormaps["Reds"](np.linspace(0.3, 1.0, 128))]),
                          name="stability")


def new_figure(**kwargs) -> "Figure":
    """A figure that is not registered with pyplot (no backend, nothing to close)."""
    from matplotlib.figure import Figure
    return Figure(**kwargs)


def plot_formats() -> list[str]:
    """The file suffixes (lower case, no dot) of the formats `save_figure` writes: matplotlib's
    (png, pdf, svg, ...; its canvas picks the format by the suffix)."""
    from matplotlib.backend_bases import FigureCanvasBase
    return sorted(FigureCanvasBase.get_supported_filetypes())


def save_figure(fig: "Figure", path: Path, dpi: int) -> None:
    """Write `fig` to `path` (the format from its suffix) at `dpi` dots per inch."""
    fig.savefig(path, dpi=dpi)


def plot_map(result: MapResult, path: Path, title: str = "", dpi: int = 120,
             formulation: str = "", overlay: Overlay | None = None) -> None:
    """Filled contour of the largest growth rate (red: squeak, blue: stable), the zero contour,
    the root-refined boundary points, and hatching where the model is not valid; `overlay`
    draws more (in display units) and returns its legend handles."""
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.patches import Patch
    kx, ky = axis_display(result.x_axis).factor, axis_display(result.y_axis).factor
    x, y, g = result.x * kx, result.y * ky, np.ma.masked_invalid(result.field.max_growth_rate)
    cmap = stability_cmap()
    fig = new_figure(figsize=(7, 5.2), layout="constrained")
    ax = fig.subplots()
    if g.count():
        lo, hi = min(float(g.min()), -1e-6), max(float(g.max()), 1e-6)
        levels = np.concatenate([np.linspace(lo, 0, 12)[:-1], np.linspace(0, hi, 16)])
        cs = ax.contourf(x, y, g, levels=levels, cmap=cmap,
                         norm=TwoSlopeNorm(0, lo, hi))
        fig.colorbar(cs, ax=ax, label=r"largest growth rate Re($\lambda$) [1/s]")
        if lo < 0 < hi and g.count() > 3:
            ax.contour(x, y, g, levels=[0.0], colors="k", linewidths=1.2)
    handles = [Patch(facecolor=cmap(0.8), label="unstable (squeak)"),
               Patch(facecolor=cmap(0.2), label="stable")]
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
    scale_axis(ax, "x", result.x)
    scale_axis(ax, "y", result.y)
    ax.set_xlim(x[0], x[-1])
    ax.set_ylim(y[0], y[-1])
    ax.set_xlabel(axis_label(result.x_axis))
    ax.set_ylabel(axis_label(result.y_axis))
    default = "; ".join(filter(None, (fixed_text(result.fixed),
                                      formulation and f"{formulation} formulation")))
    ax.set_title(title or f"Stability map ({default})", fontsize=10)
    fig.legend(handles=handles, fontsize=8, loc="outside lower center",
               ncols=min(len(handles), 4))
    save_figure(fig, path, dpi)


_LEVEL_STYLES = ("dotted", "dashed", "solid", "dashdot")   # of the PROBABILITY_LEVELS lines


def probability_overlay(result: MapResult, band: tuple[float, float] = (0.1, 0.9)
                        ) -> Overlay:
    """Draws the iso-P(squeak) lines `PROBABILITY_LEVELS` (1, 10, 50, 90 %) of a map computed
    with the probability, labelled in percent, and shades the band between the `band` levels
    (where a drive squeaks or not depending on its scatter); for `plot_map`'s `overlay`."""
    def draw(ax: "Axes") -> list:
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch
        prob = result.probability
        if prob is None or np.isfinite(prob).sum() < 4 or np.nanmax(prob) == np.nanmin(prob):
            return []
        kx, ky = axis_display(result.x_axis).factor, axis_display(result.y_axis).factor
        x, y, p = result.x * kx, result.y * ky, np.ma.masked_invalid(prob)
        ax.contourf(x, y, p, levels=list(band), colors="none", hatches=["..."])
        lines = ax.contour(x, y, p, levels=list(PROBABILITY_LEVELS), colors="k",
                           linestyles=_LEVEL_STYLES, linewidths=1.0)
        ax.clabel(lines, fmt=lambda v: f"{100 * v:g} %", fontsize=7)
        return [Patch(facecolor="none", edgecolor="0.3", hatch="...",
                      label=f"P(squeak) {100 * band[0]:g}-{100 * band[1]:g} %")] + [
            Line2D([], [], color="k", lw=1.0, ls=style, label=f"P = {100 * level:g} %")
            for level, style in zip(PROBABILITY_LEVELS, _LEVEL_STYLES)]
    return draw


def fixed_text(fixed: dict[str, float]) -> str:
    """The fixed values of a sweep or map: 'Omega = 20 rad/s, F_z = 200 N'."""
    return ", ".join(at(n, v) for n, v in fixed.items())


def plot_frequencies(result: SweepResult, path: Path, title: str = "", dpi: int = 120,
                     overlay: Overlay | None = None) -> None:
    """Frequency of every oscillatory mode along the axis: thin line, thick where Re > 0;
    `overlay` draws more (in display units) and returns its legend handles."""
    from matplotlib.lines import Line2D
    k = axis_display(result.axis).factor
    x = result.values * k
    fig = new_figure(figsize=(7.5, 5.2), layout="constrained")
    ax = fig.subplots()
    for b in track_modes(result.predictions):
        ax.plot(x, b.frequency_hz, color="0.25", lw=0.8)
        squeak = np.where(b.squeaks, b.frequency_hz, np.nan)
        if b.squeaks.any():
            ax.plot(x, squeak, color="tab:red", lw=4, solid_capstyle="butt")
            i = int(np.nanargmax(np.where(b.squeaks, b.growth, np.nan)))
            ax.annotate(b.squeak_text, (x[i], squeak[i]),
                        xytext=(4, 6), textcoords="offset points", color="tab:red",
                        fontsize=9, fontweight="bold")
    scale_axis(ax, "x", result.values)
    ax.set_yscale("log")
    ax.set_xlabel(axis_label(result.axis))
    ax.set_ylabel("frequency Im($\\lambda$)/2$\\pi$ [Hz]")
    ax.set_title(title or "Mode frequencies; thick: Re($\\lambda$) > 0 (squeak)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(handles=[Line2D([], [], color="0.25", lw=0.8, label=r"Re($\lambda$) $\leq$ 0"),
                       Line2D([], [], color="tab:red", lw=4,
                              label=r"Re($\lambda$) > 0 (squeak)")]
              + (overlay(ax) if overlay is not None else []), fontsize=8)
    save_figure(fig, path, dpi)


