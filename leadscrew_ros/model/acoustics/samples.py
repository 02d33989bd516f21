# SPDX-License-Identifier: Apache-2.0
"""A long track read piece by piece: hours of 48 kHz sound are gigabytes, so a log's audio is
kept on disk (`bag.audio.read_audio`) and the detector reads it by slices. Everything in
`acoustics` that takes samples takes a `SampleTrack` too: slicing one gives a numpy array of
that stretch only, and long stretches go through `span` (a lazy view), never a whole copy.
numpy only."""

from __future__ import annotations

import abc
from typing import Any

import numpy as np


class SampleTrack(abc.ABC):
    """A mono float32 track of `size` samples read by slices (full scale, NaN where there is
    no sound). Subclasses give `size` and `read`; `x[a:b]` reads that stretch, `np.asarray(x)`
    all of it (for short tracks and tests only)."""

    dtype = np.dtype(np.float32)
    ndim = 1

    @property
    @abc.abstractmethod
    def size(self) -> int:
        """Number of samples."""

    @abc.abstractmethod
    def read(self, start: int, stop: int) -> np.ndarray:
        """Samples [start, stop) (0 <= start <= stop <= size) as a new float32 array."""

    @property
    def shape(self) -> tuple[int]:
        """(size,), as an array's."""
        return (self.size,)

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, key: Any) -> np.ndarray:
        if isinstance(key, slice) and key.step in (None, 1):
            start, stop, _ = key.indices(self.size)
            return self.read(start, max(start, stop))
        return np.asarray(self)[key]

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        x = self.read(0, self.size)
        return x if dtype is None else x.astype(dtype)

    def span(self, start: int, stop: int) -> SampleTrack:
        """The samples [start, stop) as a track of their own, nothing read yet."""
        start = min(max(start, 0), self.size)
        return _Span(self, start, max(start, min(stop, self.size)))


class _Span(SampleTrack):
    def __init__(self, whole: SampleTrack, start: int, stop: int) -> None:
        self._whole, self._start, self._size = whole, start, stop - start

    @property
    def size(self) -> int:
        return self._size

    def read(self, start: int, stop: int) -> np.ndarray:
        return self._whole.read(self._start + start, self._start + stop)


def span(x: np.ndarray | SampleTrack, start: int, stop: int) -> np.ndarray | SampleTrack:
    """`x[start:stop]` without reading a `SampleTrack` (an array's slice is a view anyway).

    Parameters
    ----------
    x : numpy.ndarray or SampleTrack
        The samples.
    start, stop : int
        The stretch (clipped to the track).

    Returns
    -------
    numpy.ndarray or SampleTrack
    """
    return x.span(start, stop) if isinstance(x, SampleTrack) else x[start:stop]


#: Samples as the detector takes them: an array, or a long track read by slices.
Samples = np.ndarray | SampleTrack
