# SPDX-License-Identifier: Apache-2.0
"""The cheap likelihood of heard / not-heard frames given calibrated parameters theta.

Squeak at a point: some oscillatory mode's growth rate beyond the threshold of
`stability.unstable_mask` (Re lambda > GROWTH_TOL |lambda|), the live estimator's rule. It is
heard when the most unstable mode (whose limit cycle takes over; the one the virtual bench
sounds) lies in the detector's band (`DetectionErrors.band_lo_hz` .. `band_hi_hz`, its f_lo_hz
.. f_hi_hz at the expansion centre): a squeak above or below it is not heard, so its unheard
frames say nothing against it. At a
fixed operating point friction and damping enter the state matrix only through the friction
level l, the friction slope s (`kernels.level_slope`) and the damping ratio xi, and A is affine
in them. So each distinct point gets one eigen-solve at the expansion centre (the model's
parameters at the point's nut position; one geometry per nut bin), and a draw costs only

    Re lambda(theta) = Re lambda_0 + r_l (l(theta) - l_0) + r_s (s(theta) - s_0)
                       + r_xi (xi - xi_0) + sum_f r_f (theta_f - theta_f0)

with l and s of every draw computed exactly (the friction law is the nonlinear part) and the
rates r = Re(y^H dA x) of `EigenPairs`; any other calibrated (geometry) field f enters by a
first-order dA/df (`perturbation.geometry_derivative`). The expansion is exact at its centre
and first order around it: `recentred` re-expands about new parameters (the sampler does so
about the posterior mean until it no longer moves).

A mode that no draw within the box `bounds` of +-`REACH_SIGMAS` SDs of the reach prior (the
interim prior: 0.3 % of its mass per name is outside) can push across the threshold is
pruned at its point; a point where none is left has a fixed verdict. Outside the box the
log-likelihood is -inf (the interim prior truncated there), so the pruning is exact.

Detection error model (`DetectionErrors`): a frame is heard with probability

    P(heard) = false_alarm + (1 - false_alarm - miss) * squeak

Frames are not independent trials: consecutive frames share most of their samples (a
`DetectorSettings.frame_s` = 0.1 s window every hop of 0.01 s) and a detection, right or
wrong, is an episode of at least `min_duration_s`. Each frame therefore counts
hop / `correlation_s` (at most 1) of a Bernoulli trial: with the default 0.1 s (the frame
length), one trial per window of sound, a 12-s stroke ~120 trials. Counting every frame
would make the posteriors about sqrt(10) times too narrow.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy.stats import qmc

from ..acoustics.settings import DetectorSettings
from ..physics.assembly import build_geometry
from ..physics.kernels import level_slope
from ..physics.metadata import check, documented, setting
from ..physics.parameters import ParameterError, ScrewParameters
from ..physics.stability import GROWTH_TOL
from ..squeak_model import SqueakModel, Validity
from ..uncertainty.perturbation import EigenPairs, geometry_derivative
from .observations import CalibrationError, Observations
from .prior import DAMPING, FRICTION, INTERIM_WIDEN, Prior, check_names

REACH_SIGMAS = 3.0  # pruning and truncation: the box of +- this many SDs of the reach prior
_REACH_POINTS = 256  # Sobol points in that box (plus its corners) that bound the reach


@documented
@dataclass(frozen=True)
class DetectionErrors:
    """The detector's error rates and the correlation of its frames (module docstring).

    Defaults: the virtual bench's detector (a -20 dBFS tone in the motor noise) misses mostly
    the frames at an episode's onset and end (about half a frame length each, a few per cent of
    a squeak's frames) and hears orders or noise as squeak rarely; the rates also absorb the
    model's and the binning's error at a band edge. A rate of 0 would let one mislabelled frame
    rule a parameter set out, so both must be > 0.
    """

    false_alarm: float = setting(
        0.02,
        "1",
        "share of frames heard as squeak where the drive does not squeak",
        0.0,
        0.5,
        lo_open=True,
        hi_open=True,
    )
    miss: float = setting(
        0.05,
        "1",
        "share of frames not heard where the drive squeaks",
        0.0,
        0.5,
        lo_open=True,
        hi_open=True,
    )
    correlation_s: float = setting(
        0.1,
        "s",
        "correlation time of the detector's frames: a frame counts hop / this (at most 1) "
        "of an independent trial",
        1e-4,
        60.0,
    )

    band_lo_hz: float = setting(
        DetectorSettings.f_lo_hz,
        "Hz",
        "lowest squeak frequency the detector hears (its f_lo_hz): a mode below squeaks unheard",
        0.0,
        1e6,
    )
    band_hi_hz: float = setting(
        DetectorSettings.f_hi_hz,
        "Hz",
        "highest squeak frequency the detector hears (its f_hi_hz, or less below Nyquist)",
        0.0,
        1e6,
        lo_open=True,
    )

    def __post_init__(self) -> None:
        check(self, ParameterError, "errors.")
        if self.band_lo_hz >= self.band_hi_hz:
            raise ParameterError(
                f"errors.band_lo_hz = {self.band_lo_hz:g} Hz is not below "
                f"errors.band_hi_hz = {self.band_hi_hz:g} Hz"
            )

    def heard_probability(self, squeak: np.ndarray) -> np.ndarray:
        """P(frame heard) given the model's verdict.

        Parameters
        ----------
        squeak : numpy.ndarray
            Bool (or 0/1) verdicts.

        Returns
        -------
        numpy.ndarray
            false_alarm + (1 - false_alarm - miss) * squeak.
        """
        return self.false_alarm + (1.0 - self.false_alarm - self.miss) * np.asarray(squeak, float)

    def frame_weight(self, hop_s: float) -> float:
        """What one frame counts of an independent trial: min(1, hop / correlation_s).

        Parameters
        ----------
        hop_s : float
            Time between frames [s].

        Returns
        -------
        float
            The weight in (0, 1].
        """
        return min(1.0, hop_s / self.correlation_s)


def _expanded(
    dl: np.ndarray,
    ds: np.ndarray,
    dlin: np.ndarray,
    column: np.ndarray,
    rates: np.ndarray,
    margin: np.ndarray,
) -> np.ndarray:
    """(pairs, W) first-order growth beyond the threshold of (point, mode) pairs (module
    docstring): `dl`, `ds` (points, W) level and slope changes, `dlin` (F, W) the linear
    names' changes, `column` each pair's point row, `rates` (2 + F, pairs), `margin` (pairs,)
    at the centre."""
    growth = dl[column] * rates[0, :, None]
    growth += ds[column] * rates[1, :, None]
    growth += rates[2:].T @ dlin
    growth += margin[:, None]
    return growth


def _batch_bounds(
    changes: tuple[np.ndarray, ...],
    column: np.ndarray,
    rates: np.ndarray,
    size: np.ndarray,
    margin: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(pairs,) each pair's expanded growth at a batch's mean change, and a bound of how far
    the batch's draws stray from it (`size` = |rates|): cheap per pair, so that only the pairs
    the bounds cannot decide are evaluated per draw."""
    mean = margin.copy()
    bound = np.zeros(len(mean))
    for k, change in enumerate(changes[:2]):
        centre = change.mean(axis=1)
        mean += rates[k] * centre[column]
        bound += size[k] * np.abs(change - centre[:, None]).max(axis=1)[column]
    centre = changes[2].mean(axis=1)
    mean += centre @ rates[2:]
    bound += np.abs(changes[2] - centre[:, None]).max(axis=1) @ size[2:]
    return mean, bound


class GrowthLikelihood:
    """Log-likelihood of a unit's observations over draws of the calibrated parameters.

    Parameters
    ----------
    model : SqueakModel
        Its parameters are the expansion centre (and give every field not calibrated); its
        scatter is the prior that bounds the pruning when `reach` is None.
    obs : Observations
        The unit's frames at distinct operating points.
    names : sequence of str
        The calibrated parameters, the columns of theta.
    errors : DetectionErrors, optional
        The detection error model; the defaults when None.
    reach : Prior, optional
        Its prior, used for the valid domain and, within `REACH_SIGMAS` of its SDs, as the
        box that bounds the modes kept (pruning); the model's prior widened by
        `prior.INTERIM_WIDEN` when None.

    Raises
    ------
    ParameterError
        A name that cannot be calibrated or has no prior SD.

    Attributes
    ----------
    params : ScrewParameters
        The expansion centre.
    names : tuple of str
        The calibrated parameters.
    valid : numpy.ndarray
        (P,) bool: the points where the model holds at the centre (`Validity.OK`, the nut on
        the screw, the eigen-solve converged); the others carry no information.
    active : numpy.ndarray
        Indices of the points whose verdict some draw within `bounds` can change.
    bounds : tuple of numpy.ndarray
        (lo, hi), each (D,) in the fields' units: the box of +-`REACH_SIGMAS` SDs of the
        reach prior; the log-likelihood is -inf outside it.
    evaluations : int
        Draws (rows of theta) evaluated so far.
    calls : int
        Calls of `log_likelihood` / `squeaks` so far.
    """

    def __init__(
        self,
        model: SqueakModel,
        obs: Observations,
        names: Sequence[str],
        errors: DetectionErrors | None = None,
        reach: Prior | None = None,
    ):
        self.model, self.obs, self.names = model, obs, check_names(names)
        self.errors = errors or DetectionErrors()
        self.params = model.params
        self.reach = reach or Prior(model.params, model.scatter, self.names).widened(INTERIM_WIDEN)
        if self.reach.names != self.names:
            raise ParameterError("the reach prior must have the calibrated names, in order")
        self.evaluations = self.calls = 0
        self._friction = [k for k, n in enumerate(self.names) if n in FRICTION]
        self._linear = [k for k, n in enumerate(self.names) if n not in FRICTION]
        self.centre = np.array([float(getattr(self.params, n)) for n in self.names])
        self._fields = self.params.as_dict()
        u = np.full(len(self.names), REACH_SIGMAS * self.reach.widen)
        self.bounds = (self.reach.from_u(-u), self.reach.from_u(u))
        # the contact's angular length b / (R tan beta): one for every nut position
        self._alpha = build_geometry(self.params).contact.alpha
        self._expand()

    # ---------------------------------------------------------------- construction
    def _expand(self) -> None:
        """One eigen-solve per valid point at the centre: growth margins and rates of every
        oscillatory mode, then the pruning and the likelihood's per-point terms."""
        obs, p = self.obs, self.params
        speed, load, nut = obs.speed_rad_s, obs.load_n, obs.nut_position_m
        valid = np.asarray(self.model.validity_code(speed, load) == Validity.OK)
        valid &= (nut >= 0) & (nut <= p.nut_travel_m)
        point, margin, rates, inband = [], [], [], []
        band = 2 * math.pi * np.array([self.errors.band_lo_hz, self.errors.band_hi_hz])
        for z in np.unique(nut[valid]).tolist():
            at = p.with_(nut_position_m=z)
            geometry = build_geometry(at)
            for i in np.flatnonzero(valid & (nut == z)).tolist():
                try:
                    pairs = EigenPairs.solve(geometry, float(speed[i]), float(load[i]))
                except np.linalg.LinAlgError:
                    valid[i] = False
                    continue
                lam = pairs.lam
                point.append(np.full(len(lam), i))
                margin.append(lam.real - GROWTH_TOL * np.abs(lam))
                rates.append(self._mode_rates(pairs, at, float(speed[i]), float(load[i])))
                inband.append((lam.imag >= band[0]) & (lam.imag <= band[1]))
        self.valid = valid
        self._solved = (
            np.concatenate(point) if point else np.zeros(0, int),
            np.concatenate(margin) if margin else np.zeros(0),
            np.concatenate(rates, axis=1) if rates else np.zeros((2 + len(self._linear), 0)),
            np.concatenate(inband) if inband else np.zeros(0, bool),
        )
        self._prune()

    def _prune(self) -> None:
        """The (point, mode) pairs that a draw in the box can push across the threshold,
        the points they leave fixed, and the likelihood's per-point terms."""
        obs, valid = self.obs, self.valid
        point_k, margin_k, rates_k, inband_k = self._solved
        reach_k = self._reach(point_k, rates_k)
        can = margin_k + reach_k > 0  # unstable for some draw in the box
        self._rates_of(point_k, margin_k, rates_k, inband_k, reach_k)
        # The squeak heard is the most unstable mode's (the bench sounds that one, and its
        # limit cycle takes over): where a mode outside the band can be unstable as well as
        # one inside, the verdict is a contest between them, decided per draw.
        contest = np.zeros(obs.points, bool)
        contest[point_k[can & ~inband_k]] = True
        has_heard = np.zeros(obs.points, bool)
        has_heard[point_k[can & inband_k]] = True
        contest &= has_heard
        pairs = np.flatnonzero(contest[point_k] & can)
        pairs = pairs[np.argsort(point_k[pairs], kind="stable")]
        self.contested, starts_c = np.unique(point_k[pairs], return_index=True)
        self._contest = (
            np.searchsorted(self.contested, point_k[pairs]),
            margin_k[pairs],
            rates_k[:, pairs],
            inband_k[pairs],
            starts_c,
        )
        self._contest_at = self._centre_at(self.contested)
        plain = inband_k & ~contest[point_k]  # elsewhere only the modes in the band count
        point_k, margin_k, rates_k, reach_k = (
            point_k[plain],
            margin_k[plain],
            rates_k[:, plain],
            reach_k[plain],
        )
        keep = np.abs(margin_k) <= reach_k
        fixed = np.zeros(obs.points, bool)  # squeaks for every draw in the box
        fixed[point_k[~keep & (margin_k > 0)]] = True
        keep &= ~fixed[point_k]
        self._point, self._margin, self._rates = point_k[keep], margin_k[keep], rates_k[:, keep]
        self._abs_rates = np.abs(self._rates)
        self.active, starts = np.unique(self._point, return_index=True)
        self._starts = starts
        self._column = np.searchsorted(self.active, self._point)  # pair -> active column
        self._active_at = self._centre_at(self.active)
        # log-likelihood per point: base (no squeak) and the change when it squeaks
        w = self.errors.frame_weight(obs.frame_s)
        heard = w * obs.heard * valid
        quiet = w * (obs.frames - obs.heard) * valid
        q0, q1 = self.errors.heard_probability(np.array([0.0, 1.0]))
        base = heard * math.log(q0) + quiet * math.log1p(-q0)
        self._delta = heard * math.log(q1 / q0) + quiet * (math.log1p(-q1) - math.log1p(-q0))
        self.fixed = fixed
        self._constant = float(base.sum() + self._delta[fixed].sum())

    def _rates_of(
        self,
        point_k: np.ndarray,
        margin_k: np.ndarray,
        rates_k: np.ndarray,
        inband_k: np.ndarray,
        reach_k: np.ndarray,
    ) -> None:
        """What `growth_rates` needs: the (point, mode) pairs that can be unstable in the box,
        sorted by point, and per point the strongest of the others at the centre (their
        growth varies too little to cross zero: the decay rate they give is held). A pair
        that no draw in the box can make the strongest of its band at its point is dropped
        (exact: its upper bound is under another pair's lower bound)."""
        points = self.obs.points
        can = margin_k + reach_k > 0
        rest = np.full((2, points), -np.inf)  # in band, outside it
        other = ~can
        np.maximum.at(rest, (np.where(inband_k[other], 0, 1), point_k[other]), margin_k[other])
        floor = np.full((2, points), -np.inf)  # the largest lower bound of a pair
        band = np.where(inband_k, 0, 1)
        np.maximum.at(floor, (band[can], point_k[can]), (margin_k - reach_k)[can])
        can &= margin_k + reach_k >= floor[band, point_k]
        pairs = np.flatnonzero(can)
        at = np.unique(point_k[pairs])
        self._candidates = (
            np.searchsorted(at, point_k[pairs]),
            margin_k[pairs],
            rates_k[:, pairs],
            band[pairs],  # 0 in the band, 1 outside it
        )
        self._candidates_at = self._centre_at(at)
        self._candidate_starts = np.flatnonzero(np.r_[True, np.diff(point_k[pairs]) > 0])
        self._rest = rest

    def growth_rates(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per draw and point, the growth rate of the most unstable mode and whether it is in
        the detector's band: what the squeak's amplitude follows (`amplitude`).

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.

        Returns
        -------
        sigma : numpy.ndarray
            (W, P) Re(lambda) [1/s] of the most unstable mode (first order about the centre
            where a draw in the box can make some mode unstable, the centre's elsewhere);
            -inf where the model does not hold.
        in_band : numpy.ndarray
            (W, P) bool: that mode's frequency is in the band.

        Raises
        ------
        CalibrationError
            theta of the wrong shape or not finite.
        """
        theta = self._check(theta)
        w = len(theta)
        best = np.broadcast_to(self._rest[:, None, :], (2, w, self.obs.points)).copy()
        column, margin, rates, band = self._candidates
        if len(margin):
            at = self._candidates_at
            changes = self._changes(theta, at)
            mean, bound = _batch_bounds(changes, column, rates, np.abs(rates), margin)
            # a pair under another's lower bound at its point for the whole batch is not the
            # max there, and cannot decide the band (the max's band holds its max pair)
            floor = np.maximum.reduceat(mean - bound, self._candidate_starts)
            pairs = np.flatnonzero(mean + bound >= floor[column])
            group = column[pairs] * 2 + band[pairs]
            pairs = pairs[np.argsort(group, kind="stable")]
            cells, starts = np.unique(column[pairs] * 2 + band[pairs], return_index=True)
            growth = _expanded(*changes, column[pairs], rates[:, pairs], margin[pairs])
            g = np.maximum.reduceat(growth, starts, axis=0)  # (cells, W)
            best[cells % 2, :, at[0][cells // 2]] = np.maximum(
                best[cells % 2, :, at[0][cells // 2]], g
            )
        sigma = np.where(self.valid, np.maximum(best[0], best[1]), -np.inf)
        return sigma, (best[0] >= best[1]) & self.valid

    def _contest_margins(self, theta: np.ndarray) -> np.ndarray:
        """(W, len(contested)) margin of the heard squeak at the contested points: the
        largest growth in the band, or less by how much a mode outside it grows faster
        (> 0: heard)."""
        column, margin, rates, inband, starts = self._contest
        if not len(self.contested):
            return np.zeros((len(theta), 0))
        growth = _expanded(*self._changes(theta, self._contest_at), column, rates, margin)
        g_in = np.maximum.reduceat(np.where(inband[:, None], growth, -np.inf), starts, axis=0)
        g_out = np.maximum.reduceat(np.where(inband[:, None], -np.inf, growth), starts, axis=0)
        return np.minimum(g_in, g_in - g_out).T

    def _mode_rates(
        self, pairs: EigenPairs, at: ScrewParameters, speed: float, load: float
    ) -> np.ndarray:
        """(2 + len(linear), M) d Re(lambda) per unit of l, s and each linear name."""
        r = pairs.unit_rates.real  # per unit W1, W5q, W3, W5qdot, Omega coefficient
        out = [
            math.copysign(1.0, speed) * r[0] + r[2] / abs(speed),  # W1 = sign l, W3 = l/|Om|
            speed * r[1] + r[3],  # W5q = Omega s, W5qdot = s
        ]
        for k in self._linear:
            name = self.names[k]
            if name == DAMPING:
                out.append(pairs.damping_rate().real)
            else:
                out.append(pairs.matrix_rate(geometry_derivative(at, name, speed, load)).real)
        return np.array(out)

    def _reach(self, point: np.ndarray, rates: np.ndarray) -> np.ndarray:
        """Per (point, mode) pair, the largest growth change of a draw within the reach box."""
        box = self._box()
        change = np.abs(box - self.centre).max(axis=0)  # (D,)
        reach = np.zeros(len(point))
        if self._friction and len(point):
            used = np.unique(point)
            dl, ds = self._level_slope_change(box, self._centre_at(used))
            at = np.searchsorted(used, point)
            reach += np.abs(rates[0]) * np.abs(dl).max(axis=0)[at]
            reach += np.abs(rates[1]) * np.abs(ds).max(axis=0)[at]
        for j, k in enumerate(self._linear):
            reach += np.abs(rates[2 + j]) * change[k]
        return reach

    def _box(self) -> np.ndarray:
        """Values (B, D) in the box `bounds`: Sobol points and, for up to 8 names, the
        corners."""
        d = len(self.names)
        unit = qmc.Sobol(d, scramble=True, seed=0).random(_REACH_POINTS)
        if d <= 8:
            corners = np.array(np.meshgrid(*[[0.0, 1.0]] * d, indexing="ij")).reshape(d, -1).T
            unit = np.vstack([unit, corners])
        lo, hi = self.bounds
        return lo + (hi - lo) * unit

    def _centre_at(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`points` with the centre's friction level and slope there (computed once, not per
        sampler call)."""
        level0, slope0 = level_slope(
            self.params, self.obs.speed_rad_s[points], self.obs.load_n[points], self._alpha
        )
        return points, level0, slope0

    def _level_slope_change(
        self, theta: np.ndarray, at: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(W, len(points)) changes of the friction level and slope from the centre's at the
        points of `at` (`_centre_at`; the active points when None)."""
        fields = dict(self._fields)
        for k in self._friction:
            fields[self.names[k]] = theta[:, k : k + 1]
        points, level0, slope0 = self._active_at if at is None else at
        speed, load = self.obs.speed_rad_s[points], self.obs.load_n[points]
        level, slope = level_slope(SimpleNamespace(**fields), speed, load, self._alpha)
        return level - level0, slope - slope0

    # ---------------------------------------------------------------- evaluation
    def _check(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, float)
        if theta.ndim != 2 or theta.shape[1] != len(self.names):
            raise CalibrationError(
                f"theta must have shape (walkers, {len(self.names)}), got {theta.shape}"
            )
        if not np.all(np.isfinite(theta)):
            raise CalibrationError("theta is not finite: no likelihood of NaN parameters")
        self.calls += 1
        self.evaluations += len(theta)
        return theta

    def _changes(
        self, theta: np.ndarray, at: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The draws' changes from the centre, draws along the last axis: level and slope at
        the points of `at` (the active points when None) (A, W) and the linear names' (F, W);
        zeros for what is not calibrated."""
        if self._friction:
            dl, ds = (np.ascontiguousarray(c.T) for c in self._level_slope_change(theta, at))
        else:
            points = (self._active_at if at is None else at)[0]
            dl = ds = np.zeros((len(points), len(theta)))
        return dl, ds, (theta[:, self._linear] - self.centre[self._linear]).T

    def _growth(self, changes: tuple[np.ndarray, ...], pairs: np.ndarray) -> np.ndarray:
        """(len(pairs), W) expanded growth beyond the threshold of (point, mode) pairs."""
        dl, ds, dlin = changes
        return _expanded(
            dl, ds, dlin, self._column[pairs], self._rates[:, pairs], self._margin[pairs]
        )

    def _active_squeaks(self, theta: np.ndarray) -> np.ndarray:
        """(W, len(active)) verdicts at the active points. Each pair (point, mode) is first
        taken at the batch's mean change, with a bound of how far the batch's draws stray from
        it (cheap, per pair): a point where some mode's lower bound is above the threshold
        squeaks for every draw, a pair whose upper bound is below never squeaks, and only the
        rest is evaluated per draw. Exact for the expansion."""
        out = np.zeros((len(self.active), len(theta)), bool)
        if not len(self.active):
            return out.T
        changes = self._changes(theta)
        column = self._column
        mean, bound = _batch_bounds(changes, column, self._rates, self._abs_rates, self._margin)
        sure = np.maximum.reduceat(mean - bound, self._starts) > 0
        out[sure] = True
        pairs = np.flatnonzero((mean + bound > 0) & ~sure[column])
        if len(pairs):
            points, starts = np.unique(column[pairs], return_index=True)
            out[points] = np.maximum.reduceat(self._growth(changes, pairs), starts, axis=0) > 0
        return out.T

    def margins(self, theta: np.ndarray) -> np.ndarray:
        """Per draw and point, the largest expanded growth rate beyond the squeak threshold
        over the modes kept (> 0: squeak), as `squeaks` decides it (which skips most pairs).

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.

        Returns
        -------
        numpy.ndarray
            (W, P) [1/s]: +inf where every draw of the reach squeaks, -inf where none can,
            nan where the model does not hold.

        Raises
        ------
        CalibrationError
            theta of the wrong shape or not finite.
        """
        theta = self._check(theta)
        out = np.where(self.fixed, np.inf, np.where(self.valid, -np.inf, np.nan))
        out = np.broadcast_to(out, (len(theta), self.obs.points)).copy()
        if len(self.active):
            growth = self._growth(self._changes(theta), np.arange(len(self._margin)))
            out[:, self.active] = np.maximum.reduceat(growth, self._starts, axis=0).T
        out[:, self.contested] = self._contest_margins(theta)
        return out

    def log_likelihood(self, theta: np.ndarray) -> np.ndarray:
        """Log-likelihood of the observations at each row of theta.

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.

        Returns
        -------
        numpy.ndarray
            (W,) log-likelihood; -inf where a row is outside the valid domain or the
            box `bounds`.

        Raises
        ------
        CalibrationError
            theta of the wrong shape or not finite.
        """
        theta = self._check(theta)
        out = self._constant + self._active_squeaks(theta) @ self._delta[self.active]
        if len(self.contested):
            out += (self._contest_margins(theta) > 0) @ self._delta[self.contested]
        return np.where(self.in_domain(theta), out, -np.inf)

    def in_domain(self, theta: np.ndarray) -> np.ndarray:
        """(W,) bool: the rows inside the box `bounds` and the reach prior's valid domain
        (elsewhere the log-likelihood is -inf).

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.

        Returns
        -------
        numpy.ndarray
        """
        inside = np.all((theta >= self.bounds[0]) & (theta <= self.bounds[1]), axis=1)
        return np.asarray(inside & self.reach.valid(theta))

    def squeaks(self, theta: np.ndarray) -> np.ndarray:
        """The model's verdict at every point for each row of theta (False where not valid).

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values of `names` in the fields' units.

        Returns
        -------
        numpy.ndarray
            (W, P) bool.

        Raises
        ------
        CalibrationError
            theta of the wrong shape or not finite.
        """
        theta = self._check(theta)
        out = np.broadcast_to(self.fixed, (len(theta), self.obs.points)).copy()
        out[:, self.active] = self._active_squeaks(theta)
        out[:, self.contested] = self._contest_margins(theta) > 0
        return out

    def recentred(self, params: ScrewParameters) -> GrowthLikelihood:
        """The likelihood expanded about other parameters (same observations, names, errors
        and reach).

        Parameters
        ----------
        params : ScrewParameters
            The new expansion centre.

        Returns
        -------
        GrowthLikelihood
            A new likelihood (its counters start at 0).
        """
        model = SqueakModel(params, self.model.scatter, self.model.sample_count)
        return GrowthLikelihood(model, self.obs, self.names, self.errors, self.reach)
