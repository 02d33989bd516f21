# SPDX-License-Identifier: Apache-2.0
"""Controller advice: the speed nearest to the current one (same direction) whose P(squeak) is
below `safe_probability`.

A squeak band here is a speed interval where P(squeak) >= safe_probability, P being
`Prediction.probability` over the model's scatter (`band_score`). Without scatter P is the
nominal verdict (0 or 1), and the band is the deterministic one: some oscillatory mode grows.
`speed_bands` is the full search: every band in one direction, on a log grid over the valid
speed range. `band_around` learns only what the advice at one speed needs: the band that speed
sits in, scanned outward from it on the same grid spacing in small batches of predictions, with
an edge refined only when it can give the nearest safe speed. P is a share of samples, a step
function of the speed, so an edge is refined by bisection (`_edge`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from ..physics.parameters import ParameterError
from ..squeak_model import SqueakModel
from .roots import unstable_intervals

_BAND_POINTS = 64  # log-spaced speeds between min_speed and the critical speed
_SCAN_BATCH = 8  # grid points per batch of predictions of `band_around`'s scan
EDGE_RTOL = 1e-7  # relative tolerance of a refined edge
_MAX_REFINE = 60  # bisection steps per edge at most (a grid step needs 21)

# What lies beyond an end of a `Band`: safe speeds (the end is a refined edge), ground
# where the model is not valid or the end of the valid range ("limit"), or not searched yet.
End = Literal["edge", "limit", "unknown"]


def _grid_ends(model: SqueakModel) -> tuple[float, float]:
    """Lowest and highest |speed| (rad/s) of the search grid."""
    return model.params.min_speed_rad_s, model.critical_speed_rad_s * (1 - 1e-9)


def band_score(
    model: SqueakModel,
    load_n: float,
    direction: float,
    safe_probability: float,
    checkpoint: Callable[[], None] | None = None,
) -> Callable[[ArrayLike], np.ndarray]:
    """P(squeak) - safe_probability as a function of |speed|, in one direction of rotation.

    Parameters
    ----------
    model : SqueakModel
        The model; its scatter gives P (`Prediction.probability`).
    load_n : float
        Axial load [N].
    direction : float
        Its sign is the direction of rotation.
    safe_probability : float
        The threshold, in (0, 1]: P below it is safe.
    checkpoint : callable, optional
        Called before every batch of predictions; it may raise to abandon the caller's work.

    Returns
    -------
    callable
        |speed| array [rad/s] -> score array (1-d): >= 0 in a squeak band, < 0 where the
        speed is safe, NaN where the model is not valid.

    Raises
    ------
    ParameterError
        `safe_probability` is not in (0, 1].
    """
    if (
        isinstance(safe_probability, bool)
        or not isinstance(safe_probability, (int, float))
        or not 0.0 < safe_probability <= 1.0
    ):
        raise ParameterError(f"safe_probability = {safe_probability!r} must be in (0, 1]")
    sign = math.copysign(1.0, direction)

    def score(w: ArrayLike) -> np.ndarray:
        if checkpoint is not None:
            checkpoint()
        speeds = sign * np.atleast_1d(np.asarray(w, float))
        return np.array(
            [
                p.probability - safe_probability
                if p.valid and p.probability is not None
                else math.nan
                for p in model.predict_many(speeds, load_n)
            ]
        )

    return score


def _edge(score: Callable[[ArrayLike], np.ndarray], inside: float, outside: float) -> float:
    """The band edge between |speed| `inside` (score >= 0) and `outside` (score < 0 or not
    valid), to EDGE_RTOL by bisection: the outside end of the last bracket, so P there is
    below the threshold (or the point is not valid)."""
    for _ in range(_MAX_REFINE):
        if abs(outside - inside) <= EDGE_RTOL * max(inside, outside):
            break
        mid = 0.5 * (inside + outside)
        if score(mid)[0] >= 0:  # NaN (not valid) counts as outside
            inside = mid
        else:
            outside = mid
    return outside


def speed_bands(
    model: SqueakModel, load_n: float, direction: float = 1.0, *, safe_probability: float
) -> list[tuple[float, float]]:
    """|speed| intervals (rad/s) in one direction of rotation at this load where P(squeak) >=
    safe_probability (`band_score`), ends refined to EDGE_RTOL (`_edge`); the grid is
    log-spaced over the model's valid speed range."""
    score = band_score(model, load_n, direction, safe_probability)
    w = np.geomspace(*_grid_ends(model), _BAND_POINTS)
    s = score(w)
    inside = np.where(np.isnan(s), np.nan, np.where(s >= 0, 1.0, -1.0))
    edges = [
        _edge(score, *((w[i], w[i + 1]) if inside[i] > 0 else (w[i + 1], w[i])))
        for i in range(len(w) - 1)
        if np.isfinite(inside[i : i + 2]).all() and inside[i] != inside[i + 1]
    ]
    return unstable_intervals(w, inside, edges)


@dataclass(frozen=True)
class Band:
    """What is known of one squeak band (|speed| in rad/s, one direction, one load): P(squeak)
    >= safe_probability on all of [low_rad_s, high_rad_s] (on the search grid), and what lies
    beyond each end."""

    low_rad_s: float
    high_rad_s: float
    below: End
    above: End

    def contains(self, speed_rad_s: float) -> bool:
        """True if |`speed_rad_s`| lies in the band."""
        return self.low_rad_s <= abs(speed_rad_s) <= self.high_rad_s

    def safe_speed(
        self, speed_rad_s: float, lowest_rad_s: float, highest_rad_s: float, margin: float = 0.05
    ) -> float | None:
        """Nearest safe speed with the sign of `speed_rad_s` (rad/s), or None when this band
        does not contain the speed or an unsearched side could still hold a nearer one.

        A candidate is a refined edge moved out of the band by `margin` (relative) that lies
        in the valid range [lowest, highest); the nearer one wins; 0 when there is none
        (stopping never squeaks)."""
        if not self.contains(speed_rad_s):
            return None
        best, undecided = self._options(abs(speed_rad_s), lowest_rad_s, highest_rad_s, margin)
        if undecided:
            return None
        return 0.0 if best is None else math.copysign(best, speed_rad_s)

    def _options(
        self, w: float, lowest: float, highest: float, margin: float
    ) -> tuple[float | None, list[str]]:
        """The best candidate |speed| found so far (None: none) and the unsearched sides whose
        candidate could still be nearer to w."""
        best, reach = None, {}
        for side, end, v in (
            ("below", self.below, self.low_rad_s * (1 - margin)),
            ("above", self.above, self.high_rad_s * (1 + margin)),
        ):
            if not lowest <= v < highest or end == "limit":
                continue  # an edge further out moves v further out of range too
            if end == "unknown":  # the edge is at or beyond this end: v is this near at best
                reach[side] = abs(v - w)
            elif best is None or abs(v - w) < abs(best - w):
                best = v
        return best, [s for s, d in reach.items() if best is None or d < abs(best - w)]


def band_around(
    model: SqueakModel,
    load_n: float,
    speed_rad_s: float,
    margin: float = 0.05,
    checkpoint: Callable[[], None] | None = None,
    known: Band | None = None,
    *,
    safe_probability: float,
) -> Band | None:
    """The squeak band (P(squeak) >= safe_probability, `band_score`) containing `speed_rad_s`
    at this load, searched just far enough that `Band.safe_speed` at this speed (and `margin`)
    is decided; None when the speed is safe or outside the model's validity.

    Both sides are scanned outward from the speed on the log grid of `speed_bands` (same
    spacing), nearest candidate first: each batch of predictions takes the `_SCAN_BATCH`
    points whose safe-speed candidate would be nearest. A side stops at its first safe point
    (edge refined to `EDGE_RTOL` by bisection), at invalid ground or the grid end, or as soon
    as it can no longer offer the nearer candidate. At most `_BAND_POINTS + _SCAN_BATCH` scan
    points and 2 refinements. `checkpoint` is called before every batch (a refinement step is
    a batch of one); it may raise to abandon the search. `known`, a band found earlier that
    contains the speed, is extended rather than searched again (a speed jittering inside a
    band then settles after a few searches)."""
    w = abs(speed_rad_s)
    score = band_score(model, load_n, speed_rad_s, safe_probability, checkpoint)
    lowest, highest = _grid_ends(model)
    step = (highest / lowest) ** (1 / (_BAND_POINTS - 1))

    if known is not None and known.contains(w):
        band = known
    elif not score(w)[0] >= 0:  # NaN (invalid) compares False too
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
        farthest = {"below": highest - w, "above": w - lowest}  # option of the other side
        points, reach = [], []
        for s in sides:
            x = _next_points(band, s, step, lowest, highest)
            r = np.abs(x * (1 - margin if s == "below" else 1 + margin) - w)
            limit = (
                abs(best - w) if best is not None else farthest[s] if len(sides) > 1 else math.inf
            )
            keep = np.searchsorted(r, limit) + 1  # r grows outward
            points.append(x[:keep])
            reach.append(r[:keep])
        cut = np.sort(np.concatenate(reach))[:_SCAN_BATCH][-1]
        points = [x[r <= cut] for x, r in zip(points, reach, strict=True)]
        g = score(np.concatenate(points))
        for s, x, start in zip(
            sides, points, np.cumsum([0] + [len(x) for x in points]), strict=False
        ):
            band = _extend(band, s, x, g[start : start + len(x)], lowest, highest, score)


def _next_points(band: Band, side: str, step: float, lowest: float, highest: float) -> np.ndarray:
    """The next scan points beyond one end of the band, ending at the grid end."""
    k = np.arange(1, _SCAN_BATCH + 1)  # enough for a batch of one side
    if side == "below":
        x = band.low_rad_s / step**k
        return np.append(x[x > lowest], lowest)[:_SCAN_BATCH]
    x = band.high_rad_s * step**k
    return np.append(x[x < highest], highest)[:_SCAN_BATCH]


def _extend(
    band: Band,
    side: str,
    x: np.ndarray,
    g: np.ndarray,
    lowest: float,
    highest: float,
    score: Callable[[ArrayLike], np.ndarray],
) -> Band:
    """The band after scanning `x` (outward, `band_score` values `g`) beyond its `side` end."""
    end = "low_rad_s" if side == "below" else "high_rad_s"
    last = getattr(band, end)  # last point in the band, outward
    for xi, gi in zip(x.tolist(), g.tolist(), strict=True):
        if math.isnan(gi):  # invalid ground: no advice beyond
            return replace(band, **{end: last, side: "limit"})
        if gi < 0:  # safe: refine the edge
            edge: dict[str, Any] = {end: _edge(score, last, xi), side: "edge"}
            return replace(band, **edge)
        last = xi
    at_grid_end = last == (lowest if side == "below" else highest)
    return replace(band, **{end: last, side: "limit" if at_grid_end else "unknown"})
