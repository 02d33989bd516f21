# SPDX-License-Identifier: Apache-2.0
"""`review.decimation`: the bounded-memory series of a long replay's report. The envelope is
exactly what binning every sample at its final bin width gives (min, max, last, count), however
many flushes and pairwise merges it took; the reservoir is a uniform, reproducible sample kept
in arrival order."""

import numpy as np
import pytest

from leadscrew_ros.review import decimation
from leadscrew_ros.review.decimation import Envelope, Reservoir


def brute_force(t: np.ndarray, v: np.ndarray, width: float):
    """Every sample binned at `width`: (centres, lo, hi, last, count) of bins 0..last used."""
    k = (np.maximum(t, 0.0) // width).astype(int)
    n = k.max() + 1
    lo, hi, last = (np.full((n, v.shape[1]), np.nan) for _ in range(3))
    count = np.zeros(n, int)
    for i, row in zip(k, v, strict=True):
        lo[i], hi[i] = np.fmin(lo[i], row), np.fmax(hi[i], row)
        last[i] = row
        count[i] += 1
    return (np.arange(n) + 0.5) * width, lo, hi, last, count


@pytest.mark.parametrize("buffer", [3, 50, 8192])
@pytest.mark.parametrize("samples, span_s", [(40, 0.5), (2000, 7.3), (5000, 61.0)])
def test_the_envelope_is_the_binning_of_every_sample_at_its_final_width(
    monkeypatch, buffer, samples, span_s
):
    monkeypatch.setattr(decimation, "_BUFFER", buffer)  # flushes in the middle of merges
    rng = np.random.default_rng(samples)
    t = np.sort(rng.uniform(-0.05, span_s, samples))
    t[samples // 3 : samples // 3 + 20] = t[samples // 3]  # repeated times
    v = rng.normal(size=(samples, 3))
    v[::17, 1] = np.nan  # a missing value is skipped
    e = Envelope(3, max_bins=16, bin_s=0.1)
    for ti, row in zip(t, v, strict=True):
        e.add(float(ti), *row)
    got = e.series()
    # the width doubled just often enough for the last sample to fit in max_bins bins
    assert t[-1] < e.bin_s * 16 and (e.bin_s == 0.1 or t[-1] >= e.bin_s * 8)
    want = brute_force(t, v, e.bin_s)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)
    assert got[4].sum() == samples


def test_a_spike_of_one_sample_stays_its_bins_extreme():
    e = Envelope(2, max_bins=8, bin_s=0.1)
    for i in range(1000):
        e.add(i * 0.01, float(i), 1e6 if i == 500 else 0.0)
    t, lo, hi, last, count = e.series()
    assert len(t) <= 8 and count.sum() == 1000 and np.all(np.diff(t) > 0)
    assert lo[0, 0] == 0.0 and hi[-1, 0] == last[-1, 0] == 999.0
    assert np.nanmax(hi[:, 1]) == 1e6 and np.count_nonzero(hi[:, 1] == 1e6) == 1


def test_the_envelope_holds_constant_memory():
    e = Envelope(4, max_bins=64)
    before = e.nbytes
    for i in range(100_000):
        e.add(i * 0.1, 1.0, 2.0, 3.0, 4.0)
    e.flush()
    assert e.nbytes == before == 64 * (3 * 4 * 8 + 8)
    assert 32 <= e.bins <= 64


@pytest.mark.parametrize("max_bins", [0, 1, 7])
def test_an_odd_or_tiny_bin_count_is_refused(max_bins):
    with pytest.raises(ValueError, match="max_bins must be even"):
        Envelope(1, max_bins=max_bins)


def test_an_empty_envelope_has_no_bins():
    t, lo, hi, last, count = Envelope(2).series()
    assert len(t) == len(count) == 0 and lo.shape == (0, 2)


# ----------------------------------------------------------------------------- reservoir
def test_a_short_stream_is_kept_whole_in_order():
    r = Reservoir(2, size=10)
    for i in range(7):
        r.add(float(i), -float(i))
    np.testing.assert_array_equal(r.sample(), [[i, -i] for i in range(7)])


def test_the_reservoir_keeps_whole_rows_in_arrival_order_and_is_reproducible():
    def run(seed):
        r = Reservoir(3, size=50, seed=seed)
        for i in range(5000):
            r.add(float(i), 2.0 * i, -1.0)
        return r

    a = run(0)
    kept = a.sample()
    assert kept.shape == (50, 3) and a.seen == 5000
    assert np.all(np.diff(kept[:, 0]) > 0)  # arrival order
    np.testing.assert_array_equal(kept[:, 1], 2.0 * kept[:, 0])  # rows stay whole
    np.testing.assert_array_equal(kept, run(0).sample())  # the same log, the same sample
    assert not np.array_equal(kept, run(1).sample())
    assert a.nbytes == 50 * 3 * 8 + 50 * 8


def test_every_arrival_is_equally_likely_to_be_kept():
    """Algorithm R: each of N rows is kept with probability size / N. Over 400 seeds (4000
    kept rows of 100 arrivals each) every decile of the stream holds about a tenth of them."""
    per_decile = np.zeros(10)
    for seed in range(400):
        r = Reservoir(1, size=10, seed=seed)
        for i in range(100):
            r.add(float(i))
        per_decile += np.bincount((r.sample()[:, 0] // 10).astype(int), minlength=10)
    share = per_decile / per_decile.sum()
    # binomial sd of a decile's share: sqrt(0.1 * 0.9 / 4000) = 0.0047; 0.02 is > 4 sd
    assert np.all(np.abs(share - 0.1) < 0.02), share
