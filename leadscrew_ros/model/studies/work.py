# SPDX-License-Identifier: Apache-2.0
"""Work-size limits of sweeps and maps, checked before any work (`Work.check`): a map or
sweep may hold at most `MAX_POINTS` points (fewer for models with more modes: an eigen-solve
costs ~ state size cubed) and need at most about `MAX_MEMORY_BYTES`; a larger request is a
one-line `WorkSizeError` before any work. Batched eigen-solves are cut into chunks of about
the same work whatever the number of modes (`_chunk_points`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics.display import exact
from ..physics.parameters import ParameterError, field_info
from ..squeak_model import SqueakModel

_CHUNK = 1024  # points per batched eigen-solve at the reference size
REFERENCE_STATE_SIZE = 36  # state size of the default model (6 bending + 6 torsion)
MAX_POINTS = 1_000_000  # points of one map or sweep at the reference state size
MAX_MEMORY_BYTES = 2_000_000_000  # estimated peak memory of one map or sweep
_MAP_POINT_BYTES = 250  # result arrays, JSON output (measured: ~40 held, ~200 JSON)
_PREDICTION_BYTES_PER_STATE = 85  # a sweep's Prediction per point (~3 kB at 36 states)


class WorkSizeError(ParameterError):
    """A map or sweep too large to compute (one line: size, limit, what to do)."""


@dataclass(frozen=True)
class Work:
    """The size of a batch of predictions, checked against the limits before it starts."""

    what: str  # 'map of 100 x 200', 'sweep of 500 radius_m values'
    points: int
    state_size: int  # 2 x (2 n_bending + n_torsion)
    bytes_per_point: float
    remedy: str = "use fewer points"

    @property
    def point_limit(self) -> int:
        """MAX_POINTS scaled by the cost of one eigen-solve relative to the default model."""
        scale = (REFERENCE_STATE_SIZE / self.state_size) ** 3
        return max(1, min(MAX_POINTS, int(MAX_POINTS * scale)))

    def memory_bytes(self, points: int | None = None) -> float:
        """Memory [bytes] that `points` predictions take (default: this batch's)."""
        n = self.points if points is None else points
        chunk = _chunk_points(self.state_size) * self.state_size**2 * 16 * 4  # eig workspace
        return n * self.bytes_per_point + chunk

    def check(self) -> None:
        """Raise WorkSizeError if the work exceeds the point or memory limit."""
        limit = self.point_limit
        if self.points > limit:
            per_model = (
                f" for a model of {self.state_size} states ({exact(MAX_POINTS)} at "
                f"the default {REFERENCE_STATE_SIZE})"
                if limit < MAX_POINTS
                else ""
            )
            raise WorkSizeError(
                f"{self.what} = {exact(self.points)} points (about {_gb(self.memory_bytes())}) "
                f"exceeds the limit of {exact(limit)} points{per_model}; {self.remedy}"
            )
        if self.memory_bytes() > MAX_MEMORY_BYTES:
            raise WorkSizeError(
                f"{self.what} = {exact(self.points)} points needs about "
                f"{_gb(self.memory_bytes())}, more than the limit of "
                f"{_gb(MAX_MEMORY_BYTES)}; {self.remedy}"
            )


def _gb(n_bytes: float) -> str:
    return f"{exact(float(f'{n_bytes / 1e9:.2g}'))} GB"


def _chunk_points(state_size: int) -> int:
    """Points per batched eigen-solve: about the work (and Ctrl-C latency) of _CHUNK points of
    the default model, whatever the number of modes."""
    return max(1, _CHUNK * REFERENCE_STATE_SIZE**3 // state_size**3)


def _state_size(model: SqueakModel, axes: dict[str, np.ndarray]) -> int:
    """Largest state size on the axes: 2 (2 n_bending + n_torsion), the mode counts taken at
    their largest valid value where an axis varies them."""
    n = {}
    for name in ("n_bending", "n_torsion"):
        values = np.asarray(axes.get(name, getattr(model.params, name)), float)
        valid = values[(values >= field_info(name)["lo"]) & (values <= field_info(name)["hi"])]
        n[name] = int(round(valid.max())) if valid.size else getattr(model.params, name)
    return 2 * (2 * n["n_bending"] + n["n_torsion"])


def map_work(model: SqueakModel, x_axis: str, x: np.ndarray, y_axis: str, y: np.ndarray) -> Work:
    """The work of `stability_map` on the grid x times y."""
    return Work(
        f"map of {len(x)} x {len(y)}",
        len(x) * len(y),
        _state_size(model, {x_axis: x, y_axis: y}),
        _MAP_POINT_BYTES,
    )


def sweep_work(model: SqueakModel, axis: str, values: np.ndarray) -> Work:
    """The work of `sweep` along `values`."""
    size = _state_size(model, {axis: values})
    return Work(
        f"sweep of {len(values)} {axis} values",
        len(values),
        size,
        _PREDICTION_BYTES_PER_STATE * size,
    )
