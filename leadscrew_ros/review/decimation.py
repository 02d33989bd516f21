# SPDX-License-Identifier: Apache-2.0
"""Bounded-memory series for the plots of long replays.

A replay streams millions of messages; what it keeps for its report must not grow with the log:

- `Envelope`: several channels over time as min / max / last value per time bin. At most
  `max_bins` bins: when the log runs past them, neighbouring bins merge pairwise and the bin
  width doubles, so any log length ends with between max_bins / 2 and max_bins bins, and a
  spike of one sample still shows as its bin's extreme.
- `Reservoir`: a uniform random sample of at most `size` rows of a stream (Algorithm R with a
  fixed seed: the same log gives the same sample), kept in arrival order for drawing.
"""

from __future__ import annotations

from array import array

import numpy as np

_BUFFER = 8192  # samples collected before they are binned with numpy


class Envelope:
    """Min, max and last value of `channels` per time bin; samples must come with
    non-decreasing time t >= 0 (seconds)."""

    def __init__(self, channels: int, max_bins: int = 4096, bin_s: float = 0.01):
        if max_bins < 2 or max_bins % 2:
            raise ValueError(f"max_bins must be even and >= 2, got {max_bins}")
        self.channels, self.max_bins, self.bin_s = channels, max_bins, bin_s
        self.lo = np.full((max_bins, channels), np.nan)
        self.hi = np.full((max_bins, channels), np.nan)
        self.last = np.full((max_bins, channels), np.nan)
        self.count = np.zeros(max_bins, np.int64)  # samples per bin
        self.bins = 0  # bins in use (1 + the last with data)
        self._t, self._values = array("d"), array("d")

    def add(self, t_s: float, *values: float) -> None:
        """Add one sample at time `t_s` [s]: one value per channel."""
        self._t.append(t_s)
        self._values.extend(values)
        if len(self._t) >= _BUFFER:
            self.flush()

    def flush(self) -> None:
        """Bin the buffered samples, merging bins while they outrun `max_bins`."""
        if not self._t:
            return
        t = np.frombuffer(self._t, float)
        v = np.frombuffer(self._values, float).reshape(-1, self.channels)
        while t[-1] >= self.bin_s * self.max_bins:
            self._merge()
        k = np.minimum((np.maximum(t, 0.0) // self.bin_s).astype(np.int64), self.max_bins - 1)
        starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
        ends = np.r_[starts[1:], k.size] - 1
        idx = k[starts]
        with np.errstate(invalid="ignore"):
            self.lo[idx] = np.fmin(self.lo[idx], np.fmin.reduceat(v, starts))
            self.hi[idx] = np.fmax(self.hi[idx], np.fmax.reduceat(v, starts))
        self.last[idx] = v[ends]
        np.add.at(self.count, idx, ends - starts + 1)
        self.bins = max(self.bins, int(idx[-1]) + 1)
        self._t, self._values = array("d"), array("d")

    def _merge(self) -> None:
        """Pairs of bins into one: half as many bins, twice as wide."""
        half, c = self.max_bins // 2, self.channels
        lo, hi, last = (a.reshape(half, 2, c) for a in (self.lo, self.hi, self.last))
        merged = (
            np.fmin(lo[:, 0], lo[:, 1]),
            np.fmax(hi[:, 0], hi[:, 1]),
            np.where(self.count[1::2, None] > 0, last[:, 1], last[:, 0]),
        )
        for a, m in zip((self.lo, self.hi, self.last), merged, strict=True):
            a[:half], a[half:] = m, np.nan
        self.count[:half] = self.count[0::2] + self.count[1::2]
        self.count[half:] = 0
        self.bins = (self.bins + 1) // 2
        self.bin_s *= 2

    def series(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(bin centres [s], lo, hi, last, count) of the bins in use."""
        self.flush()
        n = self.bins
        return (
            (np.arange(n) + 0.5) * self.bin_s,
            self.lo[:n].copy(),
            self.hi[:n].copy(),
            self.last[:n].copy(),
            self.count[:n].copy(),
        )

    @property
    def nbytes(self) -> int:
        """Memory held by the bins (constant)."""
        return sum(a.nbytes for a in (self.lo, self.hi, self.last, self.count))


class Reservoir:
    """A uniform sample of at most `size` rows of `width` floats from a stream."""

    def __init__(self, width: int, size: int = 20_000, seed: int = 0):
        self.rows = np.full((size, width), np.nan)
        self.order = np.zeros(size, np.int64)  # arrival index of each kept row
        self.size, self.seen = size, 0
        self._rng = np.random.default_rng(seed)

    def add(self, *row: float) -> None:
        """Offer one row to the sample (reservoir sampling)."""
        if self.seen < self.size:
            slot = self.seen
        else:
            slot = int(self._rng.integers(0, self.seen + 1))
            if slot >= self.size:
                self.seen += 1
                return
        self.rows[slot], self.order[slot] = row, self.seen
        self.seen += 1

    def sample(self) -> np.ndarray:
        """The kept rows in arrival order, shape (n, width)."""
        n = min(self.seen, self.size)
        return self.rows[:n][np.argsort(self.order[:n], kind="stable")]

    @property
    def nbytes(self) -> int:
        """Memory [bytes] of the kept rows."""
        return self.rows.nbytes + self.order.nbytes
