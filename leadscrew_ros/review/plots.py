# SPDX-License-Identifier: Apache-2.0
"""Every plot of the package, and the primitives they share: axis display (labels, display
units, log scale of geometric grids), the stability colormap, the overlays.

A plot is a function of its data in the matplotlib convention: `plot_x(data, ..., ax=None)` (one
axes) or `plot_x(data, ..., fig=None)` (several panels) draws into the given axes or figure, or
into a new one when none is given, and returns the Figure. Nothing here writes a file: the
caller saves (`fig.savefig(path, dpi=...)`).

- `plot_map` (a `MapResult`), `plot_frequencies` and `plot_sweep` (a `SweepResult`),
  `plot_friction` (the friction law of the parameters), `plot_transient` (a `TransientResult`
  with its `TransientAnalysis`): the model's results have no `plot` method, as `model` may not
  import this layer (matplotlib is a review dependency); they are plotted here;
- `plot_timeline` (a `ReplayResult`, also `ReplayResult.plot`; with sound its `plot_heard`
  panel), `plot_fleet` (a `FleetRun`) and `plot_guard` (a `GuardRun`).

matplotlib is imported where a figure is drawn, never at import: importing this module (e.g.
for `map --json`) neither loads matplotlib nor selects a backend. New figures are
matplotlib.figure.Figure, which renders PNGs without pyplot or any GUI backend.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..bag.messages import SPEED_COMMAND, SPEED_COMMAND_GUARDED
from ..model.calibration.amplitude import NP_PER_DB, AmplitudeLikelihood
from ..model.physics.friction import friction_coefficient
from ..model.physics.parameters import ScrewParameters, field_info
from ..model.studies.fields import PROBABILITY_LEVELS
from ..model.studies.stability_map import MapResult
from ..model.studies.sweep import SweepResult
from ..model.studies.tracking import track_modes
from .commands import LABELS

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.colors import Colormap
    from matplotlib.figure import Figure
    from matplotlib.text import Text

    from ..model.nonlinear.transient import TransientResult
    from ..model.nonlinear.transient_analysis import TransientAnalysis
    from .commands import CommandTrace
    from .fleet import FleetRun
    from .guard import GuardRun
    from .listen import Heard, Spectrogram
    from .recording import Listened
    from .replay import ReplayResult

ERROR_GREY = "0.6"  # logs that could not be reviewed, in the fleet's panels
Overlay = Callable[["Axes"], list]  # draws on a finished plot, returns legend handles


class Display(NamedTuple):
    """How values of an axis are shown in plots and in summary sentences."""

    label: str  # axis label (matplotlib mathtext)
    symbol: str  # plain-text symbol for summary.txt
    unit: str  # display unit
    factor: float  # SI value * factor = display value


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


def scale_axis(ax: Axes, which: str, values: np.ndarray) -> None:
    """A log scale on axis `which` ('x' or 'y') when `values` are a geometric grid."""
    if _is_geometric(values):
        getattr(ax, f"set_{which}scale")("log")


def stability_cmap() -> Colormap:
    """Blues below zero, reds above, with a visible step at zero (the stability boundary)."""
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap

    return ListedColormap(
        np.vstack(
            [
                colormaps["Blues_r"](np.linspace(0.0, 0.7, 128)),
                colormaps["Reds"](np.linspace(0.3, 1.0, 128)),
            ]
        ),
        name="stability",
    )


def new_figure(**kwargs: Any) -> Figure:
    """A figure that is not registered with pyplot (no backend, nothing to close).

    Parameters
    ----------
    **kwargs
        Passed to `matplotlib.figure.Figure` (figsize, layout, ...).

    Returns
    -------
    Figure
        The new figure.
    """
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def _axes(ax: Axes | None, **figure: Any) -> tuple[Figure, Axes]:
    """The figure of `ax` and `ax`, or a new figure (of `figure`'s options) and its one axes."""
    if ax is None:
        ax = new_figure(**figure).subplots()
    fig = ax.get_figure(root=True)
    assert fig is not None  # an axes made by or added to a figure
    return fig, ax


def plot_formats() -> list[str]:
    """The file suffixes (lower case, no dot) of the formats `Figure.savefig` writes:
    matplotlib's (png, pdf, svg, ...; its canvas picks the format by the suffix)."""
    from matplotlib.backend_bases import FigureCanvasBase

    return sorted(FigureCanvasBase.get_supported_filetypes())


def plot_map(
    result: MapResult,
    *,
    title: str = "",
    formulation: str = "",
    overlay: Overlay | None = None,
    ax: Axes | None = None,
) -> Figure:
    """Stability map: filled contour of the largest growth rate (red: squeak, blue: stable),
    the zero contour, the root-refined boundary points, and hatching where the model is not
    valid.

    Parameters
    ----------
    result : MapResult
        The map (`studies.sweep.stability_map`).
    title : str
        The title; default: the fixed values and `formulation`.
    formulation : str
        Named in the default title ('' leaves it out).
    overlay : callable, optional
        Draws more on the axes (in display units) and returns its legend handles, e.g.
        `probability_overlay(result)`.
    ax : Axes, optional
        The axes to draw into (the legend goes to its figure); default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.patches import Patch

    kx, ky = axis_display(result.x_axis).factor, axis_display(result.y_axis).factor
    x, y, g = result.x * kx, result.y * ky, np.ma.masked_invalid(result.field.max_growth_rate)
    cmap = stability_cmap()
    fig, ax = _axes(ax, figsize=(7, 5.2), layout="constrained")
    if g.count():
        lo, hi = min(float(g.min()), -1e-6), max(float(g.max()), 1e-6)
        levels = np.concatenate([np.linspace(lo, 0, 12)[:-1], np.linspace(0, hi, 16)])
        cs = ax.contourf(x, y, g, levels=levels, cmap=cmap, norm=TwoSlopeNorm(0, lo, hi))
        bar = fig.colorbar(cs, ax=ax, label=r"largest growth rate Re($\lambda$) [1/s]")
        bar.set_ticks(_two_sided_ticks(lo, hi))
        if lo < 0 < hi and g.count() > 3:
            ax.contour(x, y, g, levels=[0.0], colors="k", linewidths=1.2)
    handles: list[Artist] = [
        Patch(facecolor=cmap(0.8), label="unstable (squeak)"),
        Patch(facecolor=cmap(0.2), label="stable"),
    ]
    invalid = ~result.field.valid
    if invalid.any():
        ax.contourf(x, y, invalid.astype(float), levels=[0.5, 1.5], colors="none", hatches=["///"])
        handles.append(
            Patch(facecolor="white", edgecolor="0.3", hatch="///", label="outside model validity")
        )
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
    default = "; ".join(
        filter(None, (fixed_text(result.fixed), formulation and f"{formulation} formulation"))
    )
    ax.set_title(title or f"Stability map ({default})", fontsize=10)
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncols=min(len(handles), 4))
    return fig


def _two_sided_ticks(lo: float, hi: float) -> list[float]:
    """Round ticks of a colourbar from `lo` < 0 to `hi` > 0, zero included: each side of zero
    is scaled on its own (`TwoSlopeNorm`), so each gets its own round steps."""
    from matplotlib.ticker import MaxNLocator

    ticks = np.r_[MaxNLocator(3).tick_values(lo, 0.0), MaxNLocator(5).tick_values(0.0, hi)]
    return sorted({float(t) for t in ticks if lo <= t <= hi} | {0.0})


def upright(texts: Sequence[Text]) -> None:
    """Contour labels fixed at their angle on screen now, turned to read left to right or
    bottom to top: a label along its line turns with the axes' aspect, which the layout
    changes after `clabel`, and could end up reading top to bottom or upside down."""
    for t in texts:
        angle = (t.get_rotation() + 90.0) % 180.0 - 90.0  # [-90, 90)
        t.set_transform_rotates_text(False)
        t.set_rotation(90.0 if angle < -60.0 else angle)


_LEVEL_STYLES = ("dotted", "dashed", "solid", "dashdot")  # of the PROBABILITY_LEVELS lines


def probability_overlay(result: MapResult, band: tuple[float, float] = (0.1, 0.9)) -> Overlay:
    """The iso-P(squeak) lines `PROBABILITY_LEVELS` (1, 10, 50, 90 %) of a map, labelled in
    percent, and the band between two levels shaded (where a drive squeaks or not depending on
    its scatter); for `plot_map`'s `overlay`.

    Parameters
    ----------
    result : MapResult
        A map computed with the probability (without: nothing is drawn).
    band : tuple of float
        The levels the shaded band lies between.

    Returns
    -------
    callable
        Draws on an axes (in display units) and returns its legend handles.
    """

    def draw(ax: Axes) -> list:
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        prob = result.probability
        if prob is None or np.isfinite(prob).sum() < 4 or np.nanmax(prob) == np.nanmin(prob):
            return []
        kx, ky = axis_display(result.x_axis).factor, axis_display(result.y_axis).factor
        x, y, p = result.x * kx, result.y * ky, np.ma.masked_invalid(prob)
        ax.contourf(x, y, p, levels=list(band), colors="none", hatches=["..."])
        lines = ax.contour(
            x,
            y,
            p,
            levels=list(PROBABILITY_LEVELS),
            colors="k",
            linestyles=_LEVEL_STYLES,
            linewidths=1.0,
        )
        upright(ax.clabel(lines, fmt=lambda v: f"{100 * v:g} %", fontsize=8))
        return [
            Patch(
                facecolor="none",
                edgecolor="0.3",
                hatch="...",
                label=f"P(squeak) {100 * band[0]:g}-{100 * band[1]:g} %",
            )
        ] + [
            Line2D([], [], color="k", lw=1.0, ls=style, label=f"P = {100 * level:g} %")
            for level, style in zip(PROBABILITY_LEVELS, _LEVEL_STYLES, strict=True)
        ]

    return draw


def fixed_text(fixed: dict[str, float]) -> str:
    """The fixed values of a sweep or map: 'Omega = 20 rad/s, F_z = 200 N'."""
    return ", ".join(at(n, v) for n, v in fixed.items())


def plot_frequencies(
    result: SweepResult, *, title: str = "", overlay: Overlay | None = None, ax: Axes | None = None
) -> Figure:
    """Frequency of every oscillatory mode along the sweep's axis: thin line, thick where
    Re > 0 (squeak), each squeaking branch labelled at its peak growth (the paper's Fig. 11
    for a speed sweep).

    Parameters
    ----------
    result : SweepResult
        The sweep (`studies.sweep.sweep`).
    title : str
        The title; default: what the thick lines mean.
    overlay : callable, optional
        Draws more on the axes (in display units) and returns its legend handles.
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    from matplotlib.lines import Line2D

    k = axis_display(result.axis).factor
    x = result.values * k
    fig, ax = _axes(ax, figsize=(7.5, 5.2), layout="constrained")
    for b in track_modes(result.predictions):
        ax.plot(x, b.frequency_hz, color="0.25", lw=0.8)
        squeak = np.where(b.squeaks, b.frequency_hz, np.nan)
        if b.squeaks.any():
            ax.plot(x, squeak, color="tab:red", lw=4, solid_capstyle="butt")
            i = int(np.nanargmax(np.where(b.squeaks, b.growth, np.nan)))
            ax.annotate(
                b.squeak_text,
                (x[i], squeak[i]),
                xytext=(4, 6),
                textcoords="offset points",
                color="tab:red",
                fontsize=9,
                fontweight="bold",
            )
    scale_axis(ax, "x", result.values)
    ax.set_yscale("log")
    ax.set_xlabel(axis_label(result.axis))
    ax.set_ylabel("frequency Im($\\lambda$)/2$\\pi$ [Hz]")
    ax.set_title(title or "Mode frequencies; thick: Re($\\lambda$) > 0 (squeak)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(
        handles=[
            Line2D([], [], color="0.25", lw=0.8, label=r"Re($\lambda$) $\leq$ 0"),
            Line2D([], [], color="tab:red", lw=4, label=r"Re($\lambda$) > 0 (squeak)"),
        ]
        + (overlay(ax) if overlay is not None else []),
        fontsize=8,
    )
    return fig


GROWTH_LABEL = r"growth rate Re($\lambda$) [1/s]"


def plot_sweep(
    result: SweepResult,
    *,
    title: str = "",
    top: int = 6,
    probability: bool = False,
    ax: Axes | None = None,
) -> Figure:
    """Largest growth rate and Re(lambda) of the least stable modes along the sweep's axis,
    with the unstable bands shaded (the paper's Fig. 5 for a speed sweep).

    Parameters
    ----------
    result : SweepResult
        The sweep (`studies.sweep.sweep`).
    title : str
        The title; default: the axis, the fixed values and the formulation.
    top : int
        How many mode branches are drawn (those of largest peak growth).
    probability : bool
        Also P(squeak) on a second y axis.
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    k = axis_display(result.axis).factor
    x = result.values * k
    branches = sorted(
        sorted(track_modes(result.predictions), key=lambda b: -b.peak_growth)[:top],
        key=lambda b: b.typical_frequency_hz,
    )
    fig, ax = _axes(ax, figsize=(7.5, 4.8), layout="constrained")
    ax.plot(x, result.max_growth_rate, color="0.75", lw=5, label=r"largest Re($\lambda$)")
    for b in branches:
        ax.plot(x, b.growth, lw=1.4, label=f"{b.label} ({b.typical_frequency_hz:.4g} Hz)")
    for i, (lo, hi) in enumerate(result.unstable_bands):
        ax.axvspan(
            lo * k,
            hi * k,
            color="tab:red",
            alpha=0.12,
            label="unstable (squeak)" if i == 0 else None,
        )
    ax.axhline(0.0, color="k", lw=0.8)
    scale_axis(ax, "x", result.values)
    shown = np.concatenate([result.max_growth_rate] + [b.growth for b in branches])
    if np.isfinite(shown).any():
        hi = max(float(np.nanmax(shown)), 1.0)
        ax.set_ylim(max(float(np.nanmin(shown)), -2.5 * hi) * 1.05, hi * 1.1)
    ax.set_xlabel(axis_label(result.axis))
    ax.set_ylabel(GROWTH_LABEL)
    formulation = result.predictions[0].formulation if result.predictions else "?"
    ax.set_title(
        title
        or f"Squeak propensity vs {axis_display(result.axis).label}\n"
        f"({fixed_text(result.fixed)}; {formulation} formulation)"
    )
    ax.grid(alpha=0.3, which="both")
    handles, anchor = ax.get_legend_handles_labels()[0], 1.01
    if probability:
        twin = ax.twinx()
        handles += twin.plot(
            x, result.probability, color="k", ls="--", lw=1.6, label="P(squeak) (right axis)"
        )
        twin.set_ylim(-0.02, 1.02)
        twin.set_ylabel("P(squeak) over the scatter [-]")
        anchor = 1.12
    ax.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(anchor, 1.0))
    return fig


def plot_friction(
    params: ScrewParameters, sliding_m_s: np.ndarray, *, ax: Axes | None = None
) -> Figure:
    """The friction law (eq. 12) over the sliding speed, with the rotation speed on top (the
    paper's Fig. 4).

    Parameters
    ----------
    params : ScrewParameters
        Friction coefficients, decay, radius and helix angle.
    sliding_m_s : ndarray
        Sliding speeds |Vc| [m/s] of the curve, increasing.
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    p, v = params, sliding_m_s
    fig, ax = _axes(ax, figsize=(7, 4.5), layout="constrained")
    ax.plot(
        v,
        friction_coefficient(p, v),
        lw=2,
        label=r"$\mu = \mu_k + (\mu_s - \mu_k)\,e^{-d|V_c|}$ (12)",
    )
    for value, name in ((p.mu_static, r"$\mu_s$"), (p.mu_kinetic, r"$\mu_k$")):
        ax.axhline(value, color="0.5", ls=":", lw=1)
        ax.annotate(f"{name} = {value:g}", (v[-1], value), ha="right", va="bottom")
    top = ax.secondary_xaxis(
        "top",
        functions=(
            lambda s: np.multiply(s, math.cos(p.helix_angle_rad) / p.radius_m),
            lambda w: np.multiply(w, p.radius_m / math.cos(p.helix_angle_rad)),
        ),
    )
    top.set_xlabel(r"rotation speed $\Omega = |V_c| \cos\beta / R$ [rad/s]")
    ax.set_xlabel(r"sliding speed $|V_c|$ [m/s]")
    ax.set_ylabel(r"friction coefficient $\mu$ [-]")
    ax.set_title(f"Fig. 4: friction-velocity curve ($d$ = {p.friction_decay_s_m:g} s/m)")
    ax.grid(alpha=0.3)
    ax.legend()
    return fig


def plot_transient(
    run: TransientResult, analysis: TransientAnalysis, *, title: str = "", fig: Figure | None = None
) -> Figure:
    """Three panels of a nonlinear run: the amplitude (log) with the fitted linear growth, the
    surface velocity at the nut, the spectrogram of its tangential component.

    Parameters
    ----------
    run : TransientResult
        The run (`nonlinear.transient.simulate`).
    analysis : TransientAnalysis
        Its analysis (`nonlinear.transient_analysis.analyse`).
    title : str
        The title of the top panel.
    fig : Figure, optional
        The figure to draw the panels into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    t, fit = run.time_s, analysis.linear_fit
    fig = fig if fig is not None else new_figure(figsize=(8, 8.5), layout="constrained")
    ax = fig.subplots(3, 1, sharex=True)
    ax[0].semilogy(t, analysis.amplitude, color="k", lw=1, label="modal energy norm a(t)")
    inside = (t >= fit.start_s) & (t <= fit.end_s)
    mid = np.argmin(np.abs(t - (fit.start_s + fit.end_s) / 2))
    ax[0].semilogy(
        t[inside],
        analysis.amplitude[mid] * np.exp(fit.growth_rate * (t[inside] - t[mid])),
        color="tab:red",
        lw=3,
        alpha=0.6,
        label=f"fit: {fit.mode} {fit.frequency_hz:.1f} Hz, growth {fit.growth_rate:+.1f} 1/s",
    )
    ax[0].set_ylabel(r"modal energy norm $a = \sqrt{2E}$ [$\sqrt{\mathrm{J}}$]")
    ax[0].legend(loc="lower right")
    ax[0].set_title(title)
    v = run.surface_velocity_m_s
    ax[1].plot(t, v[:, 1], lw=0.5, label="tangential")
    ax[1].plot(t, v[:, 0], lw=0.5, label="radial")
    ax[1].set_ylabel("surface velocity at nut [m/s]")
    ax[2].set_title("spectrogram of the tangential surface velocity at the nut", fontsize=10)
    ax[1].legend(loc="lower right")
    rate = 1 / (t[1] - t[0])
    nfft = 1 << max(8, int(math.log2(rate * 2e-3)))
    image = ax[2].specgram(
        v[:, 1], NFFT=nfft, Fs=rate, noverlap=nfft // 2, cmap="magma", scale="dB", mode="magnitude"
    )[3]
    fig.colorbar(image, ax=ax[2], label="tangential velocity [dB re 1 m/s]")
    ax[2].set_ylim(0, min(rate / 2, 20000))
    ax[2].set_ylabel("frequency [Hz]")
    ax[2].set_xlabel("time [s]")
    return fig


SQUEAK_COLOR = "orange"
WARN_COLOR, ERROR_COLOR = "goldenrod", "tab:red"


def _held(last: np.ndarray, count: np.ndarray) -> np.ndarray:
    """`last` with empty bins (count 0) holding the previous bin's value, as a published
    value holds until the next one."""
    idx = np.where(count > 0, np.arange(count.size), 0)
    np.maximum.accumulate(idx, out=idx)
    out = last[idx]
    out[: np.argmax(count > 0) if count.any() else count.size] = np.nan
    return out


def _filled(
    lo: np.ndarray, hi: np.ndarray, last: np.ndarray, count: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A binned series' (lo, hi) with empty bins holding the last value before them (`_held`),
    so that a log sampled more sparsely than the bins is drawn as a line, not as dots."""
    held = _held(last, count)
    empty = count[:, None] == 0
    return np.where(empty, held, lo), np.fmax(np.where(empty, held, hi), held)


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True."""
    edges = np.diff(np.r_[0, flags.astype(np.int8), 0])
    return list(
        zip(
            np.flatnonzero(edges == 1).tolist(),
            (np.flatnonzero(edges == -1) - 1).tolist(),
            strict=True,
        )
    )


def _probability_panel(result: ReplayResult, axes: Sequence[Axes]) -> None:
    """P(squeak) over time on the last of `axes`, with the WARN and ERROR probabilities
    (dashed) and, where P was at or above one, the area from 0 up to it tinted; squeak at the
    nominal parameters shaded on all of `axes`."""
    from matplotlib.lines import Line2D

    ax = axes[-1]
    envelope = result.plot_data.probability
    t, lo, hi, last, count = envelope.series()
    lo, hi = _filled(lo, hi, last, count)
    half = envelope.bin_s / 2
    thresholds = (
        (result.warn_probability, "WARN", WARN_COLOR),
        (result.error_probability, "ERROR", ERROR_COLOR),
    )
    ylim = (0.0, 1.05)
    handles: list[Artist] = []
    if t.size:
        ax.fill_between(
            t, lo[:, 0], hi[:, 0], step="mid", color="tab:blue", edgecolor="tab:blue", lw=0.8
        )  # a curve drawn as its min-max band per bin: a line in the legend
        handles.append(Line2D([], [], color="tab:blue", lw=1.5, label="P(squeak)"))
        for k, (a, b) in enumerate(_runs(np.nan_to_num(hi[:, 1]) > 0)):
            for other in axes:
                span = other.axvspan(
                    t[a] - half,
                    t[b] + half,
                    color=SQUEAK_COLOR,
                    alpha=0.3,
                    lw=0,
                    label="squeak (nominal)",
                )
            handles += [span] if k == 0 else []
        for (level, name, color), hatch in zip(thresholds, ("////", "\\\\\\\\"), strict=True):
            for k, (a, b) in enumerate(_runs(np.nan_to_num(hi[:, 0], nan=-1.0) >= level)):
                span = ax.axvspan(
                    t[a] - half,
                    t[b] + half,
                    0.0,
                    level / ylim[1],
                    facecolor="none",
                    edgecolor=color,
                    hatch=hatch,
                    lw=0,
                    label=f"P >= {name}",
                )
                handles += [span] if k == 0 else []
    for level, name, color in thresholds:
        handles.append(ax.axhline(level, color=color, ls="--", lw=1.0, label=f"{name} {level:g}"))
    pt = result.probability
    if pt.peak is not None:
        assert pt.peak_t_s is not None  # set with the peak
        handles += ax.plot([pt.peak_t_s], [pt.peak], "v", color="k", ms=5, label="peak")
    ax.set_ylim(*ylim)
    ax.set_yticks([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    ax.set_ylabel("P(squeak) [-]")
    ax.set_title(result.probability_text(), fontsize=9)
    ax.legend(handles=handles, loc="center left", bbox_to_anchor=(1.005, 0.5), fontsize=8)
    ax.set_xlabel("time since the log's first message [s]")


HEARD_COLOR = "deepskyblue"  # apart from the grey level and the plasma P(squeak) colours
_HEARD_MARKED = 500  # heard episodes drawn (the first ones)


def _edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges around increasing centres (half-way between them, mirrored at the ends)."""
    if centres.size == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    mid = (centres[1:] + centres[:-1]) / 2
    return np.r_[2 * centres[0] - mid[0], mid, 2 * centres[-1] - mid[-1]]


def plot_heard(heard: Heard, *, ax: Axes | None = None) -> Figure:
    """The sound and the predictions: spectrogram (`listen.Spectrogram`, log frequency axis
    89 Hz - 11.2 kHz, the band maxima of bounded frames), the predicted squeak frequencies over
    it coloured by P(squeak), the heard episodes marked at their frequency (a line) over their
    time span (shaded over the whole height: no mark that could read as a tone). The level's
    and P(squeak)'s colourbars are stacked on the right, apart.

    Parameters
    ----------
    heard : Heard
        What the replay heard (`ReplayResult.heard`).
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    fig, ax = _axes(ax, figsize=(10, 3.2), layout="constrained")
    handles = _spectrogram(fig, ax, heard.spectrogram, heard.scale)
    pts = heard.squeak_points
    if len(pts):
        sc = ax.scatter(
            pts[:, 0],
            pts[:, 1],
            c=np.nan_to_num(pts[:, 2]),
            s=5,
            cmap="plasma",
            vmin=0.0,
            vmax=1.0,
            lw=0,
            label="predicted squeak modes",
        )
        handles.append(sc)
        fig.colorbar(sc, cax=ax.inset_axes((1.01, 0.0, 0.015, 0.44)), label="P(squeak) [-]")
    handles += _episodes(ax, heard.detection.episodes)
    ax.set_xlabel("time since the log's first message [s]")
    ax.set_title(heard.text()[0], fontsize=9)
    if handles:
        ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.8)
    return fig


def _spectrogram(fig: Figure, ax: Axes, sg: Spectrogram, scale: str) -> list[Any]:
    """The spectrogram of a sound panel (grey, its colourbar in the upper right), the
    frequency axis (log, ECMA-418-1's range); returns the legend handles (none yet)."""
    from .listen import SPECTROGRAM_F_HZ

    if sg.times_s.size:
        level = np.ma.masked_invalid(sg.level_db.T)
        top = float(level.max()) if level.count() else 0.0
        mesh = ax.pcolormesh(
            _edges(sg.times_s),
            sg.edges_hz,
            level,
            cmap="gray_r",
            vmin=top - 80.0,
            vmax=top,
            shading="flat",
            rasterized=True,
        )
        unit = "Pa" if scale == "Pa" else "FS"
        fig.colorbar(
            mesh, cax=ax.inset_axes((1.01, 0.56, 0.015, 0.44)), label=f"PSD [dB re {unit}²/Hz]"
        )
    ax.set_yscale("log")
    ax.set_ylim(*SPECTROGRAM_F_HZ)
    ax.set_ylabel("frequency [Hz]")
    return []


def _episodes(ax: Axes, episodes: Sequence[Any]) -> list[Any]:
    """The heard episodes (the first `_HEARD_MARKED`): a line at the frequency, the span
    shaded; returns their legend handles."""
    handles: list[Any] = []
    for k, e in enumerate(episodes[:_HEARD_MARKED]):
        line = ax.hlines(
            e.frequency_hz,
            e.start_s,
            e.end_s,
            colors=HEARD_COLOR,
            lw=3,
            label="heard episode: frequency",
        )
        span = ax.axvspan(
            e.start_s, e.end_s, color=HEARD_COLOR, alpha=0.2, lw=0, label="heard episode: time"
        )
        handles += [line, span] if k == 0 else []
    return handles


def plot_listened(listened: Listened, *, ax: Axes | None = None) -> Figure:
    """A recording without a log (`recording.listen_recording`): its spectrogram with the
    heard squeak episodes (as `plot_heard`), the background tones (dashed, over the whole
    recording) and, with a speed, the drive orders heard (ratio x |speed| / 2 pi, dotted).

    Parameters
    ----------
    listened : Listened
        What `listen` heard.
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    fig, ax = _axes(ax, figsize=(10, 3.6), layout="constrained")
    handles = _spectrogram(fig, ax, listened.spectrogram, listened.scale)
    d = listened.detection
    t = listened.spectrogram.times_s
    span = (float(t[0]), float(t[-1])) if t.size else (0.0, listened.duration_s)
    for k, tone in enumerate(d.background):
        line = ax.hlines(
            tone.frequency_hz,
            *span,
            colors="tab:green",
            lw=1.5,
            linestyles="--",
            label=f"background tone ({d.background_source})",
        )
        handles += [line] if k == 0 else []
    if listened.speed is not None and d.drive_orders:
        st, sv = listened.speed
        f1 = np.where(np.abs(sv) > 0, np.abs(sv) / (2 * np.pi), np.nan)  # none at rest
        for k, order in enumerate(d.drive_orders):
            (drawn,) = ax.plot(
                st,
                order.ratio * f1,
                color="tab:orange",
                lw=1.2,
                ls=":",
                label="drive order (ratio x speed)",
            )
            handles += [drawn] if k == 0 else []
    handles += _episodes(ax, d.episodes)
    ax.set_xlabel("time since the recording's first sample [s]")
    ax.set_title(listened.text()[0], fontsize=9)
    if handles:
        ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.8)
    return fig


def plot_timeline(result: ReplayResult, *, fig: Figure | None = None) -> Figure:
    """A replay over time: speed (with the squeak guard's raw and guarded command when the log
    has them, `review.commands`), load, nut position (only when the log has a nut input) and
    P(squeak), squeak at the nominal parameters shaded; the P(squeak) panel has the WARN and
    ERROR probabilities as dashed lines, bars under the curve where P was at or above them and
    the peak marked. Drawn from the replay's binned series (min-max band per bin). With sound,
    a `plot_heard` panel above P(squeak).

    Parameters
    ----------
    result : ReplayResult
        The replay (`review.replay.replay`).
    fig : Figure, optional
        The figure to draw the panels into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    tl = result.timeline
    t, lo, hi, last, count = tl.trace.series()
    lo, hi = _filled(lo, hi, last, count)  # an input value holds until the next
    panels = [(0, "speed [rad/s]", 1.0), (1, "axial load [N]", 1.0)]
    if tl.nut_measured:
        panels.append((2, "nut position [mm]", 1e3))
    heard = result.heard
    rows = len(panels) + 1 + (heard is not None)
    if fig is None:
        fig = new_figure(
            figsize=(10, 2.1 * rows + 0.2 + (1.0 if heard else 0.0)), layout="constrained"
        )
    axes = list(
        fig.subplots(
            rows,
            1,
            sharex=True,
            height_ratios=[1] * len(panels) + [1.6] * (heard is not None) + [1],
        )
    )
    for ax, (k, label, factor) in zip(axes, panels, strict=False):
        ax.fill_between(
            t,
            lo[:, k] * factor,
            hi[:, k] * factor,
            step="mid",
            color="tab:blue",
            edgecolor="tab:blue",
            lw=0.7,
        )
        ax.set_ylabel(label)
    if result.commands is not None:  # the guard's command over the motor's speed
        _commands(result.commands, axes[0])
    if heard is not None:
        sound = axes.pop(-2)
        plot_heard(heard, ax=sound)
        sound.set_xlabel("")
    _probability_panel(result, axes)
    for ax in axes:
        ax.grid(alpha=0.3)
    nut = (
        ""
        if tl.nut_measured
        else (f"; no nut input: model nut at {tl.nut * 1e3:.0f} mm (parameter nut_position_m)")
    )
    axes[0].set_title(
        f"Replay of {result.log.name}: {result.episode_count} squeak episodes "
        f"(shaded), {result.time_in_squeak_s:.1f} s in squeak{nut}",
        fontsize=10,
    )
    return fig


def _commands(commands: CommandTrace, ax: Axes) -> None:
    """The raw and the guarded speed command as lines (each bin's last value, held) over the
    speed panel, with a legend."""
    for topic, color, style in (
        (SPEED_COMMAND, "0.3", "--"),
        (SPEED_COMMAND_GUARDED, "tab:orange", "-"),
    ):
        envelope = commands.envelopes.get(topic)
        if envelope is None:
            continue
        t, lo, hi, last, count = envelope.series()
        ax.plot(t, _held(last, count)[:, 0], color=color, ls=style, lw=1.0, label=LABELS[topic])
    ax.plot([], [], color="tab:blue", lw=4, label="motor speed (min-max per bin)")
    ax.legend(loc="upper right", fontsize=8)


_NAMED_BARS = 40  # up to this many logs the time-in-squeak panel names each one


def plot_fleet(run: FleetRun, *, fig: Figure | None = None) -> Figure:
    """Four panels of a fleet's squeak: share of logs that squeak, squeak frequencies, time in
    squeak per log, where in speed x load the fleet squeaked; when logs have sound, two more:
    heard vs predicted squeak time per log, and heard against predicted frequencies.

    Parameters
    ----------
    run : FleetRun
        The review (`review.fleet.review_logs`).
    fig : Figure, optional
        The figure to draw the panels into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    from matplotlib.ticker import MaxNLocator

    ok = [r for r in run.rows if r["status"] == "ok"]
    squeaks = [r for r in ok if r["episodes"]]
    heard = [r for r in ok if r.get("heard_s") is not None]
    fig = (
        fig
        if fig is not None
        else new_figure(figsize=(12, 12.5 if heard else 8.5), layout="constrained")
    )
    panels = fig.subplots(3 if heard else 2, 2)
    (a, b), (c, d) = panels[:2]
    if heard:
        _heard_panels(heard, *panels[2])
    counts = [len(squeaks), len(ok) - len(squeaks), run.failed]
    bars = a.bar(["squeak", "no squeak", "error"], counts, color=["C3", "C2", ERROR_GREY])
    # shares of all logs, as the title counts them
    a.bar_label(bars, [f"{n} ({100 * n / max(len(run.rows), 1):.0f} %)" for n in counts])
    a.set_ylabel("number of logs [-]")
    a.yaxis.set_major_locator(MaxNLocator(integer=True))
    a.set_title(f"{len(squeaks)} of {_counted(len(run.rows), 'log')} squeak")
    pts = np.array(run.points, dtype=float).reshape(-1, 3)
    if len(pts):
        b.hist(pts[:, 2], bins=min(50, max(5, len(pts) // 20)), color="C3")
    b.set_xlabel("squeak frequency [Hz]")
    b.set_ylabel("number of predictions (sample) [-]")
    b.set_title("squeak frequencies over the fleet")
    ranked = sorted(ok, key=lambda r: -r["time_in_squeak_s"])
    times = [r["time_in_squeak_s"] for r in ranked]
    errors = [r for r in run.rows if r["status"] != "ok"]
    if len(ranked) + len(errors) <= _NAMED_BARS:
        # error logs at the bottom, with no bar: no time in squeak is known for them
        labels = [str(r.get("unit_id", r.get("name", "?"))) for r in ranked + errors]
        c.barh(labels[::-1], ([0.0] * len(errors) + times[::-1]), color="C3")
        for k in range(len(errors)):
            c.text(0, len(errors) - 1 - k, " error", va="center", color=ERROR_GREY, fontsize=8)
        c.tick_params(axis="y", labelsize=8)
        c.set_xlabel("time in squeak [s]")
        c.set_ylabel("log (unit id)")
    else:
        c.plot(np.arange(1, len(times) + 1), times, color="C3")
        c.xaxis.set_major_locator(MaxNLocator(integer=True))
        c.set_xlabel(
            "rank of the log [-]"
            + (f" ({_counted(len(errors), 'error')} not shown)" if errors else "")
        )
        c.set_ylabel("time in squeak [s]")
    c.set_title("time in squeak per log")
    if len(pts):
        sc = d.scatter(np.abs(pts[:, 0]), np.abs(pts[:, 1]), c=pts[:, 2], s=6, cmap="viridis")
        fig.colorbar(sc, ax=d, label="squeak frequency [Hz]")
    d.set_xlabel(r"rotation speed $|\Omega|$ [rad/s]")
    d.set_ylabel("axial load $|F_z|$ [N]")
    d.set_title("where the fleet squeaked (sample of predictions)")
    fig.suptitle(f"fleet review: {_counted(len(run.rows), 'log')}, {_counted(run.failed, 'error')}")
    return fig


def _counted(n: int, noun: str) -> str:
    """'1 log', '5 logs', '0 errors'."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _heard_panels(rows: list[dict], e: Axes, f: Axes) -> None:
    """Heard vs predicted squeak time per log (`e`) and the logs' heard and predicted squeak
    frequencies (`f`)."""
    from matplotlib.ticker import MaxNLocator, NullFormatter

    predicted = np.array([r["time_in_squeak_s"] for r in rows], float)
    heard = np.array([r["heard_s"] for r in rows], float)
    e.scatter(predicted, heard, s=14, color="C0")
    top = max(float(predicted.max(initial=0.0)), float(heard.max(initial=0.0)), 1e-3) * 1.05
    e.plot([0, top], [0, top], color="0.5", ls="--", lw=1, label="heard = predicted")
    if len(rows) <= _NAMED_BARS:
        for r, x, y in zip(rows, predicted, heard, strict=True):
            e.annotate(r["unit_id"], (x, y), fontsize=8, xytext=(2, 2), textcoords="offset points")
    e.set_xlabel("predicted squeak time [s]")
    e.set_ylabel("heard squeak time [s]")
    e.legend(fontsize=8)
    e.set_title(f"heard vs predicted squeak per log ({len(rows)} logs with sound)")
    heard_hz = [hz for r in rows for hz in r["heard_frequencies_hz"] or []]
    predicted_hz = [hz for r in rows for hz in r["squeak_frequencies_hz"] or []]
    values = [v for v in heard_hz + predicted_hz if v > 0]
    if values:
        bins = np.geomspace(min(values) / 1.05, max(values) * 1.05, 40).tolist()
        f.hist(
            [predicted_hz, heard_hz],
            bins=bins,
            color=["C3", "C0"],
            label=["predicted (per log, per mode)", "heard (per log)"],
        )
        f.set_xscale("log")
        f.xaxis.set_minor_formatter(NullFormatter())  # labelled minor ticks overlap
        f.legend(fontsize=8)
    f.set_xlabel("squeak frequency [Hz]")
    f.set_ylabel("number of logs [-]")
    f.yaxis.set_major_locator(MaxNLocator(integer=True))
    f.set_title("heard against predicted squeak frequencies")


# ----------------------------------------------------------------------------- calibration
_FOREST_UNITS = 60  # units drawn in a posterior panel (the first ones)


def _unit_samples(post: Any, name: str) -> np.ndarray | None:
    """A posterior's samples of `name` (friction_drop: mu_static - mu_kinetic)."""
    names = list(post.names)
    if name in names:
        return post.samples[:, names.index(name)]
    if name == "friction_drop" and {"mu_static", "mu_kinetic"} <= set(names):
        return (
            post.samples[:, names.index("mu_static")] - post.samples[:, names.index("mu_kinetic")]
        )
    return None


def _unit_of(name: str) -> str:
    """The unit of a calibrated parameter (or friction_drop) in an axis label: '-' for a
    dimensionless one."""
    unit = "1" if name == "friction_drop" else field_info(name)["unit"]
    return "-" if unit in ("", "1") else unit


def _population_samples(
    params: Any, scatter: dict[str, float], names: Sequence[str], count: int = 4096
) -> dict[str, np.ndarray]:
    """Draws of a population of units (nominal `params`, `scatter`) for `names`, with
    friction_drop; a name without scatter is its nominal value."""
    from ..model.uncertainty.scatter import Scatter, draw

    values = draw(params, Scatter({n: scatter.get(n, 0.0) for n in names}), count).values
    out = {
        n: values[n].ravel() if n in values else np.full(count, float(getattr(params, n)))
        for n in names
    }
    if {"mu_static", "mu_kinetic"} <= set(out):
        out["friction_drop"] = out["mu_static"] - out["mu_kinetic"]
    return out


def plot_posteriors(
    result: Any, name: str, *, legend: bool = True, ax: Axes | None = None
) -> Figure:
    """The units' posterior marginals of one calibrated parameter (or friction_drop): mean and
    90 % interval per unit (held-out units hollow), the fleet mean's 90 % interval shaded, the
    prior's nominal value dashed.

    Parameters
    ----------
    result : CalibrationResult
        The calibration (`review.calibration.run.calibrate`).
    name : str
        A calibrated parameter, or 'friction_drop'.
    legend : bool
        Draw the legend on the axes (else the caller draws it from the axes' legend handles:
        the kinds of unit, the fleet mean, the prior).
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    fig, ax = _axes(ax, figsize=(4, 5), layout="constrained")
    run = result.run
    rows: list[tuple[Any, np.ndarray]] = []
    for u in run.units:
        s = None if u.reported is None else _unit_samples(u.reported, name)
        if s is not None and len(rows) < _FOREST_UNITS:
            rows.append((u, s))
    kinds: set[str] = set()
    for k, (u, s) in enumerate(rows):
        lo, hi = np.quantile(s, [0.05, 0.95])
        colour = "C0" if u.calibrated else "0.6"
        hollow = "white" if u.held_out else colour
        ax.hlines(k, lo, hi, color=colour, lw=1.5)
        ax.plot(s.mean(), k, "o", ms=4, color=colour, mfc=hollow, mew=1.2)
        kind = ("held-out unit" if u.held_out else "unit") + (
            "" if u.calibrated else " (not calibrated)"
        )
        if kind not in kinds:  # a legend entry of each kind: marker and interval
            kinds.add(kind)
            ax.errorbar([], [], xerr=[], fmt="o", ms=4, color=colour, mfc=hollow, label=kind)
    ax.set_yticks(range(len(rows)), [u.unit_id for u, _ in rows], fontsize=8)
    ax.invert_yaxis()
    pop = run.population.summary().get(name) if run.population is not None else None
    if pop is not None:
        m = pop["mean"]
        ax.axvspan(m["q05"], m["q95"], color="C1", alpha=0.25, lw=0, label="fleet mean, 90 %")
    prior = _population_samples(run.prior.params, dict(run.prior.scatter), result.settings.names)
    if name in prior:
        ax.axvline(float(np.median(prior[name])), color="0.3", ls="--", lw=1, label="prior")
    ax.set_xlabel(f"{name} [{_unit_of(name)}]")
    ax.set_title(f"{name}: units' mean, 90 %", fontsize=9)
    if legend:
        ax.legend(fontsize=8, loc="lower right")
    return fig


def plot_population(result: Any, name: str, *, ax: Axes | None = None) -> Figure:
    """The prior's unit-to-unit distribution of one parameter (or friction_drop) against the
    calibrated fleet population's (`Population.params_and_scatter`), as densities of draws.

    Parameters
    ----------
    result : CalibrationResult
        The calibration.
    name : str
        A calibrated parameter, or 'friction_drop'.
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    fig, ax = _axes(ax, figsize=(4, 3), layout="constrained")
    run, names = result.run, result.settings.names
    curves = [("prior", "0.3", run.prior.params, dict(run.prior.scatter))]
    if run.params is not None and run.scatter is not None:
        curves.append(("fleet (calibrated)", "C1", run.params, dict(run.scatter.sd)))
    drawn = [(label, c, _population_samples(p, s, names)) for label, c, p, s in curves]
    values = np.concatenate([d[name] for _, _, d in drawn if name in d])
    if values.size and np.ptp(values) > 0:
        lo, hi = np.quantile(values, [0.001, 0.999]).tolist()
        bins = np.linspace(lo, hi, 60).tolist()
        for label, colour, d in drawn:
            ax.hist(d[name], bins=bins, density=True, histtype="step", color=colour, label=label)
    unit = _unit_of(name)
    ax.set_xlabel(f"{name} [{unit}]")
    ax.set_ylabel("density [-]" if unit == "-" else f"density [1/({unit})]")
    ax.set_title(f"{name}: prior vs fleet", fontsize=9)
    ax.legend(fontsize=8)
    return fig


def plot_reliability(result: Any, *, ax: Axes | None = None) -> Figure:
    """The held-out reliability curve: predicted P(squeak) against the share of frames heard,
    in bins of P, with the prior and with the calibrated population (marker area by frames),
    the diagonal of a perfect forecast.

    Parameters
    ----------
    result : CalibrationResult
        The calibration.
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    fig, ax = _axes(ax, figsize=(4.5, 4.5), layout="constrained")
    h = result.run.held_out
    ax.plot([0, 1], [0, 1], color="0.6", ls="--", lw=1, label="perfect")
    curves = h.reliability(result.settings.reliability_bins)
    total = max(h.frames, 1)
    for key, colour, brier in (
        ("prior", "0.3", h.brier_prior),
        ("calibrated", "C1", h.brier_calibrated),
    ):
        rows = curves[key]
        if not rows:
            continue
        p = [r["p"] for r in rows]
        f = [r["heard"] for r in rows]
        size = [20 + 400 * r["frames"] / total for r in rows]
        ax.plot(p, f, color=colour, lw=1, marker="o", ms=5, label=f"{key} (Brier {brier:.3f})")
        ax.scatter(p, f, s=size, color=colour, zorder=3)  # area: the bin's frames
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("predicted P(squeak) [-]")
    ax.set_ylabel("share of frames heard [-]")
    ax.set_title(
        f"held-out reliability ({_counted(len(h.units), 'unit')}, {h.frames} frames)", fontsize=9
    )
    ax.legend(fontsize=8, loc="best", title="marker area: frames", title_fontsize=8)
    return fig


def plot_calibration(result: Any, *, fig: Figure | None = None) -> Figure:
    """calibration.png: per calibrated parameter and friction_drop the units' posteriors
    (`plot_posteriors`) over the prior against the fleet (`plot_population`), and the
    held-out reliability curve (`plot_reliability`).

    Parameters
    ----------
    result : CalibrationResult
        The calibration (`review.calibration.run.calibrate`).
    fig : Figure, optional
        The figure to draw the panels into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    names = [*result.settings.names]
    if {"mu_static", "mu_kinetic"} <= set(names):
        names.append("friction_drop")
    n = len(names)
    rows = min(max(len(result.run.units), 4), _FOREST_UNITS)
    fig = (
        fig
        if fig is not None
        else new_figure(figsize=(3.2 * n, 3.2 + 0.12 * rows + 6.5), layout="constrained")
    )
    grid = fig.add_gridspec(3, n, height_ratios=[1.5 + 0.05 * rows, 1.0, 1.6])
    for k, name in enumerate(names):
        plot_posteriors(result, name, legend=False, ax=(top := fig.add_subplot(grid[0, k])))
        plot_population(result, name, ax=fig.add_subplot(grid[1, k]))
        if k == 0:  # the posteriors' legend, once, below the panels: no interval hidden under it
            handles, labels = top.get_legend_handles_labels()
            fig.legend(handles, labels, loc="outside lower center", ncols=len(labels), fontsize=8)
    half = max(n // 2, 1)
    plot_reliability(result, ax=fig.add_subplot(grid[2, :half]))
    if n > half:
        _held_out_panel(result, fig.add_subplot(grid[2, half:]))
    run = result.run
    comparison = result.comparison
    fig.suptitle(
        f"calibration: {len(run.units)} units, formulation {run.formulation}"
        + (
            f" (supported {comparison.strength})"
            if comparison is not None and comparison.supported
            else ""
        )
    )
    return fig


def _held_out_panel(result: Any, ax: Axes) -> None:
    """The held-out units' Brier scores, prior against calibrated (with both formulations,
    each formulation's calibrated score)."""
    runs = result.runs
    units = result.run.held_out.units
    series = [("prior", "0.3", {u: v[0] for u, v in result.run.held_out.per_unit.items()})]
    for name, run in runs.items():
        label = f"calibrated ({name})" if len(runs) > 1 else "calibrated"
        colour = "C1" if name == result.chosen else "C0"
        series.append((label, colour, {u: v[1] for u, v in run.held_out.per_unit.items()}))
    width = 0.8 / len(series)
    x = np.arange(len(units))
    few = len(units) * len(series) <= 12  # the values are written on the bars
    for k, (label, colour, scores) in enumerate(series):
        bars = ax.bar(
            x + (k - (len(series) - 1) / 2) * width,
            [scores.get(u, np.nan) for u in units],
            width,
            color=colour,
            label=label,
        )
        if few:
            ax.bar_label(bars, fmt="%.3f", fontsize=8)
    turn = len(units) > 3
    ax.set_xticks(
        x, units, fontsize=8, rotation=30 if turn else 0, ha="right" if turn else "center"
    )
    ax.margins(y=0.15)
    ax.set_ylabel("Brier score [-]")
    ax.set_title("held-out units: Brier score (lower is better)", fontsize=9)
    ax.legend(fontsize=8)


def plot_guard(run: GuardRun, *, title: str = "", fig: Figure | None = None) -> Figure:
    """Two panels of the guard applied to a command (`review.guard.apply_guard`): the raw and
    the guarded speed with the squeak (P >= p_max) of each shaded, and P(squeak) along both.

    Parameters
    ----------
    run : GuardRun
        The command, its guarded version and P along both.
    title : str
        The title of the top panel.
    fig : Figure, optional
        The figure to draw the panels into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    t, p_max = run.command.time_s, run.settings.p_max
    fig = fig if fig is not None else new_figure(figsize=(8, 6), layout="constrained")
    ax = fig.subplots(2, 1, sharex=True)
    lines = (
        ("raw command", run.command.speed_rad_s, run.p_raw, "0.45", "--"),
        ("guarded command", run.guarded_rad_s, run.p_guarded, "tab:blue", "-"),
    )
    for label, speed, p, color, style in lines:
        ax[0].plot(t, speed, color=color, ls=style, lw=1.5, label=label)
        squeak = p >= p_max
        ax[0].fill_between(
            t,
            0,
            speed,
            where=squeak,
            color=SQUEAK_COLOR if color != "0.45" else "0.8",
            step="post",
            alpha=0.6,
            label=f"{label}: P(squeak) >= {p_max:g}",
        )
        ax[1].plot(t, p, color=color, ls=style, lw=1.2, label=label)
    ax[1].axhline(p_max, color="tab:red", lw=1, ls=":", label=f"p_max = {p_max:g}")
    ax[0].set_ylabel("speed command [rad/s]")
    ax[0].set_title(title)
    ax[0].legend(loc="upper right", fontsize=8)
    ax[1].set_ylabel("P(squeak) [-]")
    ax[1].set_ylim(-0.02, 1.02)
    ax[1].set_xlabel("time [s]")
    ax[1].legend(loc="upper right", fontsize=8)
    return fig


def plot_amplitude(
    likelihood: AmplitudeLikelihood,
    theta: np.ndarray,
    log_weight: np.ndarray | None = None,
    *,
    ax: Axes | None = None,
) -> Figure:
    """One unit's heard frames with the observation model's squeak amplitude over them
    (`model.calibration.amplitude`): the log-amplitude over the floor along the frames at the
    parameters `theta`, for the grid cell (detection threshold h, floor depth) of largest
    weight, h as a line, the heard frames shaded; the line is left blank where the model does
    not hold (the drive standing).

    Parameters
    ----------
    likelihood : AmplitudeLikelihood
        The unit's likelihood (its observations).
    theta : numpy.ndarray
        (D,) the parameters, in the order of `likelihood.names`.
    log_weight : numpy.ndarray, optional
        (Kd, Kh) the grid's weights (the bench's posterior); the likelihood's when None.
    ax : Axes, optional
        The axes to draw into; default: a new figure.

    Returns
    -------
    Figure
        The figure drawn into.
    """
    fig, ax = _axes(ax, figsize=(10, 3.0), layout="constrained")
    weight = likelihood.log_weight if log_weight is None else log_weight
    d, k = np.unravel_index(int(np.argmax(weight)), weight.shape)
    db = 1.0 / NP_PER_DB
    depth, h = float(likelihood.depth_np[d]), float(likelihood.threshold_np[k])
    a, hearable = likelihood.amplitude(np.asarray(theta, float)[None, :], depth, every=True)
    frames = np.flatnonzero(likelihood.obs.sequence >= 0)
    t = frames * likelihood.obs.frame_s
    gap = np.r_[False, np.diff(frames) > 1]  # break the line where the model does not hold
    line = np.where(hearable[0], a[0] * db, np.nan)
    ax.plot(
        np.insert(t, np.flatnonzero(gap), np.nan),
        np.insert(line, np.flatnonzero(gap), np.nan),
        color="C3",
        lw=1.4,
        label="model: squeak level over its floor (mode in the band)",
    )
    heard = likelihood.obs.frame_heard[frames]
    for first, last in _runs(heard):
        ax.axvspan(t[first], t[last], color="C0", alpha=0.25, lw=0)
    ax.axhline(h * db, color="k", ls="--", lw=1, label=f"detection threshold h = {h * db:.0f} dB")
    ax.axhline(depth * db, color="0.5", ls=":", lw=1, label=f"limit cycle {depth * db:.0f} dB")
    ax.fill_between([], [], color="C0", alpha=0.25, label="heard frames")
    ax.set_ylim(-0.35 * depth * db, depth * db * 1.08)
    ax.set_xlabel("time since the unit's first frame [s]")
    ax.set_ylabel("level over the floor [dB]")
    ax.set_title(f"unit {likelihood.obs.unit_id}: heard frames and the model's squeak", fontsize=9)
    ax.legend(loc="lower center", ncol=4, fontsize=7, framealpha=0.9)
    return fig
