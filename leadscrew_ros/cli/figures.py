# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak figures`: the paper's Figs. 4-11 with a computed summary, Fig. 7 again with
the P(squeak) band around its boundary (fig07p); and the sweep plot.

The plots are `review.plots`' (`plot_sweep` is shared with `sweep --plot`, `plot_map` with
`map --plot` and the replay report); this module computes, calls and saves. `make_figures`
writes fig04..fig11 and fig07p PNGs and `summary.txt`, whose sentences are computed from the
plotted data (nothing is hard-coded). Importing this module does not import matplotlib
(`map --json`).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property, partial
from pathlib import Path

import numpy as np

from ..model.physics.friction import friction_coefficient, friction_slope, sliding_speed
from ..model.physics.parameters import ScrewParameters
from ..model.squeak_model import SqueakModel
from ..model.studies.fields import REFERENCE_SPEED_RAD_S, _native
from ..model.studies.stability_map import MapResult, stability_map
from ..model.studies.sweep import SweepResult, probability_crossings, sweep
from ..model.studies.tracking import Branch, track_modes
from ..model.studies.work import Work, map_work, sweep_work
from ..review.plots import (
    at,
    fixed_text,
    fmt,
    plot_frequencies,
    plot_friction,
    plot_map,
    plot_sweep,
    probability_overlay,
)
from ..review.progress import progress_bar
from .args import WORK_LIMITS, Parser, build_model, output_directory

# --------------------------------------------------------------------------- data summaries
BOUNDARY, VALIDITY, GRID = "boundary", "validity", "grid"


@dataclass(frozen=True)
class Limit:
    """Where the model's validity ends along an axis (NaN: not known, e.g. a load axis)."""

    value: float = math.nan
    name: str = ""


@dataclass(frozen=True)
class Edge:
    """One end of a squeak band on a grid line. BOUNDARY: a root refined between a stable and
    an unstable valid grid point; VALIDITY: the last unstable grid point before the model stops
    being valid (`limit` says where it stops; the band may reach it); GRID: the unstable end of
    the grid (squeak may continue beyond it)."""

    value: float
    kind: str
    limit: Limit = Limit()

    def text(self, axis: str, upper: bool) -> str:
        """The edge as text on axis `axis`; `upper`: the band's upper end."""
        value = fmt(axis, self.value)
        if self.kind == BOUNDARY:
            return value
        if self.kind == GRID:
            return f"{'>=' if upper else '<='} {value} (grid edge)"
        where = (
            f"; validity ends at {self.limit.name} {fmt(axis, self.limit.value)}"
            if math.isfinite(self.limit.value)
            else ""
        )
        return f"{value} ({'last' if upper else 'first'} valid grid point{where})"


Band = tuple[Edge, Edge]


def band_text(axis: str, band: Band) -> str:
    """'1.8-423 rad/s', or with the kind of each end that is not a refined boundary."""
    lo, hi = band
    if lo.kind == hi.kind == BOUNDARY:
        return f"{fmt(axis, lo.value).split()[0]}-{fmt(axis, hi.value)}"
    return f"{lo.text(axis, False)} to {hi.text(axis, True)}"


def line_bands(
    values: np.ndarray,
    growth: np.ndarray,
    roots: Sequence[float],
    limits: Callable[[], tuple[Limit, Limit]] = lambda: (Limit(), Limit()),
) -> list[Band]:
    """Every squeak band of one grid line (growth NaN where the model is not valid), in order.
    `roots` are the refined sign changes on the line; `limits()` gives the lower and upper
    validity limits along the axis (called only when a band ends at an invalid point or at
    a grid end: a grid end at or beyond a limit is a VALIDITY edge)."""
    unstable, valid, n = np.nan_to_num(growth, nan=-1.0) > 0, np.isfinite(growth), len(values)
    known: list[tuple[Limit, Limit]] = []

    def limit(upper: bool) -> Limit:
        if not known:
            known.append(limits())
        return known[0][upper]

    def edge(i: int, upper: bool) -> Edge:
        j, v = i + (1 if upper else -1), float(values[i])
        if 0 <= j < n and valid[j]:
            a, b = sorted((float(values[j]), v))
            return Edge(next(r for r in roots if a <= r <= b), BOUNDARY)
        lim = limit(upper)
        beyond = 0 <= j < n or (v >= lim.value if upper else v <= lim.value)
        return Edge(v, VALIDITY, lim) if beyond else Edge(v, GRID)

    bands, i = [], 0
    while i < n:
        if unstable[i]:
            k = i
            while k + 1 < n and unstable[k + 1]:
                k += 1
            bands.append((edge(i, False), edge(k, True)))
            i = k
        i += 1
    return bands


def _speed_limits(params: ScrewParameters, axis: str, value: float) -> tuple[Limit, Limit]:
    """min_speed_rad_s and the first critical speed of the model at `axis` = `value`."""
    name = "axial_load_n" if axis == "load_n" else axis
    model = SqueakModel(params.with_(**{name: _native(name, value)}))
    return (
        Limit(params.min_speed_rad_s, "min_speed_rad_s"),
        Limit(model.critical_speed_rad_s, "the first critical speed"),
    )


def map_bands(result: MapResult, along: str, params: ScrewParameters) -> list[list[Band]]:
    """The squeak bands along `along` ('x' or 'y') on each grid line across it (each column
    for 'y', each row for 'x'); validity limits are known along a speed axis."""
    g, pts = result.field.max_growth_rate, result.boundary
    axis, values, across, lines = (
        (result.y_axis, result.y, result.x_axis, g.T)
        if along == "y"
        else (result.x_axis, result.x, result.y_axis, g)
    )
    out = []
    for k, v in enumerate((result.x if along == "y" else result.y).tolist()):
        roots = [p[1] if along == "y" else p[0] for p in pts if p[0 if along == "y" else 1] == v]
        limits: Callable[[], tuple[Limit, Limit]] = (
            partial(_speed_limits, params, across, v)
            if axis == "speed_rad_s"
            else (lambda: (Limit(), Limit()))
        )
        out.append(line_bands(values, lines[k], roots, limits))
    return out


def _bound(bands: list[Band], upper: bool) -> Edge | None:
    """The highest (upper) or lowest end of all the bands of a line; None if it is stable."""
    return (bands[-1][1] if upper else bands[0][0]) if bands else None


def _bound_text(axis: str, edge: Edge | None, upper: bool) -> str:
    return "none (no squeak)" if edge is None else edge.text(axis, upper)


def _bands_text(axis: str, bands: list[Band]) -> str:
    return " and ".join(band_text(axis, b) for b in bands) or "no squeak"


def _trend(
    what: str, bands: list[list[Band]], upper: bool, axis: str, x_axis: str, x: np.ndarray
) -> str:
    """'<what> falls from A at R = 2 mm to B at R = 10 mm'."""
    a, b = _bound(bands[0], upper), _bound(bands[-1], upper)
    verb = (
        "goes"
        if a is None or b is None
        else ("falls" if a.value > b.value else "rises" if a.value < b.value else "stays")
    )
    return (
        f"{what} {verb} from {_bound_text(axis, a, upper)} at {at(x_axis, x[0])} "
        f"to {_bound_text(axis, b, upper)} at {at(x_axis, x[-1])}"
    )


def _extreme(
    what: str,
    bands: list[list[Band]],
    upper: bool,
    largest: bool,
    axis: str,
    x_axis: str,
    x: np.ndarray,
    params: ScrewParameters,
) -> str:
    """'<what> is largest, A, at R = 2 mm' (with the nut centre for a nut-location axis)."""
    ends = np.array([math.nan if e is None else e.value for e in (_bound(b, upper) for b in bands)])
    if not np.isfinite(ends).any():
        return f"{what}: none on the grid (no squeak)"
    i = int(np.nanargmax(ends) if largest else np.nanargmin(ends))
    note = ""
    if x_axis == "nut_position_m":
        note = (
            f" (nut centre z_o + b/2 = {fmt(x_axis, x[i] + params.nut_length_m / 2)}; "
            f"screw centre L/2 = {fmt(x_axis, params.length_m / 2)})"
        )
    return (
        f"{what} is {'largest' if largest else 'smallest'}, "
        f"{_bound_text(axis, _bound(bands[i], upper), upper)}, at {at(x_axis, x[i])}{note}"
    )


def _ends(bands: list[list[Band]], axis: str, x_axis: str, x: np.ndarray) -> str:
    """Every band at both ends of the grid."""
    return (
        f"squeak bands at {at(x_axis, x[0])}: {_bands_text(axis, bands[0])}; "
        f"at {at(x_axis, x[-1])}: {_bands_text(axis, bands[-1])}"
    )


def _several(bands: list[list[Band]], axis: str, x_axis: str, x: np.ndarray) -> str:
    """Every band of every line that has more than one."""
    lines = [
        f"{at(x_axis, v)} ({_bands_text(axis, b)})"
        for v, b in zip(x, bands, strict=True)
        if len(b) > 1
    ]
    return ("more than one band at " + ", ".join(lines)) if lines else "one band at most per line"


def _peak(result: MapResult) -> str:
    g = result.field.max_growth_rate
    if not np.isfinite(g).any():
        return "no valid point on the grid"
    j, i = np.unravel_index(np.nanargmax(g), g.shape)
    frac = np.mean(g[np.isfinite(g)] > 0)
    return (
        f"{100 * frac:.0f} % of the valid grid squeaks, most unstable grid point "
        f"{at(result.x_axis, result.x[i])}, {at(result.y_axis, result.y[j])} "
        f"(growth {g[j, i]:.1f} 1/s)"
    )


def _nominal(result: MapResult, bands: list[list[Band]], params: ScrewParameters) -> str:
    """Every squeak band on the grid column nearest the nominal parameter value."""
    nominal = getattr(params, "axial_load_n" if result.x_axis == "load_n" else result.x_axis)
    i = int(np.argmin(np.abs(result.x - nominal)))
    return (
        f"nearest the nominal value, at {at(result.x_axis, result.x[i])}: "
        f"{_bands_text(result.y_axis, bands[i])}"
    )


def describe_speed_map(result: MapResult, params: ScrewParameters) -> str:
    """Figs. 6-8: every unstable speed band for each parameter value (columns)."""
    bands = map_bands(result, "y", params)
    args = ("speed_rad_s", result.x_axis, result.x)
    return (
        f"{_ends(bands, *args)}; "
        f"{_trend('upper speed bound of squeak', bands, True, *args)}; "
        f"{_trend('lower speed bound', bands, False, *args)}; "
        f"{_extreme('upper speed bound', bands, True, True, *args, params)}; "
        f"{_several(bands, *args)}; "
        f"{_nominal(result, bands, params)}; {_peak(result)}."
    )


def describe_load_speed_map(result: MapResult, params: ScrewParameters) -> str:
    """Fig. 7: also the load below which no speed squeaks (rows)."""
    rows = map_bands(result, "x", params)
    lowest = _extreme(
        "lowest unstable load", rows, False, False, "load_n", "speed_rad_s", result.y, params
    )
    return f"{describe_speed_map(result, params)} Lower load bound of squeak: {lowest}."


def describe_load_map(result: MapResult, params: ScrewParameters) -> str:
    """Figs. 9-10: the lowest unstable load for each parameter value at a fixed speed."""
    bands = map_bands(result, "y", params)
    args = ("load_n", result.x_axis, result.x)
    return (
        f"at {fixed_text(result.fixed)}: "
        f"{_trend('lowest unstable load', bands, False, *args)}; "
        f"{_extreme('lowest unstable load', bands, False, False, *args, params)}; "
        f"{_several(bands, *args)}; "
        f"{_nominal(result, bands, params)}; {_peak(result)}."
    )


def describe_probability_band(result: MapResult, model: SqueakModel) -> str:
    """Fig. 7 with P: where P(squeak) crosses each level on the load column nearest the
    nominal load (refined between the grid points, `sweep.probability_crossings`), next to
    the nominal boundary there."""
    assert result.probability is not None  # a map made with probability=True
    i = int(np.argmin(np.abs(result.x - model.params.axial_load_n)))
    roots = sorted(p[1] for p in result.boundary if p[0] == result.x[i])
    crossings = probability_crossings(
        model,
        dict(result.fixed, **{result.x_axis: result.x[i]}),
        result.y_axis,
        result.y,
        result.probability[:, i],
    )
    parts = [
        f"{100 * level:g} % at " + (", ".join(fmt("speed_rad_s", v) for v in found) or "none")
        for level, found in crossings.items()
    ]
    bound = ", ".join(fmt("speed_rad_s", r) for r in roots) or "none on the grid"
    return (
        f"at {at(result.x_axis, result.x[i])} (nearest the nominal load) P(squeak) "
        f"crosses {'; '.join(parts)}; nominal stability boundary {bound}; "
        f"{_probability_share(result)}."
    )


def _probability_share(result: MapResult) -> str:
    assert result.probability is not None  # as in describe_probability_band
    prob = result.probability[np.isfinite(result.probability)]
    if not prob.size:
        return "no valid point on the grid"
    band = np.mean((prob > 0.1) & (prob < 0.9))
    return f"{100 * band:.0f} % of the valid grid has 10 % < P < 90 %"


def describe_speed_sweep(result: SweepResult) -> str:
    """Fig. 5: band, peak and squeak modes."""
    g = result.max_growth_rate
    if not np.isfinite(g).any():
        return "no valid point in the sweep."
    bands = ", ".join(f"{lo:.3g}-{hi:.3g} rad/s" for lo, hi in result.unstable_bands) or "none"
    modes = ", ".join(b.squeak_text for b in squeak_branches(result)) or "none"
    return (
        f"unstable band {bands} (refined boundaries; stable elsewhere on "
        f"{fmt('speed_rad_s', result.values[0])}-{fmt('speed_rad_s', result.values[-1])}); "
        f"largest growth {result.peak_growth_rate:.1f} 1/s at "
        f"{at('speed_rad_s', result.peak_value)} (refined); "
        f"squeak modes {modes}."
    )


def describe_frequencies(result: SweepResult) -> str:
    """Fig. 11: which mode frequencies are thick (Re > 0) and over which speeds."""
    branches, squeak = track_modes(result.predictions), squeak_branches(result)
    parts = [
        f"{b.squeak_text} for {result.values[b.squeaks].min():.3g}-"
        f"{fmt('speed_rad_s', result.values[b.squeaks].max())}"
        for b in squeak
    ]
    return (
        f"thick (squeak) lines (unstable sweep grid points): {'; '.join(parts) or 'none'}; "
        f"all other {len(branches) - len(parts)} traced mode branches stay at Re <= 0."
    )


def squeak_branches(result: SweepResult) -> list[Branch]:
    """The traced branches that are unstable somewhere, by squeak frequency."""
    return sorted(
        (b for b in track_modes(result.predictions) if b.squeaks.any()),
        key=lambda b: b.squeak_frequency_hz,
    )


def describe_friction(p: ScrewParameters, v: np.ndarray, mu: np.ndarray) -> str:
    """The friction law `mu` over sliding speeds `v` [m/s] in words (Fig. 4)."""
    v_ref = float(sliding_speed(p, REFERENCE_SPEED_RAD_S))
    mu_ref = float(friction_coefficient(p, v_ref))
    return (
        f"mu falls from {mu[0]:.3f} (mu_s) at rest to {mu[-1]:.3f} at |Vc| = {v[-1]:.2f} m/s "
        f"(mu_k = {p.mu_kinetic:.3f}), steepest slope {float(friction_slope(p, 0.0)):.3f} "
        f"s/m at rest; at "
        f"{at('speed_rad_s', REFERENCE_SPEED_RAD_S)} (|Vc| = {v_ref:.3f} m/s) "
        f"mu_o = {mu_ref:.3f}."
    )


# --------------------------------------------------------------------------- the figure set
@dataclass(frozen=True)
class Grids:
    """Resolution of the figure set: sweep and map points, and the PNGs' dots per inch."""

    sweep_points: int
    map_x: int
    map_y: int
    dpi: int


FULL = Grids(sweep_points=500, map_x=81, map_y=101, dpi=130)
QUICK = Grids(sweep_points=60, map_x=7, map_y=9, dpi=100)  # text >= 8 pt on screen

SWEEP_SPEEDS_RAD_S = (0.5, 120.0)  # Figs. 5 and 11: the whole band (~0.8-55 rad/s at Table 1)
RADIUS_RANGE_M = (0.002, 0.010)
LOAD_RANGE_N = (0.0, 600.0)
FRICTION_FILE = "fig04_friction.png"
GROWTH_FILE = "fig05_growth_vs_speed.png"
FREQUENCY_FILE = "fig11_frequency_vs_speed.png"
PROBABILITY_FILE = "fig07p_speed_load_probability.png"


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
    probability: bool = False  # also P on the grid (shared with fig07p)


def _nut_range(p: ScrewParameters) -> tuple[float, float]:
    """z_o from 0 to L - b (the nut stays on the screw)."""
    return 0.0, p.nut_travel_m


def _radius_range(p: ScrewParameters) -> tuple[float, float]:
    return RADIUS_RANGE_M


def _load_range(p: ScrewParameters) -> tuple[float, float]:
    return LOAD_RANGE_N


MAPS = (
    MapSpec(
        "fig06_speed_radius.png",
        "Fig. 6: stability boundary, speed vs effective radius",
        "radius_m",
        _radius_range,
        "speed_rad_s",
        (0.5, 600.0),
        None,
        describe_speed_map,
    ),
    MapSpec(
        "fig07_speed_load.png",
        "Fig. 7: stability boundary, speed vs axial load",
        "load_n",
        _load_range,
        "speed_rad_s",
        (0.5, 200.0),
        None,
        describe_load_speed_map,
        probability=True,
    ),
    MapSpec(
        "fig08_speed_location.png",
        "Fig. 8: stability boundary, speed vs nut location",
        "nut_position_m",
        _nut_range,
        "speed_rad_s",
        (0.5, 200.0),
        None,
        describe_speed_map,
    ),
    MapSpec(
        "fig09_load_radius.png",
        "Fig. 9: stability boundary, axial load vs effective radius",
        "radius_m",
        _radius_range,
        "load_n",
        LOAD_RANGE_N,
        REFERENCE_SPEED_RAD_S,
        describe_load_map,
    ),
    MapSpec(
        "fig10_load_location.png",
        "Fig. 10: stability boundary, axial load vs nut location",
        "nut_position_m",
        _nut_range,
        "load_n",
        LOAD_RANGE_N,
        REFERENCE_SPEED_RAD_S,
        describe_load_map,
    ),
)


def _grid(axis: str, lo: float, hi: float, n: int) -> np.ndarray:
    """Speed on a geometric grid (both boundaries of the band are visible), others linear."""
    return np.geomspace(lo, hi, n) if axis == "speed_rad_s" else np.linspace(lo, hi, n)


def run_map(
    model: SqueakModel,
    x_axis: str,
    x: np.ndarray,
    y_axis: str,
    y: np.ndarray,
    speed_rad_s: float | None = None,
    load_n: float | None = None,
    desc: str = "map",
    probability: bool = False,
) -> MapResult:
    """`stability_map` with a progress bar over the grid points (after the work check); with
    `probability` the bar counts each point twice (growth rate, then P)."""
    map_work(model, x_axis, x, y_axis, y).check()
    with progress_bar(x.size * y.size * (2 if probability else 1), desc) as update:
        return stability_map(
            model,
            x_axis,
            x,
            y_axis,
            y,
            speed_rad_s,
            load_n,
            progress=update,
            probability=probability,
        )


@dataclass
class FigureSet:
    """The paper's figures of one model into `out`: each job draws a figure and returns its
    summary sentence; the maps are computed once (fig07p reuses Fig. 7's)."""

    model: SqueakModel
    out: Path
    grids: Grids
    maps: dict[str, MapResult] = field(default_factory=dict)  # by file: fig07p reuses Fig. 7

    def _title(self, text: str) -> str:
        return f"{text}\n({self.model.params.formulation} formulation)"

    @cached_property
    def speed_sweep(self) -> SweepResult:
        """The speed sweep behind Figs. 5 and 11, computed once."""
        speeds = np.geomspace(*SWEEP_SPEEDS_RAD_S, self.grids.sweep_points)
        return sweep(self.model, "speed_rad_s", speeds)

    def friction(self, path: Path) -> str:
        """Draw the friction law (Fig. 4) to `path`; its description."""
        p = self.model.params
        v = np.linspace(0.0, float(sliding_speed(p, SWEEP_SPEEDS_RAD_S[1])), 400)
        plot_friction(p, v).savefig(path, dpi=self.grids.dpi)
        return describe_friction(p, v, friction_coefficient(p, v))

    def growth(self, path: Path) -> str:
        """Draw the growth rates against speed (Fig. 5) to `path`; their description."""
        plot_sweep(
            self.speed_sweep, title=self._title("Fig. 5: squeak propensity vs rotation speed")
        ).savefig(path, dpi=self.grids.dpi)
        return describe_speed_sweep(self.speed_sweep)

    def frequencies(self, path: Path) -> str:
        """Draw the squeak frequencies against speed (Fig. 11) to `path`; their description."""
        plot_frequencies(
            self.speed_sweep,
            title=self._title(
                r"Fig. 11: squeak frequencies vs rotation speed (thick: Re($\lambda$) > 0)"
            ),
        ).savefig(path, dpi=self.grids.dpi)
        return describe_frequencies(self.speed_sweep)

    def map(self, spec: MapSpec) -> MapResult:
        """The stability map of `spec`, computed on first use."""
        if spec.file not in self.maps:
            x = _grid(spec.x_axis, *spec.x_range(self.model.params), self.grids.map_x)
            y = _grid(spec.y_axis, *spec.y_range, self.grids.map_y)
            self.maps[spec.file] = run_map(
                self.model,
                spec.x_axis,
                x,
                spec.y_axis,
                y,
                spec.speed_rad_s,
                desc=spec.file.split("_")[0],
                probability=spec.probability,
            )
        return self.maps[spec.file]

    def stability(self, spec: MapSpec, path: Path) -> str:
        """Draw the stability map of `spec` to `path`; its description."""
        result = self.map(spec)
        title = self._title("\n".join(filter(None, (spec.title, fixed_text(result.fixed)))))
        plot_map(result, title=title).savefig(path, dpi=self.grids.dpi)
        return spec.describe(result, self.model.params)

    def probability_band(self, path: Path) -> str:
        """Fig. 7 with the iso-P(squeak) lines and the 10-90 % band over the default scatter
        (or --scatter)."""
        spec = next(s for s in MAPS if s.probability)
        result = self.map(spec)
        scatter = ", ".join(f"{k} {v:g}" for k, v in self.model.scatter.sd.items()) or "none"
        title = self._title(f"{spec.title}, with P(squeak) over the scatter\n(scatter: {scatter})")
        plot_map(result, title=title, overlay=probability_overlay(result)).savefig(
            path, dpi=self.grids.dpi
        )
        return describe_probability_band(result, self.model)

    def work(self) -> Work:
        """All the predictions of the figures, as one batch (checked before the first)."""
        speeds = sweep_work(self.model, "speed_rad_s", np.zeros(self.grids.sweep_points))
        maps = [
            map_work(
                self.model,
                s.x_axis,
                np.zeros(self.grids.map_x),
                s.y_axis,
                np.zeros(self.grids.map_y),
            )
            for s in MAPS
            for _ in range(2 if s.probability else 1)
        ]  # P: one more
        return Work(
            f"figures: {len(maps)} maps of {self.grids.map_x} x {self.grids.map_y} and "
            f"a sweep of {self.grids.sweep_points}",
            speeds.points + sum(m.points for m in maps),
            speeds.state_size,
            speeds.bytes_per_point,
            "use --quick or fewer modes",
        )

    def jobs(self) -> dict[str, Callable[[Path], str]]:
        """File name -> function that draws it and returns its summary sentence."""
        jobs = {
            FRICTION_FILE: self.friction,
            GROWTH_FILE: self.growth,
            FREQUENCY_FILE: self.frequencies,
            PROBABILITY_FILE: self.probability_band,
        }
        jobs.update({s.file: partial(self.stability, s) for s in MAPS})
        return {name: jobs[name] for name in FIGURE_FILES}


FIGURE_FILES = (
    FRICTION_FILE,
    GROWTH_FILE,
    *(f for s in MAPS for f in (s.file, PROBABILITY_FILE)[: 1 + s.probability]),
    FREQUENCY_FILE,
)


def _header(params: ScrewParameters) -> str:
    default = ScrewParameters()
    changed = [
        f"{k} = {v!r}"
        for k, v in params.as_dict().items()
        if v != getattr(default, k) and k != "formulation"
    ]
    base = "Table 1 defaults" + (" except " + ", ".join(changed) if changed else "")
    return f"leadscrew-squeak figures: {params.formulation} formulation, {base}"


def make_figures(model: SqueakModel, out: Path, quick: bool = False) -> str:
    """Write the nine PNGs and summary.txt into `out`; return the summary text. Raises
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


# --------------------------------------------------------------------------- the command
def cmd_figures(args: argparse.Namespace) -> int:
    """`figures`: write the paper's figures; exit status."""
    model = build_model(args)
    print(make_figures(model, output_directory(args.out), quick=args.quick), end="")
    return 0


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `figures` to `sub`; `common`: the model options."""
    p = sub.add_parser(
        "figures",
        parents=common,
        help="the paper's Figs. 4-11, Fig. 7 with the P(squeak) band, and summary.txt",
        epilog=WORK_LIMITS.replace("points", "points in all", 1),
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--quick", action="store_true", help="coarse grids (a few seconds)")
    p.set_defaults(run=cmd_figures)
