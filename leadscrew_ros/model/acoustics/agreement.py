# SPDX-License-Identifier: Apache-2.0
"""How well the predictions agree with what the microphone heard.

The comparison is made at the detector's frames, each standing for one hop of time. The
prediction in force at a frame is the latest one at or before it (zero-order hold, as the live
node publishes); before the first prediction a frame counts as not predicted with P(squeak) 0.
Only frames inside the span covered by both the sound (first to last frame) and the predictions
(first prediction to `valid_until_s`, by default the last prediction) count, so a recording that
starts before the predictor or outlasts it is not held against it. Frames whose P(squeak) is
unknown (None or nan) count for the times but not for the Brier score. With a `collar_s`, frames
closer than it to a heard episode's start or end are not counted either: the detector places an
edge only to about half its frame (`DetectorSettings.frame_s`), and sound-event evaluations
leave such a collar around onsets and offsets for the same reason (DCASE uses 200 ms).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .detection import Detection

#: A heard episode and a predicted mode match within this relative frequency error.
MATCH_TOLERANCE = 0.03


@dataclass
class FrequencyMatch:
    """A heard episode and the predicted squeak mode nearest to it in frequency.

    Attributes
    ----------
    start_s, end_s : float
        The heard episode [s].
    heard_hz : float
        Its frequency (median of its track) [Hz].
    label : str or None
        The nearest predicted squeak mode's label; None when none was predicted during it.
    predicted_hz : float or None
        Its frequency [Hz].
    relative_error : float or None
        (predicted - heard) / heard.
    matched : bool
        |relative_error| <= MATCH_TOLERANCE.
    heard_growth_per_s, heard_growth_se : float or None
        The episode's growth rate at its onset, measured from the sound, and its standard
        error [1/s] (`Episode.growth`); None when not measured.
    predicted_growth_per_s : float or None
        Re(lambda) of the nearest mode (its label) in the prediction in force at the onset, or
        its first prediction during the episode [1/s]; None without one.
    """

    start_s: float
    end_s: float
    heard_hz: float
    label: str | None
    predicted_hz: float | None
    relative_error: float | None
    matched: bool
    heard_growth_per_s: float | None = None
    heard_growth_se: float | None = None
    predicted_growth_per_s: float | None = None


@dataclass
class Agreement:
    """Seconds of agreement and disagreement, the scores, and the frequency matches.

    Attributes
    ----------
    both_s : float
        Time heard and predicted [s].
    predicted_only_s : float
        Time predicted but not heard [s].
    heard_only_s : float
        Time heard but not predicted [s].
    neither_s : float
        Time neither heard nor predicted [s].
    recall : float or None
        Share of the heard squeak time that was predicted (nominal verdict); None when nothing
        was heard.
    precision : float or None
        Share of the predicted squeak time that was heard; None when nothing was predicted.
    brier : float or None
        Mean of (P(squeak) - heard)^2 over the counted frames with a known P; None without.
    frequency_match : list of FrequencyMatch
        One per heard episode overlapping the counted span.
    frames : int
        Frames counted.
    """

    both_s: float
    predicted_only_s: float
    heard_only_s: float
    neither_s: float
    recall: float | None
    precision: float | None
    brier: float | None
    frequency_match: list[FrequencyMatch] = field(default_factory=list)
    frames: int = 0

    def as_dict(self) -> dict[str, Any]:
        """The agreement as a JSON-safe dict.

        Returns
        -------
        dict
        """
        return asdict(self)


def nearest_mode(f_hz: float, modes: Sequence[tuple[str, float]]) -> tuple[str, float] | None:
    """The predicted mode nearest in frequency to a heard tone.

    Parameters
    ----------
    f_hz : float
        The heard frequency [Hz].
    modes : sequence of (str, float)
        (label, frequency [Hz]) of the predicted squeak modes.

    Returns
    -------
    tuple of (str, float) or None
        The nearest mode (matched when within `MATCH_TOLERANCE` of `f_hz`); None without modes.
    """
    return min(modes, key=lambda m: abs(m[1] - f_hz), default=None)


def _probabilities(probability: ArrayLike, n: int) -> np.ndarray:
    p = np.array(
        [
            math.nan if v is None else float(v)
            for v in np.ravel(np.asarray(probability, dtype=object))
        ],
        dtype=float,
    )
    if p.size != n:
        raise ValueError(f"{p.size} probabilities for {n} prediction times")
    return p


def agreement(
    detection: Detection,
    pred_times_s: Any,
    predicted_squeak: Any,
    probability: ArrayLike,
    predicted_modes: Sequence[Sequence[tuple[str, float, float]]],
    *,
    valid_until_s: float | None = None,
    collar_s: float = 0.0,
) -> Agreement:
    """Compare the predictions with what the detector heard.

    Parameters
    ----------
    detection : Detection
        What the microphone heard (`detect`).
    pred_times_s : array_like
        Times of the predictions [s], increasing.
    predicted_squeak : array_like of bool
        Nominal verdict of each prediction.
    probability : sequence of float or None
        P(squeak) of each prediction (None: unknown).
    predicted_modes : sequence of sequence of (str, float, float)
        Per prediction: (label, frequency [Hz], Re(lambda) [1/s]) of its squeaking modes.
    valid_until_s : float, optional
        End of the span the predictions cover (default: the last prediction's time).
    collar_s : float
        Frames closer than this to a heard episode's start or end are not counted [s].

    Returns
    -------
    Agreement

    Raises
    ------
    ValueError
        When the per-prediction sequences differ in length.
    """
    tp = np.asarray(pred_times_s, dtype=float).reshape(-1)
    squeak = np.asarray(predicted_squeak, dtype=bool).reshape(-1)
    p = _probabilities(probability, tp.size)
    if squeak.size != tp.size or len(predicted_modes) != tp.size:
        raise ValueError(
            f"{tp.size} prediction times, {squeak.size} verdicts, "
            f"{len(predicted_modes)} mode lists: they must match"
        )
    t = detection.frame_times_s
    hop = detection.hop_s
    if t.size == 0 or tp.size == 0 or not math.isfinite(hop):
        return Agreement(0.0, 0.0, 0.0, 0.0, None, None, None)
    end = tp[-1] if valid_until_s is None else float(valid_until_s)
    counted = (t >= max(t[0], tp[0])) & (t <= min(t[-1], end))
    if detection.usable is not None and detection.usable.size == t.size:
        counted &= detection.usable  # no sound to judge by: NaN samples, a muted microphone
    if collar_s > 0 and detection.episodes:
        edges = np.sort([x for e in detection.episodes for x in (e.start_s, e.end_s)])
        k = np.searchsorted(edges, t)
        near = np.minimum(
            np.abs(t - edges[np.maximum(k - 1, 0)]),
            np.abs(t - edges[np.minimum(k, edges.size - 1)]),
        )
        counted &= near >= collar_s
    j = np.searchsorted(tp, t, side="right") - 1  # prediction in force, -1: none yet
    pred = np.where(j >= 0, squeak[np.maximum(j, 0)], False)
    prob = np.where(j >= 0, p[np.maximum(j, 0)], 0.0)
    heard = detection.heard
    both = float(np.sum(counted & heard & pred)) * hop
    pred_only = float(np.sum(counted & ~heard & pred)) * hop
    heard_only = float(np.sum(counted & heard & ~pred)) * hop
    neither = float(np.sum(counted & ~heard & ~pred)) * hop
    known = counted & np.isfinite(prob)
    brier = float(np.mean((prob[known] - heard[known]) ** 2)) if known.any() else None
    matches = []
    lo, hi = max(t[0], tp[0]), min(t[-1], end)
    for ep in detection.episodes:
        if ep.end_s < lo or ep.start_s > hi:
            continue
        j0 = max(int(np.searchsorted(tp, max(ep.start_s, lo), side="right")) - 1, 0)
        j1 = int(np.searchsorted(tp, min(ep.end_s, hi), side="right"))
        during = [
            (str(lab), float(f), float(g))
            for jj in range(j0, j1)
            for lab, f, g in predicted_modes[jj]
            if math.isfinite(float(f))
        ]
        growth = getattr(ep, "growth", None)
        measured = dict(
            heard_growth_per_s=growth.rate_per_s if growth is not None else None,
            heard_growth_se=growth.se_per_s if growth is not None else None,
        )
        nearest = nearest_mode(ep.frequency_hz, [(lab, f) for lab, f, _ in during])
        if nearest is not None:
            lab, f = nearest
            err = (f - ep.frequency_hz) / ep.frequency_hz
            # the first prediction of the episode holding the mode: the one at its onset
            sigma = next((g for m, _, g in during if m == lab), None)
            matches.append(
                FrequencyMatch(
                    ep.start_s,
                    ep.end_s,
                    ep.frequency_hz,
                    lab,
                    f,
                    err,
                    abs(err) <= MATCH_TOLERANCE,
                    predicted_growth_per_s=sigma
                    if sigma is not None and math.isfinite(sigma)
                    else None,
                    **measured,
                )
            )
        else:
            matches.append(
                FrequencyMatch(
                    ep.start_s, ep.end_s, ep.frequency_hz, None, None, None, False, **measured
                )
            )
    return Agreement(
        both_s=both,
        predicted_only_s=pred_only,
        heard_only_s=heard_only,
        neither_s=neither,
        recall=both / (both + heard_only) if both + heard_only > 0 else None,
        precision=both / (both + pred_only) if both + pred_only > 0 else None,
        brier=brier,
        frequency_match=matches,
        frames=int(counted.sum()),
    )
