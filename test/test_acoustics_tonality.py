# SPDX-License-Identifier: Apache-2.0
"""ECMA-418-1 limits, short-time spectra, and TNR / PR against MOSQITO on the same signals."""

import numpy as np
import pytest

from leadscrew_ros.model.acoustics.tonality import (
    ToneAnalyzer,
    critical_band,
    phasor,
    pr_limit_db,
    short_time_psd,
    tnr_limit_db,
)

FS = 48000


def test_limits_at_the_notes_frequencies():
    f = np.array([224.0, 898.0, 2653.0, 1000.0, 89.1])
    assert tnr_limit_db(f) == pytest.approx([13.41, 8.39, 8.0, 8.0, 16.75], abs=0.01)
    assert pr_limit_db(f) == pytest.approx([15.50, 9.47, 9.0, 9.0, 19.50], abs=0.01)


def test_critical_band_is_ecma_418_1():
    f1, f2 = critical_band(np.array([224.0, 500.0, 2653.0]))
    assert f2 - f1 == pytest.approx([103.6, 117.3, 413.7], abs=0.1)
    assert (f1[0] + f2[0]) / 2 == pytest.approx(224.0)  # arithmetic below 500 Hz
    assert np.sqrt(f1[2] * f2[2]) == pytest.approx(2653.0, rel=2e-3)  # ~geometric above


def test_psd_keeps_the_mean_square():
    """Summed over the bins, the PSD of white noise is its variance; a sine's is A^2 / 2."""
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 0.1, FS).astype(np.float32)
    psd = short_time_psd(x, FS, 4800, 480)
    assert psd.shape == (91, 2401) and psd.dtype == np.float32
    assert np.mean(psd.sum(axis=1) * 10.0) == pytest.approx(0.01, rel=0.02)
    t = np.arange(FS) / FS
    s = (0.5 * np.sin(2 * np.pi * 1234.5 * t)).astype(np.float32)
    assert np.median(short_time_psd(s, FS, 4800, 480).sum(axis=1) * 10.0) == pytest.approx(
        0.125, rel=1e-3
    )


def test_psd_of_the_analysed_bins_is_the_whole_psd_cut():
    """`bins`: the first bins of the whole spectrum, the same values (the Nyquist bin's
    halving only where it is kept)."""
    x = np.random.default_rng(1).normal(0.0, 0.1, FS // 2).astype(np.float32)
    whole = short_time_psd(x, FS, 4800, 480)
    assert np.array_equal(short_time_psd(x, FS, 4800, 480, bins=1400), whole[:, :1400])
    assert np.array_equal(short_time_psd(x, FS, 4800, 480, bins=9999), whole)


def test_phasor_is_the_complex_exponential_within_float32_rounding():
    """exp(-2 pi i cycles) over phases of thousands of cycles (a squeak's over seconds):
    within 1e-6, as complex64."""
    cycles = np.cumsum(np.full(96000, 2479.3 / FS)) + 0.123
    got = phasor(cycles)
    assert got.dtype == np.complex64
    assert np.max(np.abs(got - np.exp(-2j * np.pi * cycles))) < 1e-6


def _tone(f, snr_db, seed, n=FS):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    amp = np.sqrt(2.0) * 10 ** (snr_db / 20)  # broadband SNR against unit noise
    return 0.02 * (amp * np.sin(2 * np.pi * f * t) + rng.normal(0.0, 1.0, n))


def _mine(x, frame):
    an = ToneAnalyzer(FS, frame, 89.1, 11200.0, 8)
    c = an.candidates(short_time_psd(x, FS, frame, frame))
    return c


CASES = [
    (224.0, -10.0),
    (224.0, 0.0),
    (898.0, -20.0),
    (898.0, -10.0),
    (898.0, 0.0),
    (2653.0, -10.0),
    (2653.0, 0.0),
    (5000.0, -10.0),
    (5000.0, 0.0),
]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize(("f", "snr"), CASES)
def test_tnr_and_pr_within_1_db_of_mosqito(f, snr, seed):
    """Same 1 s signal, same 1 Hz resolution (one frame): |mine - MOSQITO| <= 1 dB for the
    tone's TNR and PR (measured over these 36 cases: TNR 0.02-0.76 dB lower, PR 0-0.53 dB
    lower; MOSQITO labels bin k as (k + 1) Hz and takes the tone's width as one bin).

    Not every noise draw compares: when MOSQITO's screening finds a second peak inside the
    tone's critical band farther than its proximity distance (21 Hz at 224 Hz), it takes the
    tone's level from the single peak bin and counts the Hann neighbours as noise, which lowers
    its TNR by up to 11 dB (seen with seed 214 at 224 Hz, -10 dB); these seeds avoid that."""
    sq = pytest.importorskip("mosqito.sq_metrics")
    x = _tone(f, snr, seed)
    c = _mine(x, FS)
    i = np.argmin(np.abs(c.frequency_hz[0] - f))
    assert c.frequency_hz[0, i] == pytest.approx(f, abs=0.5)
    _, tnr, _, tf = sq.tnr_ecma_st(x, FS, prominence=False)
    _, pr, _, pf = sq.pr_ecma_st(x, FS, prominence=False)
    j, k = (
        np.argmin(np.abs(np.asarray(tf, float) - f)),
        np.argmin(np.abs(np.asarray(pf, float) - f)),
    )
    assert abs(tf[j] - f) <= 2.0 and abs(pf[k] - f) <= 2.0
    assert c.tnr_db[0, i] == pytest.approx(tnr[j], abs=1.0)
    assert c.pr_db[0, i] == pytest.approx(pr[k], abs=1.0)


@pytest.mark.parametrize(
    ("f", "snr"), [(224.0, -10.0), (898.0, -10.0), (2653.0, -10.0), (5000.0, 0.0)]
)
def test_short_frames_agree_with_mosqito_in_the_median(f, snr):
    """The detector's 0.1 s frames: the median over the frames within 1.5 dB of MOSQITO's 1 s
    stationary value (measured: within 0.6 dB)."""
    sq = pytest.importorskip("mosqito.sq_metrics")
    x = _tone(f, snr, seed=7)
    an = ToneAnalyzer(FS, 4800, 89.1, 11200.0, 8)
    c = an.candidates(short_time_psd(x, FS, 4800, 480))
    i = np.argmin(np.abs(c.frequency_hz - f), axis=1)[:, None]
    tnr = np.median(np.take_along_axis(c.tnr_db, i, axis=1))
    pr = np.median(np.take_along_axis(c.pr_db, i, axis=1))
    _, ref_tnr, _, tf = sq.tnr_ecma_st(x, FS, prominence=False)
    _, ref_pr, _, pf = sq.pr_ecma_st(x, FS, prominence=False)
    assert tnr == pytest.approx(ref_tnr[np.argmin(np.abs(np.asarray(tf, float) - f))], abs=1.5)
    assert pr == pytest.approx(ref_pr[np.argmin(np.abs(np.asarray(pf, float) - f))], abs=1.5)


def test_a_strong_tone_is_one_candidate_without_side_lobes():
    t = np.arange(FS) / FS
    x = (
        0.5 * np.sin(2 * np.pi * 1503.7 * t) + 1e-5 * np.random.default_rng(1).normal(size=FS)
    ).astype(np.float32)
    c = ToneAnalyzer(FS, 4800, 89.1, 11200.0, 8).candidates(short_time_psd(x, FS, 4800, 480))
    assert np.all(c.prominent.sum(axis=1) == 1)
    f = c.frequency_hz[c.prominent]
    assert np.all(np.abs(f - 1503.7) < 1.0)


def test_low_sample_rate_limits_the_band():
    an = ToneAnalyzer(16000, 1600, 89.1, 11200.0, 8)
    assert 6000 < an.f_hi_hz < 8000
    assert ToneAnalyzer(1000, 100, 89.1, 11200.0, 8).f_hi_hz < 500


def test_a_gate_measures_its_peaks_as_without_one():
    """With a gate the band powers are summed at the peaks through it only, without one from
    the cumulative sum over every bin: the same peaks get the same frequency, power, TNR, PR
    and verdicts (six tones of 10 to 30 dB in noise, a gate below all of them)."""
    rng = np.random.default_rng(7)
    t = np.arange(2 * FS) / FS
    tones = [(224.0, 10.0), (898.0, 20.0), (1503.7, 30.0), (2653.0, 15.0), (4100.0, 25.0)]
    x = rng.normal(0.0, 0.01, t.size)
    for f, snr in tones + [(7020.5, 12.0)]:
        x += 0.01 * np.sqrt(2.0) * 10 ** (snr / 20) * np.sin(2 * np.pi * f * t)
    psd = short_time_psd(x.astype(np.float32), FS, 4800, 480)
    an = ToneAnalyzer(FS, 4800, 89.1, 11200.0, 8)
    ungated = an.candidates(psd)
    gate = np.full(an.k_hi - an.k_lo + 1, 1e-5)  # a tone of 10 dB here: 1.6e-4
    gated = an.candidates(psd, reference=gate)
    for j in range(psd.shape[0]):
        mine = {round(f, 6): i for i, f in enumerate(gated.frequency_hz[j]) if gated.valid[j, i]}
        theirs = np.flatnonzero(ungated.valid[j] & ungated.tonal[j])
        assert len(theirs) == 6
        for i in theirs:  # every tonal peak without a gate is through it, measured alike
            k = mine[round(ungated.frequency_hz[j, i], 6)]
            assert gated.power[j, k] == ungated.power[j, i]
            assert gated.tnr_db[j, k] == pytest.approx(ungated.tnr_db[j, i], abs=1e-9)
            assert gated.pr_db[j, k] == pytest.approx(ungated.pr_db[j, i], abs=1e-9)
            assert gated.tonal[j, k] and gated.prominent[j, k] == ungated.prominent[j, i]


def test_a_block_ranks_as_many_peaks_as_its_most_tonal_frame_needs():
    """Without a gate every frame of a block keeps as many columns as its most tonal frame
    needs (ranked by pieces of frames, a piece ranked with fewer is ranked again): twelve
    tones in the last frames are all found, and the first frames, a piece away, keep the
    tonal candidates they have alone."""
    rng = np.random.default_rng(3)
    t = np.arange(2 * FS) / FS
    x = rng.normal(0.0, 0.01, t.size)
    series = 300.0 * 1.35 ** np.arange(12)  # 300 Hz .. 8.1 kHz, over a critical band apart
    late = t >= 1.2
    for k, f in enumerate(series):
        x += (1.0 if k % 5 == 0 else late) * 0.05 * np.sin(2 * np.pi * f * t)
    psd = short_time_psd(x.astype(np.float32), FS, 4800, 480)
    an = ToneAnalyzer(FS, 4800, 89.1, 11200.0, 8)
    whole = an.candidates(psd)
    assert whole.frequency_hz.shape[1] >= 12
    assert np.all(np.count_nonzero(whole.tonal[-20:], axis=1) == 12)
    alone = an.candidates(psd[:40])
    assert alone.frequency_hz.shape[1] < whole.frequency_hz.shape[1]
    for j in range(40):
        assert sorted(whole.frequency_hz[j, whole.tonal[j]]) == sorted(
            alone.frequency_hz[j, alone.tonal[j]]
        )
