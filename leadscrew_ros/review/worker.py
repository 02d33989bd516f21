# SPDX-License-Identifier: Apache-2.0
"""A replay's prediction worker: a batch of jobs solved into the verdicts the replaying process
keeps and the CDR payloads it writes (`solve`), and the worker's start (`start`).

Only this module, the timeline and what they import are loaded in a worker process (the
package inits resolve their names on first use): not the fleet, the plots, the acoustics nor
scipy.stats (~0.7 s less per worker).
"""

from __future__ import annotations

import ctypes
import signal
from typing import NamedTuple

import numpy as np

from ..bag import messages
from ..model import Prediction, Validity
from ..model.uncertainty.scatter import Samples
from .timeline import ModelSpec, predict_jobs, share_samples

Payloads = tuple[bytes, ...]  # of `messages.PREDICTION_TOPICS`, in that order


class Verdict(NamedTuple):
    """What the replaying process keeps of a prediction (episodes, plots, counts): small, as
    it crosses from the workers for every recompute; the full prediction goes into the
    annotated MCAP as its CDR payloads.

    Attributes
    ----------
    speed_rad_s, load_n : float
        The operating point [rad/s], [N].
    validity : Validity
        Whether the linearisation holds (the rest is empty or None when not).
    probability : float or None
        P(squeak).
    max_growth_rate : float or None
        Largest Re(lambda) of the oscillatory modes [1/s].
    divergence_rates : tuple of float
        Real eigenvalues > 0 [1/s].
    squeak : tuple of (str, float, float)
        The squeak modes, most unstable first: label, frequency [Hz] and Re(lambda) [1/s].
    """

    speed_rad_s: float
    load_n: float
    validity: Validity
    probability: float | None
    max_growth_rate: float | None
    divergence_rates: tuple[float, ...]
    squeak: tuple[tuple[str, float, float], ...]

    @classmethod
    def of(cls, p: Prediction) -> Verdict:
        """The verdict kept of prediction `p`."""
        return cls(
            p.speed_rad_s,
            p.load_n,
            p.validity,
            p.probability,
            p.max_growth_rate,
            p.divergence_rates,
            tuple((m.label, m.frequency_hz, m.growth_rate) for m in p.squeak_modes),
        )

    @property
    def valid(self) -> bool:
        """True if the prediction is valid (Validity.OK)."""
        return self.validity is Validity.OK

    @property
    def stable(self) -> bool:
        """No squeak mode and no divergence (False outside validity: not a verdict)."""
        return self.valid and not self.squeak and not self.divergence_rates


def solve(
    spec: ModelSpec, speeds: np.ndarray, loads: np.ndarray, model_nuts: np.ndarray
) -> tuple[list[Verdict], list[Payloads | None]]:
    """`predict_jobs` as verdicts and the valid predictions' CDR payloads (None outside
    validity), encoded where they are solved: in a worker, the replaying process only copies
    bytes."""
    predictions = predict_jobs(spec, speeds, loads, model_nuts)
    return [Verdict.of(p) for p in predictions], [
        tuple(data for _, data in messages.prediction_payloads(p)) if p.valid else None
        for p in predictions
    ]


# glibc's mallopt parameters: the heap is trimmed only beyond the first, blocks from the
# second up are mapped (and unmapped when freed) on their own
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_WORKER_HEAP_BYTES = 1 << 28  # kept by a worker once freed
_WORKER_MMAP_BYTES = 1 << 25  # glibc's largest threshold (32 MB)


def start(spec: ModelSpec | None = None, samples: Samples | None = None) -> None:
    """A prediction worker's start (the pool's initializer): it ignores SIGINT (Ctrl-C reaches
    the whole process group, and the replaying process shuts the pool down), predicts with
    `samples` (the replaying process's draw of `spec`'s scatter, the same points: drawing
    them here would import scipy.stats) and keeps the memory its batches free: a batch's
    arrays of several MB (contacts, state matrices, the samples' friction) otherwise go back
    to the kernel and come again as fresh pages, each zeroed on its first touch (measured:
    about 12 % of a worker's time on the dense bench log; glibc only, elsewhere its
    allocator as it is).

    Parameters
    ----------
    spec : ModelSpec, optional
        What the worker predicts with.
    samples : Samples, optional
        `spec`'s scatter samples as the replaying process drew them; None: drawn here.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if spec is not None and samples is not None:
        share_samples(spec, samples)
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt(_M_TRIM_THRESHOLD, _WORKER_HEAP_BYTES)
        libc.mallopt(_M_MMAP_THRESHOLD, _WORKER_MMAP_BYTES)
    except (OSError, AttributeError):  # not glibc: its allocator as it is
        pass
