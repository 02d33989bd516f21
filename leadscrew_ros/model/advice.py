# SPDX-License-Identifier: Apache-2.0
"""Controller advice: the squeak-free speed nearest to the current one (same direction).

`speed_bands` is the full search: every squeak band in one direction, on a log grid over the
valid speed range. `band_around` learns only what the advice at one speed needs: the band that
speed sits in, scanned outward from it on the same grid spacing in small batched eigen-solves,
with an edge refined by root finding only when it can give the nearest squeak-free speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Literal

import numpy as np
from scipy.optimize import brentq

from .predictor import SqueakModel
from .sweep import growth_field, refine_crossings, unstable_intervals

_BAND_POINTS = 64          # log-spaced speeds between min_speed and the critical speed
_SCAN_BATCH = 8            # grid points per batched eigen-solve of `band_around`'s scan
EDGE_RTOL = 1e-7           # relative tolerance of an edge refined by `band_around`
_MAX_REFINE = 60           # brentq iterations per edge (bisection needs < 25 at EDGE_RTOL)

# What lies beyond an end of a `Band`: squeak-free speeds (the end is a refined edge), ground
# where the model is not valid or the end of the valid range ("limit"), or not searched yet.
End = Literal["edge", "limit", "unknown"]


def _grid_ends(model: SqueakModel) -> tuple[float, float]:
    """Lowest and highest |speed| (rad/s) of the search grid."""
    return model.params.min_speed_rad_s, model.critical_speed_rad_s * (1 - 1e-9)


def speed_bands(model: SqueakModel, load_n: float, direction: float = 1.0
                ) -> list[tuple[float, float]]:
    """Unstable |speed| intervals (rad/s) in one direction of rotation at this load, ends
    refined by root finding; the grid is log-spaced over the model's valid speed range."""
    sign = math.copysign(1.0, direction)
    w = np.geomspace(*_grid_ends(model), _BAND_POINTS)
    growth = growth_field(model, sign * w, load_n).max_growth_rate

    def f(x: float) -> float:
        return float(growth_field(model, sign * x, load_n).max_growth_rate)

    return unstable_intervals(w, growth, refine_crossings(f, w, growth, rtol=1e-6))


@dataclass(frozen=True)
class Band:
    """What is known of one squeak band (|speed| in rad/s, one direction, one load): squeak on
    all of [low_rad_s, high_rad_s] (on the search grid), and what lies beyond each end."""

    low_rad_s: float
    high_rad_s: float
    below: End
    above: End

    def contains(self, speed_rad_s: float) -> bool:
        return self.low_rad_s <= abs(speed_rad_s) <= self.high_rad_s

    def safe_speed(self, speed_rad_s: float, lowest_rad_s: float, highest_rad_s: float,
                   margin: float = 0.05) -> float | None:
        """Nearest squeak-free speed with the sign of `speed_rad_s` (rad/s), or None when this
        band does not contain the speed or an unsearched side could still hold a nearer one.

        A candidate is a refined edge moved out of the band by `margin` (relative) that lies
        in the valid range [lowest, highest); the nearer one wins; 0 when there is none
        (stopping is always squeak-free)."""
        if not self.contains(speed_rad_s):
            return None
        best, undecided = self._options(abs(speed_rad_s), lowest_rad_s, highest_rad_s, margin)
        if undecided:
            return None
        return 0.0 if best is None else math.copysign(best, speed_rad_s)

    def _options(self, w: float, lowest: float, highest: float, margin: float
                 ) -> tuple[float | None, list[str]]:
        """The best candidate |speed| found so far (None: none) and the unsearched sides whose
        candidate could still be nearer to w."""
        best, reach = None, {}
        for side, end, v in (("below", self.below, self.low_rad_s * (1 - margin)),
                             ("above", self.above, self.high_rad_s * (1 + margin))):
            if not lowest <= v < highest or end == "limit":
                continue          # an edge further out moves v further out of range too
            if end == "unknown":  # the edge is at or beyond this end: v is this near at best
                reach[side] = abs(v - w)
            elif best is None or abs(v - w) < abs(best - w):
                best = v
        return best, [s for s, d in reach.items() if best is None or d < abs(best - w)]


def band_around(model: SqueakModel, load_n: float, speed_rad_s: float, margin: float = 0.05,
                checkpoint: Callable[[], None] | None = None, known: Band | None = None
                ) -> Band | None:
    """The squeak band containing `speed_rad_s` at this load, searched just far enough that
    `Band.safe_speed` at this speed (and `margin`) is decided; None when the speed is
    squeak-free or outside the model's validity.

    Both sides are scanned outward from the speed on the log grid of `speed_bands` (same
    spacing), nearest candidate first: each batched solve takes the `_SCAN_BATCH` points whose
    safe-speed candidate would be nearest. A side stops at its first squeak-free point (edge
    refined to `EDGE_RTOL` with brentq), at invalid ground or the grid end, or as soon as it
    can no longer offer the nearer candidate. At most `_BAND_POINTS + _SCAN_BATCH` scan points
    and 2 refinements. `checkpoint` is called before every eigen-solve; it may raise to abandon
    the search. `known`, a band found earlier that contains the speed, is extended rather than
    searched again (a speed jittering inside a band then settles after a few searches)."""
    sign, w = math.copysign(1.0, speed_rad_s), abs(speed_rad_s)
    lowest, highest = _grid_ends(model)
    step = (highest / lowest) ** (1 / (_BAND_POINTS - 1))

    def growth(x) -> np.ndarray:
        if checkpoint is not None:
            checkpoint()
        return growth_field(model, sign * np.asarray(x, float), load_n).max_growth_rate

    if known is not None and known.contains(w):
        band = known
    elif not growth(w) > 0:                           # NaN (invalid) compares False too
        return None
    else:
        band = Band(w, w, "unknown", "unknown")
    while True:
        best, sides = band._options(w, lowest, highest, margin)
        if not sides:
            return band
        # A side's points, each with the distance its candidate would have if the edge were
        # just before it; beyond what can still win only the first is needed (to learn that
        # the band goes on), and nothing beyond the batch's nearest.
        farthest = {"below": highest - w, "above": w - lowest}   # option of the other side
        points, reach = [], []
        for s in sides:
            x = _next_points(band, s, step, lowest, highest)
            r = np.abs(x * (1 - margin if s == "below" else 1 + margin) - w)
            limit = (abs(best - w) if best is not None else farthest[s] if len(sides) > 1
                     else math.inf)
            keep = np.searchsorted(r, limit) + 1          # r grows outward
            points.append(x[:keep])
            reach.append(r[:keep])
        cut = np.sort(np.concatenate(reach))[:_SCAN_BATCH][-1]
        points = [x[r <= cut] for x, r in zip(points, reach)]
        g = growth(np.concatenate(points))
        for s, x, start in zip(sides, points, np.cumsum([0] + [len(x) for x in points])):
            band = _extend(band, s, x, g[start:start + len(x)], lowest, highest, growth)


def _next_points(band: Band, side: str, step: float, lowest: float, highest: float
                 ) -> np.ndarray:
    """The next scan points beyond one end of the band, ending at the grid end."""
    k = np.arange(1, _SCAN_BATCH + 1)                 # enough for a batch of one side
    if side == "below":
        x = band.low_rad_s / step ** k
        return np.append(x[x > lowest], lowest)[:_SCAN_BATCH]
    x = band.high_rad_s * step ** k
    return np.append(x[x < highest], highest)[:_SCAN_BATCH]


def _extend(band: Band, side: str, x: np.ndarray, g: np.ndarray, lowest: float,
            highest: float, growth: Callable) -> Band:
    """The band after scanning `x` (outward, growth `g`) beyond its `side` end."""
    end = "low_rad_s" if side == "below" else "high_rad_s"
    last = getattr(band, end)                         # last squeak point, outward
    for xi, gi in zip(x.tolist(), g.tolist()):
        if math.isnan(gi):                            # invalid ground: no advice beyond
            return replace(band, **{end: last, side: "limit"})
        if gi <= 0:                                   # squeak-free: refine the edge
            def f(v: float) -> float:                 # invalid inside counts as squeak-free
                return float(np.nan_to_num(growth(v), nan=-1.0))
            edge = brentq(f, last, xi, xtol=1e-300, rtol=EDGE_RTOL, maxiter=_MAX_REFINE)
            return replace(band, **{end: edge, side: "edge"})
        last = xi
    at_grid_end = last == (lowest if side == "below" else highest)
    return replace(band, **{end: last, side: "limit" if at_grid_end else "unknown"})
