# SPDX-License-Identifier: Apache-2.0
"""The observation model: what a microphone can hear of a squeak that grows from the floor.

A frame is not heard because the model's growth rate sigma = Re(lambda) of the most unstable
mode is positive there, but because the squeak has grown loud enough by then. Near the Hopf
bifurcation the mode's amplitude A obeys d(ln A)/dt = sigma - l A^2 (the amplitude equation,
`acoustics.envelope`); in the log-amplitude over the noise floor, a = ln(A / A_floor) [Np]:

    da/dt = sigma(t)    for 0 < a < depth                                      (A1)

held at 0 (the floor: broadband friction and drive excitation keep a stable mode ringing
there) and at `depth` (the limit cycle). A frame is heard when a >= h and the mode is in the
detector's band (`GrowthLikelihood.growth_rates`), with the detector's false-alarm and miss
rates (`DetectionErrors`). Along a ramp sigma crosses zero and rises at some rate; the squeak
then needs the time that integral of sigma takes to reach h, so it becomes audible late, the
later the slower sigma rises (slow passage through the bifurcation), and it stays audible
after sigma falls below zero for (depth - h) / |sigma|. Where the operating point leaves the
model's range (the drive stands) a returns to the floor; mode switches carry it (one a, of the
most unstable mode).

(A1) with both bounds is a map a_k = clip(a_{k-1} + sigma_k dt, 0, depth) per frame; such
maps are closed under composition (clip(clip(x + c1, l1, u1) + c2, l2, u2) = clip(x + c1 + c2,
clip(l1 + c2, l2, u2), clip(u1 + c2, l2, u2))), so the amplitude at every frame is an
inclusive scan over the stroke: log2(runs) vectorised passes (a run is consecutive frames at
one point, whose composition is one map), not a loop over frames.

h and depth are the bench's (its microphone, its room, its drive's noise), not the unit's:
a grid of `HearingPrior` (normal in dB, documented defaults) over which each unit's likelihood
is marginalised; the run then learns the bench's grid posterior from all its units
(`bench_posterior`) and re-weights their samples to it.

Growth rates as data: each heard onset's measured rate r +- se (`acoustics.growth`) is compared
with sigma at the onset's frame, with a relative model error (the measured rate is that of the
sound through the room, over a window in which sigma moves) and a share of outliers (an onset
the detector misplaced):

    p(r | sigma) = (1 - o) N(r; sigma, se^2 + (e r)^2) + o / r_max                 (A2)

Only a resolved growth enters (A2): r at least `HearingPrior.onset_min_t` SEs over zero. An
episode that starts without one is no growth from the floor measured (a tone heard again after
a short dropout, while the model decays it; one fading in over the room's noise); on the
realistic bench such rates (0-15 1/s +- 10-30, where the model decays at 20-50 1/s) were
within the Gaussian's reach, not the outliers', and pulled the units' drop and damping down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import logsumexp
from scipy.stats import norm

from ..physics.metadata import check, documented, setting
from ..physics.parameters import ParameterError, ScrewParameters
from .likelihood import GrowthLikelihood
from .observations import CalibrationError

NP_PER_DB = math.log(10.0) / 20.0  # a level in dB is this many nepers of amplitude
# The scan runs in float32 (half the memory traffic; a is compared with thresholds of whole
# dB, 0.1 Np, and float32 keeps it to ~1e-5 Np). A run without a point moves a by FLOOR_STEP
# per frame (finite, so no inf - inf): far below any depth. _BIG is an identity map's bound.
FLOOR_STEP = -1.0e4
_BIG = 1.0e30


@documented
@dataclass(frozen=True)
class HearingPrior:
    """The prior of the bench's detection threshold and floor depth, and of the growth data
    (module docstring).

    The defaults are wide: a squeak whose limit cycle stands some 15-65 dB over the level it
    grows from and that is heard 0-40 dB over that level (the squeak's floor lies under the
    room's background, which the detector needs a tone to exceed by its TNR threshold), down
    to a tone heard almost at once (a low threshold and a shallow floor: a bench whose tone
    starts and stops within a frame).
    """

    threshold_db: float = setting(
        20.0,
        "dB",
        "prior mean of the detection threshold h: the squeak's level over its floor at which "
        "the detector hears it",
        0.0,
        200.0,
        lo_open=True,
    )
    threshold_sd_db: float = setting(
        12.0, "dB", "prior SD of the detection threshold", 0.0, 100.0, lo_open=True
    )
    depth_db: float = setting(
        40.0,
        "dB",
        "prior mean of the floor's depth: the limit cycle's level over the floor",
        0.0,
        300.0,
        lo_open=True,
    )
    depth_sd_db: float = setting(
        20.0, "dB", "prior SD of the floor's depth", 0.0, 100.0, lo_open=True
    )
    headroom_db: float = setting(
        3.0,
        "dB",
        "the threshold lies at least this far under the limit cycle (grid cells beyond have "
        "no prior mass)",
        0.0,
        100.0,
    )
    threshold_points: int = setting(
        8, "1", "grid points of the threshold (at equal prior mass)", 1, 64
    )
    depth_points: int = setting(3, "1", "grid points of the depth (at equal prior mass)", 1, 16)
    onset_error: float = setting(
        0.15,
        "1",
        "relative model error of a measured onset growth rate against sigma at the middle of "
        "its fit window (on the realistic bench, at the units' own parameters, within ~8 %)",
        0.0,
        10.0,
    )
    onset_outlier: float = setting(
        0.1, "1", "share of measured onset rates that are outliers", 0.0, 1.0, hi_open=True
    )
    max_rate_per_s: float = setting(
        1000.0,
        "1/s",
        "an outlier rate is uniform on 0 .. this (faster growth is complete within a frame)",
        1.0,
        1e6,
    )
    onset_min_t: float = setting(
        2.0,
        "1",
        "a measured onset rate is a growth only this many standard errors over zero; a "
        "weaker one (a tone heard again after a dropout, one fading in over the room) is left "
        "out of (A2)",
        0.0,
        100.0,
    )

    def __post_init__(self) -> None:
        check(self, ParameterError, "hearing.")

    def resolved(self, rate: np.ndarray, se: np.ndarray) -> np.ndarray:
        """Which measured onset rates are a resolved growth (`onset_min_t` SEs over zero).

        Parameters
        ----------
        rate, se : numpy.ndarray
            Measured rates and their standard errors [1/s].

        Returns
        -------
        numpy.ndarray
            bool, the rates that enter (A2).
        """
        rate, se = np.asarray(rate, float), np.asarray(se, float)
        return np.isfinite(rate) & np.isfinite(se) & (rate > 0) & (rate >= self.onset_min_t * se)

    def onset_sd(self, rate: np.ndarray, se: np.ndarray) -> np.ndarray:
        """(A2)'s spread of a measured rate about sigma: its SE and the relative model error.

        Parameters
        ----------
        rate, se : numpy.ndarray
            Measured rates and their standard errors [1/s].

        Returns
        -------
        numpy.ndarray
            The SDs [1/s].
        """
        return np.sqrt(np.asarray(se, float) ** 2 + (self.onset_error * np.asarray(rate)) ** 2)

    def grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The grid the likelihood is marginalised over.

        Returns
        -------
        threshold_np : numpy.ndarray
            (Kh,) increasing thresholds h [Np].
        depth_np : numpy.ndarray
            (Kd,) increasing depths [Np].
        log_weight : numpy.ndarray
            (Kd, Kh) log prior mass of each cell (-inf where h is within `headroom_db` of
            the depth), normalised.

        Raises
        ------
        ParameterError
            No cell with prior mass.
        """

        def points(mean: float, sd: float, k: int) -> np.ndarray:
            return mean + sd * norm.ppf((np.arange(k) + 0.5) / k)

        h = np.maximum(points(self.threshold_db, self.threshold_sd_db, self.threshold_points), 0.5)
        depth = points(self.depth_db, self.depth_sd_db, self.depth_points)
        ok = h[None, :] <= depth[:, None] - self.headroom_db
        if not ok.any():
            raise ParameterError(
                "hearing: no threshold lies under the depth: raise hearing.depth_db or lower "
                "hearing.threshold_db"
            )
        log_weight = np.where(ok, 0.0, -np.inf)
        return h * NP_PER_DB, depth * NP_PER_DB, log_weight - logsumexp(log_weight)

    def summary(self, log_posterior: np.ndarray) -> dict[str, Any]:
        """The threshold's and the depth's posterior mean and 5 / 95 % points [dB] from a
        grid posterior, beside the prior's.

        Parameters
        ----------
        log_posterior : numpy.ndarray
            (Kd, Kh) log weights of the grid (`bench_posterior`).

        Returns
        -------
        dict
            {'threshold_db' | 'depth_db': {mean, q05, q95, prior_mean, prior_sd, grid}} and
            'log_posterior' (the (Kd, Kh) weights as lists; -inf where a cell has no mass).
        """
        h, depth, _ = self.grid()
        p = np.exp(log_posterior - logsumexp(log_posterior))
        out = {}
        for name, values, marginal, mean, sd in (
            ("threshold_db", h, p.sum(axis=0), self.threshold_db, self.threshold_sd_db),
            ("depth_db", depth, p.sum(axis=1), self.depth_db, self.depth_sd_db),
        ):
            db = values / NP_PER_DB
            cdf = np.cumsum(marginal)
            at = np.minimum(np.searchsorted(cdf, [0.05, 0.95]), len(db) - 1)
            q05, q95 = (float(x) for x in db[at])
            out[name] = {
                "mean": float(marginal @ db),
                "q05": q05,
                "q95": q95,
                "prior_mean": mean,
                "prior_sd": sd,
                "grid": db.tolist(),
            }
        out["log_posterior"] = log_posterior.tolist()  # (depth, threshold) cells
        return out


def _scan(c: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, ...]:
    """Inclusive scan of clip maps x -> clip(x + c, lo, hi) along the last axis (module
    docstring): the k-th result is map k after map k-1 ... after map 0 (Hillis-Steele)."""
    c, lo, hi = c.copy(), lo.copy(), hi.copy()
    n, shift = c.shape[-1], 1
    while shift < n:
        c2, lo2, hi2 = c[..., shift:], lo[..., shift:], hi[..., shift:]
        new_c = c[..., :-shift] + c2
        new_lo = np.minimum(np.maximum(lo[..., :-shift] + c2, lo2), hi2)
        new_hi = np.minimum(np.maximum(hi[..., :-shift] + c2, lo2), hi2)
        c[..., shift:], lo[..., shift:], hi[..., shift:] = new_c, new_lo, new_hi
        shift *= 2
    return c, lo, hi


def _compose(c: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, ...]:
    """`_scan` in blocks of about sqrt(n): within each block, over the blocks' totals, then
    each block after its prefix; log2(n) / 2 + 1 passes over the whole array, not log2(n)."""
    n = c.shape[-1]
    b = max(int(math.isqrt(max(n - 1, 0))) + 1, 1)
    blocks = -(-n // b)
    pad = blocks * b - n
    big = np.asarray(_BIG, c.dtype)
    shape = (*c.shape[:-1], blocks, b)

    def padded(x: np.ndarray, fill: np.ndarray) -> np.ndarray:  # identity maps at the end
        return np.concatenate([x, np.broadcast_to(fill, (*x.shape[:-1], pad))], -1).reshape(shape)

    cb, lb, hb = padded(c, np.zeros((), c.dtype)), padded(lo, -big), padded(hi, big)
    cb, lb, hb = _scan(cb, lb, hb)
    tc, tl, th = _scan(cb[..., -1], lb[..., -1], hb[..., -1])
    # the prefix before each block: the identity for the first, the scanned totals after
    pc = np.concatenate([np.zeros_like(tc[..., :1]), tc[..., :-1]], -1)[..., None]
    pl = np.concatenate([np.full_like(tl[..., :1], -big), tl[..., :-1]], -1)[..., None]
    ph = np.concatenate([np.full_like(th[..., :1], big), th[..., :-1]], -1)[..., None]
    out_c = pc + cb
    out_lo = np.minimum(np.maximum(pl + cb, lb), hb)
    out_hi = np.minimum(np.maximum(ph + cb, lb), hb)
    return tuple(x.reshape(*c.shape[:-1], -1)[..., :n] for x in (out_c, out_lo, out_hi))


class AmplitudeLikelihood:
    """Log-likelihood of a unit's frame sequence under the observation model (module
    docstring), over draws of the calibrated parameters.

    Parameters
    ----------
    growth : GrowthLikelihood
        The unit's expansion: growth rates per point and draw, bounds, names.
    hearing : HearingPrior, optional
        The grid and growth-data settings; the defaults when None.
    log_weight : numpy.ndarray, optional
        (Kd, Kh) log weights of the grid cells (the bench's posterior); the prior's when None.

    Raises
    ------
    CalibrationError
        Observations without their frame sequence, or weights of the wrong shape.
    """

    def __init__(
        self,
        growth: GrowthLikelihood,
        hearing: HearingPrior | None = None,
        log_weight: np.ndarray | None = None,
    ):
        obs = growth.obs
        if not len(obs.sequence):
            raise CalibrationError(
                f"unit {obs.unit_id}: the observations have no frame sequence: the observation "
                "model needs the frames in time order (thin them with their times)"
            )
        self.growth, self.obs = growth, obs
        self.hearing = hearing or HearingPrior()
        self.threshold_np, self.depth_np, prior_weight = self.hearing.grid()
        self.log_weight = prior_weight if log_weight is None else np.asarray(log_weight, float)
        if self.log_weight.shape != prior_weight.shape:
            raise CalibrationError(
                f"grid weights of shape {self.log_weight.shape}, need {prior_weight.shape}"
            )
        seq, reset = obs.sequence, obs.frame_reset
        new_run = reset | np.r_[True, seq[1:] != seq[:-1]]
        self._run_start = np.flatnonzero(new_run)
        self._run_len = np.diff(np.r_[self._run_start, seq.size])
        self._run_point = seq[self._run_start]
        self._run_reset = reset[self._run_start]
        frame_run = self._all_run = np.cumsum(new_run) - 1
        # only the counted frames at a point are scored: the amplitude is needed there alone
        self._used = np.flatnonzero(obs.frame_counted & (seq >= 0))
        self._frame_run = frame_run[self._used]
        self._frame_k = self._used - self._run_start[self._frame_run] + 1
        w = growth.errors.frame_weight(obs.frame_s)
        heard = obs.frame_heard & obs.frame_counted
        quiet = ~obs.frame_heard & obs.frame_counted
        q0, q1 = growth.errors.heard_probability(np.array([0.0, 1.0]))
        self._delta = (
            w * (heard * math.log(q1 / q0) + quiet * (math.log1p(-q1) - math.log1p(-q0)))
        )[self._used]
        self._base = float(np.sum(w * (heard * math.log(q0) + quiet * math.log1p(-q0))))
        onsets = obs.onsets[obs.sequence[obs.onsets[:, 0].astype(int)] >= 0]
        onsets = onsets[self.hearing.resolved(onsets[:, 1], onsets[:, 2])]
        self._onset_point = obs.sequence[onsets[:, 0].astype(int)]
        self._onset_rate, self._onset_se = onsets[:, 1], onsets[:, 2]

    # the expansion's attributes, for the sampler
    @property
    def names(self) -> tuple[str, ...]:
        """The calibrated parameters."""
        return self.growth.names

    @property
    def centre(self) -> np.ndarray:
        """(D,) the expansion centre's values of `names`."""
        return self.growth.centre

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the box outside which the log-likelihood is -inf."""
        return self.growth.bounds

    @property
    def valid(self) -> np.ndarray:
        """(P,) the points where the model holds."""
        return self.growth.valid

    @property
    def evaluations(self) -> int:
        """Draws evaluated so far."""
        return self.growth.evaluations

    def amplitude(
        self, theta: np.ndarray, depth_np: float, every: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """The log-amplitude over the floor at every frame, (A1) with one depth.

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.
        depth_np : float
            The limit cycle's level over the floor [Np].
        every : bool
            At every frame at a point (`Observations.sequence` >= 0), not only the scored
            ones.

        Returns
        -------
        a : numpy.ndarray
            (W, m) [Np] at each scored frame (`scored`), or at every frame at a point.
        hearable : numpy.ndarray
            (W, m) bool: the most unstable mode there is in the detector's band.
        """
        sigma, in_band = self.growth.growth_rates(theta)
        frames = np.flatnonzero(self.obs.sequence >= 0) if every else self._used
        a = self._amplitudes(sigma, np.array([depth_np]), frames)[0]
        return a, in_band[:, self.obs.sequence[frames]]

    @property
    def scored(self) -> np.ndarray:
        """(m,) the frames that are scored (counted, at a point): indices into
        `Observations.sequence`."""
        return self._used

    def _steps(self, sigma: np.ndarray) -> np.ndarray:
        """(W, R) float32: the change of a per frame of each run (`FLOOR_STEP` where there is
        no point or the model does not hold: to the floor at once)."""
        point = self._run_point
        step = sigma[:, np.maximum(point, 0)] * self.obs.frame_s
        ok = (point >= 0) & np.isfinite(step)
        return np.where(ok, np.maximum(step, FLOOR_STEP), FLOOR_STEP).astype(np.float32)

    def _amplitudes(
        self, sigma: np.ndarray, depths: np.ndarray, frames: np.ndarray | None = None
    ) -> np.ndarray:
        """(Kd, W, m) a per depth, draw and scored frame (or `frames`): one scan of the runs'
        maps for all."""
        step = self._steps(sigma)
        total = step * self._run_len.astype(np.float32)
        depth = depths.astype(np.float32)[:, None, None]
        reset = self._run_reset
        zero = np.float32(0.0)
        reached = np.minimum(np.maximum(total, zero), depth)  # a reset run starts at the floor
        c = np.broadcast_to(np.where(reset, zero, total), reached.shape)
        lo = np.where(reset, reached, zero)
        hi = np.where(reset, reached, depth)
        c, lo, hi = _compose(c, lo, hi)
        end = np.minimum(np.maximum(c, lo), hi)  # from the floor at the first frame
        start = np.zeros_like(end)
        start[..., 1:] = end[..., :-1]
        start[..., reset] = 0.0
        if frames is None:
            run, k = self._frame_run, self._frame_k
        else:
            run = self._all_run[frames]
            k = frames - self._run_start[run] + 1
        a = start[..., run] + k.astype(np.float32) * step[:, run]
        return np.minimum(np.maximum(a, zero), depth)

    def _hearable(self, in_band: np.ndarray) -> np.ndarray:
        return in_band[:, self.obs.sequence[self._used]]

    def grid_log_likelihood(self, theta: np.ndarray) -> np.ndarray:
        """The frames' log-likelihood at each grid cell, without the growth data.

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.

        Returns
        -------
        numpy.ndarray
            (W, Kd, Kh).
        """
        sigma, in_band = self.growth.growth_rates(theta)
        return self._grid(sigma, in_band)

    def _grid(self, sigma: np.ndarray, in_band: np.ndarray) -> np.ndarray:
        a = self._amplitudes(sigma, self.depth_np)  # (Kd, W, m)
        kd, w, m = a.shape
        kh = len(self.threshold_np)
        # above: how many thresholds a reaches (0 where the mode is not heard)
        above = np.searchsorted(self.threshold_np, a, side="right") * self._hearable(in_band)
        rows = np.arange(kd * w)[:, None] * (kh + 1)
        delta = np.broadcast_to(self._delta, (kd * w, m)).ravel()
        sums = np.bincount((rows + above.reshape(kd * w, m)).ravel(), delta, kd * w * (kh + 1))
        tail = np.cumsum(sums.reshape(kd, w, kh + 1)[..., ::-1], axis=-1)[..., ::-1]
        return self._base + tail[..., 1:].transpose(1, 0, 2)  # frames at or over h_j, (W, Kd, Kh)

    def _onset_term(self, sigma: np.ndarray) -> np.ndarray:
        """(W,) log p of the measured onset rates (A2)."""
        if not len(self._onset_rate):
            return np.zeros(len(sigma))
        hp = self.hearing
        r, se = self._onset_rate, self._onset_se
        sd = hp.onset_sd(r, se)
        log_n = norm.logpdf(r, sigma[:, self._onset_point], np.maximum(sd, 1e-9))
        log_out = math.log(hp.onset_outlier / hp.max_rate_per_s) if hp.onset_outlier else -np.inf
        both = np.logaddexp(np.log1p(-hp.onset_outlier) + log_n, log_out)
        return np.sum(both, axis=1)

    def log_likelihood(self, theta: np.ndarray) -> np.ndarray:
        """Log-likelihood of the frames and the onset rates, the grid marginalised.

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.

        Returns
        -------
        numpy.ndarray
            (W,); -inf outside the valid domain or the box `bounds`.
        """
        theta = np.asarray(theta, float)
        sigma, in_band = self.growth.growth_rates(theta)
        grid = self._grid(sigma, in_band) + self.log_weight
        out = logsumexp(grid.reshape(len(theta), -1), axis=1) + self._onset_term(sigma)
        return np.where(self.growth.in_domain(theta), out, -np.inf)

    def responsibilities(self, theta: np.ndarray) -> np.ndarray:
        """Per draw, the posterior weights of the grid cells (they sum to 1).

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.

        Returns
        -------
        numpy.ndarray
            (W, Kd, Kh).
        """
        grid = self.grid_log_likelihood(theta) + self.log_weight
        flat = grid.reshape(len(grid), -1)
        return np.exp(flat - logsumexp(flat, axis=1, keepdims=True)).reshape(grid.shape)

    def heard_probability(self, theta: np.ndarray, batch: int = 64) -> np.ndarray:
        """Per scored frame, the share of the draws (and of the grid, by its weights) whose
        squeak stands over the threshold in the detector's band there.

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) draws of `names` in the fields' units.
        batch : int
            Draws per vectorised pass.

        Returns
        -------
        numpy.ndarray
            (m,) P(heard) at the frames of `scored`.
        """
        weight = np.exp(self.log_weight - logsumexp(self.log_weight))
        out = np.zeros(len(self._used))
        for k in range(0, len(theta), batch):
            sigma, in_band = self.growth.growth_rates(theta[k : k + batch])
            hearable = self._hearable(in_band)
            for d, a in enumerate(self._amplitudes(sigma, self.depth_np)):
                for j, h in enumerate(self.threshold_np.tolist()):
                    if weight[d, j] > 0:
                        out += weight[d, j] * np.sum((a >= h) & hearable, axis=0)
        return out / max(len(theta), 1)

    def recentred(self, params: ScrewParameters) -> AmplitudeLikelihood:
        """The likelihood expanded about other parameters (same observations and grid).

        Parameters
        ----------
        params : ScrewParameters
            The new expansion centre.

        Returns
        -------
        AmplitudeLikelihood
        """
        return AmplitudeLikelihood(self.growth.recentred(params), self.hearing, self.log_weight)


def bench_posterior(log_prior: np.ndarray, unit_posteriors: list[np.ndarray]) -> np.ndarray:
    """The bench's grid posterior from its units' (each under the same grid prior).

    The units share h and the depth, so p(cell | all) is proportional to
    p(cell) prod_u p(cell | u) / p(cell), each unit's grid posterior averaged over its samples.

    Parameters
    ----------
    log_prior : numpy.ndarray
        (Kd, Kh) the grid's log prior (`HearingPrior.grid`).
    unit_posteriors : list of numpy.ndarray
        (Kd, Kh) each unit's grid posterior (mean `responsibilities` over its samples).

    Returns
    -------
    numpy.ndarray
        (Kd, Kh) log posterior, normalised (the prior when no unit is given).
    """
    mass = np.isfinite(log_prior)  # cells without prior mass stay without
    out = log_prior.copy()
    for p in unit_posteriors:
        out[mass] += np.log(np.maximum(np.asarray(p)[mass], 1e-300)) - log_prior[mass]
    return out - logsumexp(out)
