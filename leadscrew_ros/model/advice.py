"""Controller advice: the squeak-free speed nearest to the current one (same direction)."""

from __future__ import annotations

import math

import numpy as np

from .predictor import SqueakModel
from .sweep import growth_field, refine_crossings, unstable_intervals

_BAND_POINTS = 64          # log-spaced speeds between min_speed and the critical speed


def speed_bands(model: SqueakModel, load_n: float, direction: float = 1.0
                ) -> list[tuple[float, float]]:
    """Unstable |speed| intervals (rad/s) in one direction of rotation at this load, ends
    refined by root finding; the grid is log-spaced over the model's valid speed range."""
    sign = math.copysign(1.0, direction)
    w = np.geomspace(model.params.min_speed_rad_s, model.critical_speed_rad_s * (1 - 1e-9),
                     _BAND_POINTS)
    growth = growth_field(model, sign * w, load_n).max_growth_rate

    def f(x: float) -> float:
        return float(growth_field(model, sign * x, load_n).max_growth_rate)

    return unstable_intervals(w, growth, refine_crossings(f, w, growth, rtol=1e-6))


def safe_speed(bands: list[tuple[float, float]], speed_rad_s: float, lowest_rad_s: float,
               highest_rad_s: float, margin: float = 0.05) -> float:
    """Nearest squeak-free speed with the sign of `speed_rad_s` (rad/s).

    The current speed when it is outside every band; else the band edge nearer to it, moved
    out of the band by `margin` (relative), if that lies in the valid range
    [lowest, highest); else 0 (stopping is always squeak-free)."""
    w, sign = abs(speed_rad_s), math.copysign(1.0, speed_rad_s)
    for lo, hi in bands:
        if lo <= w <= hi:
            below, above = lo * (1 - margin), hi * (1 + margin)
            options = [v for v in (below, above) if lowest_rad_s <= v < highest_rad_s]
            return sign * min(options, key=lambda v: abs(v - w)) if options else 0.0
    return speed_rad_s
