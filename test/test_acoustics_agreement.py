# SPDX-License-Identifier: Apache-2.0
"""agreement(): seconds, recall, precision, Brier and frequency matches on constructed cases."""

import json

import numpy as np
import pytest

from leadscrew_ros.model.acoustics import Detection, Episode
from leadscrew_ros.model.acoustics.agreement import agreement


def _detection(heard_spans, t0=0.0, t1=10.0, hop=0.01, hz=1000.0):
    """Frames every `hop` from t0 + hop/2; heard inside the (start, end) spans."""
    t = t0 + hop / 2 + np.arange(int(round((t1 - t0) / hop))) * hop
    heard = np.zeros(t.size, bool)
    eps = []
    for a, b in heard_spans:
        inside = (t > a) & (t < b)
        heard |= inside
        eps.append(Episode(a, b, hz, 20.0, 20.0, -30.0))
    freq = np.where(heard, hz, np.nan)
    return Detection(t, heard, freq, eps, 48000.0, "full scale", [])


def test_seconds_recall_precision_brier_by_hand():
    """Heard 2-4 s; predicted squeak from 3 s to 6 s (P 0.8), silent before (P 0.1) and
    after (P 0.2); predictions at 1, 3, 6 s and a last one at 9 s: frames 1-9 s count (800)."""
    d = _detection([(2.0, 4.0)])
    a = agreement(
        d,
        [1.0, 3.0, 6.0, 9.0],
        [False, True, False, False],
        [0.1, 0.8, 0.2, 0.2],
        [[], [("b1", 1010.0, 12.0)], [], []],
    )
    assert a.frames == 800
    assert a.both_s == pytest.approx(1.0)  # 3-4 s
    assert a.heard_only_s == pytest.approx(1.0)  # 2-3 s
    assert a.predicted_only_s == pytest.approx(2.0)  # 4-6 s
    assert a.neither_s == pytest.approx(4.0)  # 1-2 s and 6-9 s
    assert a.recall == pytest.approx(0.5) and a.precision == pytest.approx(1 / 3)
    # 1-2 s P .1 silent, 2-3 s P .1 heard, 3-4 s P .8 heard, 4-6 s P .8 silent, 6-9 s P .2
    brier = (100 * 0.1**2 + 100 * 0.9**2 + 100 * 0.2**2 + 200 * 0.8**2 + 300 * 0.2**2) / 800
    assert a.brier == pytest.approx(brier)
    (m,) = a.frequency_match
    assert (m.label, m.predicted_hz, m.matched) == ("b1", 1010.0, True)
    assert m.relative_error == pytest.approx(0.01)
    assert m.predicted_growth_per_s == 12.0  # Re(lambda) beside the (unmeasured) growth
    assert m.heard_growth_per_s is None and m.heard_growth_se is None
    json.dumps(a.as_dict(), allow_nan=False)


def test_the_measured_growth_beside_the_predicted_re_lambda_at_the_onset():
    """The episode's measured growth and the matched mode's Re(lambda) in the prediction in
    force at its onset (not a later one)."""
    from leadscrew_ros.model.acoustics.growth import Growth

    d = _detection([(2.0, 4.0)])
    d.episodes[0].growth = Growth(31.0, 2.5, (1.95, 2.1), 40.0)
    modes = [[("b1", 1005.0, 25.0)], [("b1", 1010.0, 60.0), ("t1", 3000.0, 5.0)], []]
    a = agreement(d, [1.5, 3.0, 6.0], [True, True, False], [0.9, 0.9, 0.1], modes)
    (m,) = a.frequency_match
    assert m.label == "b1" and m.predicted_growth_per_s == 25.0
    assert (m.heard_growth_per_s, m.heard_growth_se) == (31.0, 2.5)


def test_zero_order_hold_and_the_span_that_counts():
    """Sound 0-10 s, predictions 5-8 s (valid until 8.5 s): only 5-8.5 s counts; the hold keeps
    the 7 s verdict to 8.5 s."""
    d = _detection([(0.0, 6.0)])
    a = agreement(
        d, [5.0, 7.0], [True, True], [1.0, 1.0], [[("t1", 2000.0, 3.0)], []], valid_until_s=8.5
    )
    assert a.frames == 350
    assert a.both_s == pytest.approx(1.0) and a.predicted_only_s == pytest.approx(2.5)
    assert a.heard_only_s == 0.0 and a.neither_s == 0.0
    assert a.recall == 1.0 and a.precision == pytest.approx(1 / 3.5)
    assert a.brier == pytest.approx(2.5 / 3.5)
    (m,) = a.frequency_match
    assert m.label == "t1" and not m.matched and m.relative_error == pytest.approx(1.0)


def test_nothing_heard_or_nothing_predicted():
    d = _detection([])
    a = agreement(d, [0.0, 5.0], [False, False], [0.0, None], [[], []])
    assert a.recall is None and a.precision is None
    assert a.neither_s == pytest.approx(5.0) and a.brier == pytest.approx(0.0)  # 0-5 s known
    d = _detection([(1.0, 2.0)])
    a = agreement(d, [0.0, 5.0], [False, False], [0.0, 0.0], [[], []])
    assert a.recall == 0.0 and a.precision is None and a.heard_only_s == pytest.approx(1.0)
    (m,) = a.frequency_match
    assert m.label is None and m.predicted_hz is None and not m.matched


def test_nearest_mode_of_the_predictions_during_the_episode():
    d = _detection([(2.0, 3.0)], hz=1500.0)
    modes = [
        [("a", 900.0, 1.0)],
        [("b", 1480.0, 2.0), ("c", 3000.0, 3.0)],
        [("d", 1501.0, 4.0)],
        [("e", 1500.0, 5.0)],
    ]
    a = agreement(d, [0.0, 2.5, 2.9, 3.5], [True] * 4, [0.9] * 4, modes)
    (m,) = a.frequency_match  # a (in force at 2 s), b, d; e comes after the episode
    assert m.label == "d" and m.matched


def test_empty_inputs_and_mismatched_lengths():
    a = agreement(_detection([], t1=0.0), [1.0], [True], [0.5], [[]])
    assert a.frames == 0 and a.recall is None and a.brier is None
    with pytest.raises(ValueError, match="must match"):
        agreement(_detection([]), [1.0, 2.0], [True], [0.5, 0.5], [[], []])
    with pytest.raises(ValueError, match="probabilities"):
        agreement(_detection([]), [1.0, 2.0], [True, True], [0.5], [[], []])
