# SPDX-License-Identifier: Apache-2.0
"""Mode tracking: the oscillatory eigenvalues of a sweep followed from point to point.

A sweep's predictions list their modes by growth rate, and a mode's label (its dominant
coordinate) is ambiguous within a whirl pair, so neither order nor label identifies a mode
along the sweep. `track_modes` pairs the eigenvalues of neighbouring points by a minimum-cost
assignment of their relative distances; each resulting `Branch` is one mode along the sweep.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..squeak_model import Prediction


@dataclass
class Branch:
    """One oscillatory mode followed along a sweep; NaN where it does not exist.

    Attributes
    ----------
    growth : numpy.ndarray
        Re(lambda) at each point of the sweep [1/s]; NaN where the branch does not exist.
    frequency_hz : numpy.ndarray
        Im(lambda) / 2 pi at each point of the sweep [Hz]; NaN where the branch does not exist.
    labels : collections.Counter
        How often each mode label was met along the branch.
    """

    growth: np.ndarray
    frequency_hz: np.ndarray
    labels: Counter = field(default_factory=Counter)

    @property
    def label(self) -> str:
        """The most frequent mode label of the branch."""
        return self.labels.most_common(1)[0][0]

    @property
    def peak_growth(self) -> float:
        """The largest growth rate along the branch [1/s]."""
        return float(np.nanmax(self.growth))

    @property
    def typical_frequency_hz(self) -> float:
        """Median frequency along the branch [Hz]."""
        return float(np.nanmedian(self.frequency_hz))

    @property
    def squeaks(self) -> np.ndarray:
        """Where the branch is unstable (Re > 0)."""
        return np.nan_to_num(self.growth, nan=-1.0) > 0

    @property
    def squeak_frequency_hz(self) -> float:
        """Median frequency where the branch is unstable [Hz]; NaN if it never is."""
        return float(np.median(self.frequency_hz[self.squeaks])) if self.squeaks.any() else math.nan

    @property
    def squeak_text(self) -> str:
        """'B1y 224 Hz': the one wording of a squeak mode in plots and summaries."""
        return f"{self.label} {self.squeak_frequency_hz:.0f} Hz"


def _eigenvalues(p: Prediction) -> np.ndarray:
    return np.array([complex(m.growth_rate, 2 * math.pi * m.frequency_hz) for m in p.modes])


def track_modes(predictions: Sequence[Prediction], max_jump: float = 0.15) -> list[Branch]:
    """Follow the oscillatory eigenvalues from point to point by nearest-neighbour assignment.

    Labels alone cannot do this: the dominant coordinate of a whirl pair is ambiguous.

    Parameters
    ----------
    predictions : sequence of Prediction
        The predictions of a sweep, in the order of its axis.
    max_jump : float
        Largest relative distance |lambda_i - lambda_j| / max(|lambda_i|, |lambda_j|) [1]
        between eigenvalues of neighbouring points that continues a branch; a mode that
        appears or jumps farther starts a new one.

    Returns
    -------
    list of Branch
        Every branch, in the order they start; together they hold each mode of each
        prediction exactly once.
    """
    size, last = len(predictions), np.empty(0, complex)
    branches: list[Branch] = []
    alive: list[int] = []  # branch index of each mode of `last`
    for i, p in enumerate(predictions):
        lam = _eigenvalues(p)
        owner = [-1] * len(lam)
        if len(last) and len(lam):
            cost = np.abs(last[:, None] - lam[None, :]) / np.maximum(
                np.abs(last)[:, None], np.abs(lam)[None, :]
            )
            for r, c in zip(*linear_sum_assignment(cost), strict=True):
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
