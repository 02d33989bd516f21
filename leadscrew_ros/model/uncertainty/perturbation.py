# SPDX-License-Identifier: Apache-2.0
"""First-order eigenvalue perturbation of (27), and the fast P(squeak) built on it.

For a simple eigenvalue lambda of the state matrix A with right and left eigenvectors x, y
(A x = lambda x, y^H A = lambda y^H, y^H x = 1):

    d lambda = y^H (dA) x

`EigenPairs` holds the oscillatory eigenvalues (Im > 0) of one eigen-solve with x and y^H
(`stability.eig_both`, or the right vectors alone and `stability.left_rows`), so the prediction
and the probability share one LAPACK call.

`FirstOrderProbability` is the live estimator of P(squeak) over scatter samples. Friction and
damping enter A only through three scalars at a fixed operating point: the friction level
l = mu_o |F_z| c_f / (alpha R) (W1-W4), the friction slope s = gamma |F_z| c_5 / alpha (W5) and
the damping ratio xi; A is affine in them (`kernels.scales`). Each oscillatory eigenvalue is
expanded to first order in them while l, s and xi of every sample are computed exactly (the
friction law is the nonlinear part). A scattered geometry parameter (radius, nut position, ...)
is not first order at all (it moves the modes' coupling): the expansion is made at a few node
geometries and interpolated between them (`FirstOrderProbability`). P is the share of samples
in which some mode's expanded growth rate exceeds the squeak threshold of
`stability.unstable_mask`, so the modes' correlation (one friction scatter drives them all)
is kept.

Only the modes that some sample can move across the threshold are expanded over the samples:
a mode's growth is linear in the three changes, so its largest growth over the samples is at
most the sum over the changes of the rate times the change's larger or smaller end, whichever
gives more, and a mode whose bound stays below the threshold is never a hit (no mode left: P =
0 at once). The bound is exact arithmetic on the mode's own rates, no heuristic: which modes
are skipped cannot change P. (Skipping the left
vectors too, by a bound on the rates without them, does not pay here: the modes' sensitivities
range over orders of magnitude across operating points, and the damping scatter reaches the
threshold of every lightly damped mode unless the sign of its rate is known; see
doc/development/benchmarks.md.)
"""

from __future__ import annotations

import copy
import math
from functools import cached_property
from types import SimpleNamespace

import numpy as np
from numpy.typing import ArrayLike

from ..physics.assembly import Geometry, build_geometry
from ..physics.friction import SteadyFriction
from ..physics.kernels import level_slope
from ..physics.parameters import GEOMETRY_FIELDS, ParameterError, ScrewParameters
from ..physics.stability import GROWTH_TOL, Eigen, Solves, eig_both, left_rows, left_rows_many
from .scatter import Samples, Scatter

GEOMETRY_STEP = 1e-6  # relative step of a state-matrix difference in a geometry field
MAX_GEOMETRY_FIELDS = 2  # scattered geometry fields the live estimate takes
GEOMETRY_NODES = {1: 9, 2: 5}  # node geometries per scattered geometry field
_OUTSIDE = -1e30  # margin of a node without a prediction (counts as no squeak)
_POINTS_PER_STEP = 64  # of `estimates`' growth over the samples: (64, modes, count) at a time


class EigenPairs:
    """The oscillatory eigenvalues (Im > 0) of A with right and left eigenvectors.

    Parameters
    ----------
    geometry : Geometry
        The geometry A was built from (its unit matrices give dA).
    speed : float
        Screw speed of A [rad/s].
    eigen : Eigen
        The eigen-solve of A (`stability.eig_both`); without left vectors they come from the
        right ones (`stability.left_rows`).

    Raises
    ------
    numpy.linalg.LinAlgError
        Without left vectors: the right ones are not a basis (a defective A).
    """

    def __init__(self, geometry: Geometry, speed: float, eigen: Eigen):
        self.geometry, self.speed = geometry, speed
        self.lam, self.x = eigen.lam[eigen.osc], eigen.right
        if eigen.left is None:  # normalised by construction
            self.y_h = left_rows(eigen.vr, eigen.osc)
            return
        y_h = eigen.left.conj().T
        self.y_h = y_h / np.einsum("ij,ji->i", y_h, self.x)[:, None]  # y_i^H x_i = 1

    @classmethod
    def solve(cls, geometry: Geometry, speed: float, load: float) -> EigenPairs:
        """Eigen-solve A at one operating point [rad/s], [N]."""
        return cls(geometry, speed, eig_both(geometry.state_matrices(speed, load)))

    @cached_property
    def unit_rates(self) -> np.ndarray:
        """d lambda per unit of each coefficient (W1, W5q, W3, W5qdot, Omega) of
        `Geometry.state_matrices` (dA = -[0; U_k]), shape (5, M)."""
        n = self.geometry.n
        units = self.geometry.lower_half_units.reshape(-1, n, 2 * n)
        return -np.einsum("ij,kji->ki", self.y_h[:, n:], units @ self.x)

    def coefficient_rate(self, dc: ArrayLike) -> np.ndarray:
        """d lambda for a change `dc` of the coefficient vector (W1, W5q, W3, W5qdot, Omega)."""
        return np.asarray(dc, float) @ self.unit_rates

    def damping_rate(self) -> np.ndarray:
        """d lambda / d xi of the modal damping ratio (A.1): dA = -2 diag(omega) in D."""
        n, om = self.geometry.n, self.geometry.basis.omega_rad_s
        return np.einsum("ij,ji->i", self.y_h[:, n:], -2 * om[:, None] * self.x[n:])

    def speed_rate_of_stiffness(self) -> np.ndarray:
        """d lambda / d Omega of the -Omega^2 I term of K alone: dA = 2 Omega I in A's K block."""
        n = self.geometry.n
        return 2 * self.speed * np.einsum("ij,ji->i", self.y_h[:, n:], self.x[:n])

    def matrix_rate(self, da: np.ndarray) -> np.ndarray:
        """d lambda for a change `da` of the whole state matrix."""
        return np.einsum("ij,ji->i", self.y_h, da @ self.x)


def geometry_derivative(
    params: ScrewParameters, name: str, speed: float, load: float
) -> np.ndarray:
    """dA / d(name) by a central difference of two geometries (relative step GEOMETRY_STEP);
    the geometries are cached, so a parameter set pays for them once."""
    h = GEOMETRY_STEP * getattr(params, name)
    hi, lo = (
        build_geometry(params.with_(**{name: getattr(params, name) + s})).state_matrices(
            speed, load
        )
        for s in (h, -h)
    )
    return (hi - lo) / (2 * h)


def geometry_fields(scatter: Scatter) -> list[str]:
    """The scattered geometry fields, checked against what the live estimate takes.

    Raises
    ------
    ParameterError
        More than `MAX_GEOMETRY_FIELDS` geometry fields scatter.
    """
    fields = [k for k in scatter.names if k in GEOMETRY_FIELDS]
    if len(fields) > MAX_GEOMETRY_FIELDS:
        raise ParameterError(
            f"{len(fields)} geometry fields scatter ({', '.join(fields)}); the live "
            f"estimate takes at most {MAX_GEOMETRY_FIELDS} (probability.monte_carlo "
            "takes any)"
        )
    return fields


class _Expansion:
    """First-order growth of the oscillatory modes in the friction level, slope and damping
    ratio around one geometry's eigen-solve; `friction` holds the samples' friction
    parameters, each an array (count + 1,) whose last entry is the nominal value (one pass of
    the friction law gives the samples and the nominal: two passes cost a live prediction
    0.04x a bare eig); the rest of the parameters are the geometry's."""

    def __init__(
        self,
        geometry: Geometry,
        friction: dict[str, np.ndarray],
        like: _Expansion | None = None,
    ):
        self.geometry, self.params = geometry, geometry.params
        self.sampled = SimpleNamespace(**{**self.params.as_dict(), **friction})
        # the law's factors take the friction fields, the radius and the helix angle: `like`'s
        # (the same samples) serve a moved nut
        self.friction: SteadyFriction = (
            like.friction
            if like is not None
            and (like.params.radius_m, like.params.helix_angle_rad)
            == (self.params.radius_m, self.params.helix_angle_rad)
            else SteadyFriction(self.sampled)
        )
        self.units = units_on_displacements(geometry.lower_half_units, geometry.basis.omega_rad_s)

    def changes(self, speed: ArrayLike, load: ArrayLike, damping: np.ndarray) -> np.ndarray:
        """The samples' changes of friction level, slope and damping ratio from the nominal,
        shape (3, ..., count) for speeds and loads of shape (...) [rad/s], [N]; `damping`
        (count,) the samples' damping-ratio changes."""
        if type(speed) is not float and np.ndim(speed):  # a column of samples per point
            speed, load = np.asarray(speed, float)[..., None], np.asarray(load, float)[..., None]
        level, slope = level_slope(
            self.sampled, speed, load, self.geometry.contact.alpha, self.friction
        )
        change = np.empty((3,) + level.shape[:-1] + damping.shape)
        np.subtract(level[..., :-1], level[..., -1:], out=change[0])
        np.subtract(slope[..., :-1], slope[..., -1:], out=change[1])
        change[2] = damping
        return change

    def margins(
        self,
        pairs: EigenPairs,
        load: float,
        damping: np.ndarray,
        reach_damping: float,
        prune: bool = True,
    ) -> np.ndarray:
        """Per sample, the largest expanded growth rate beyond the squeak threshold over the
        modes [1/s] (> 0: squeak); `damping` holds the samples' damping-ratio changes. `prune`
        leaves out the modes that cannot reach the threshold (then -inf where none can):
        right for the sign, not for interpolation. Thread-safe: nothing shared is written."""
        n = self.geometry.n
        change = self.changes(pairs.speed, load, damping)
        rates = growth_rates(
            self.units, float(pairs.speed), pairs.lam, pairs.x[:n], pairs.y_h[:, n:]
        )
        threshold = GROWTH_TOL * np.abs(pairs.lam) - pairs.lam.real  # growth beyond it
        reach = [abs(change[0]).max(), abs(change[1]).max(), reach_damping]
        candidates = (
            np.flatnonzero(np.dot(reach, np.abs(rates)) > threshold)
            if prune
            else np.arange(len(threshold))
        )
        if not len(candidates):  # no mode can reach it
            return np.full(change.shape[1], -np.inf)
        growth = rates[:, candidates].T @ change  # (Mc, count)
        growth -= threshold[candidates, None]
        return growth.max(axis=0)


def units_on_displacements(lower_half_units: np.ndarray, omega_rad_s: np.ndarray) -> np.ndarray:
    """dA per unit coefficient (W1, W5q, W3, W5qdot) and per unit of xi, -[0; U_k] and
    [0; -2 diag(omega)] (A.1), as they act on the displacements q of a right vector
    x = [q; lam q]: the first two act on q, the others on the velocities lam q. From
    `Geometry.lower_half_units` (..., 5, N * 2N): shape (..., 5N, N), real (a complex q
    multiplies them as a real view)."""
    n = len(omega_rad_s)
    units = lower_half_units.reshape(lower_half_units.shape[:-2] + (5, n, 2 * n))
    out = np.zeros(units.shape[:-3] + (5, n, n))
    np.negative(units[..., :2, :, :n], out=out[..., :2, :, :])
    np.negative(units[..., 2:4, :, n:], out=out[..., 2:4, :, :])
    damping = out[..., 4, :, :].reshape(out.shape[:-3] + (n * n,))  # a view
    damping[..., :: n + 1] = -2 * omega_rad_s
    return out.reshape(out.shape[:-3] + (5 * n, n))


def growth_rates(
    units: np.ndarray, speed: ArrayLike, lam: np.ndarray, q: np.ndarray, y_lower: np.ndarray
) -> np.ndarray:
    """d Re(lambda) per unit friction level l, slope s and damping ratio xi of M modes,
    shape (..., 3, M): from the eigenvalues `lam` (..., M), the displacement halves `q`
    (..., N, M) of their right vectors and the lower halves of y^H (..., M, N),
    y^H dA x = y_lower dA_lower [q; lam q]; `units` as `units_on_displacements` gives them,
    (5N, N) or each point's (..., 5N, N); `speed` [rad/s] one per point (a float for one)."""
    n, m = q.shape[-2:]
    q = np.ascontiguousarray(q)
    uq = (units @ q.view(np.float64)).view(np.complex128).reshape(q.shape[:-2] + (5, n, m))
    r = np.einsum("...ki,...cik->...ck", y_lower, uq)
    r[..., 2:, :] *= lam[..., None, :]  # the velocity terms
    return _rate_terms(speed) @ r.real


def _rate_terms(speed: ArrayLike) -> np.ndarray:
    """d (W1, W5q, W3, W5qdot, xi) / d (l, s, xi): level l: W1 = sign l, W3 = l / |Omega|;
    slope s: W5q = Omega s, W5qdot = s; (3, 5), or (G, 3, 5) for G speeds [rad/s]."""
    if isinstance(speed, float):
        return np.array(
            [
                [math.copysign(1.0, speed), 0.0, 1.0 / abs(speed), 0.0, 0.0],
                [0.0, speed, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 0.0, 1.0],
            ]
        )
    speeds = np.asarray(speed, float)
    terms = np.zeros(speeds.shape + (3, 5))
    terms[..., 0, 0] = np.copysign(1.0, speeds)
    terms[..., 0, 2] = 1.0 / np.abs(speeds)
    terms[..., 1, 1] = speeds
    terms[..., 1, 3] = terms[..., 2, 4] = 1.0
    return terms


def hits_of(rates: np.ndarray, threshold: np.ndarray, change: np.ndarray) -> np.ndarray | None:
    """Which samples squeak by the first-order growth at one operating point: `rates` (3, M)
    per unit change, the modes' `threshold` (M,) (growth needed to squeak), the samples'
    `change` (3, count). None where no mode can reach its threshold in any sample (by the
    bound of the module docstring: no sample squeaks), else the (count,) verdicts from the
    modes that can."""
    reach = _reach(rates, change.max(axis=1)[:, None], change.min(axis=1)[:, None], threshold)
    return _hits(rates, threshold, np.flatnonzero(reach), change)


def _reach(rates: np.ndarray, hi: np.ndarray, lo: np.ndarray, threshold: np.ndarray) -> np.ndarray:
    """The modes some sample may move across the threshold: the bound of the module docstring
    from the rates (..., 3, M) and the changes' larger and smaller ends (..., 3, 1)."""
    return np.maximum(rates * hi, rates * lo).sum(axis=-2) > threshold


def _hits(
    rates: np.ndarray, threshold: np.ndarray, candidates: np.ndarray, change: np.ndarray
) -> np.ndarray | None:
    """The samples' verdicts from the growth of the `candidates` among the modes (None: no
    candidate, no sample squeaks)."""
    if not len(candidates):
        return None
    growth = rates[:, candidates].T @ change  # (Mc, count)
    growth -= threshold[candidates, None]
    return growth.max(axis=0) > 0


class FirstOrderProbability:
    """P(squeak) over scatter samples (see the module docstring).

    Without geometry scatter one eigen-solve serves every sample (the caller's). A scattered
    geometry field moves the modes and their coupling far beyond first order (1 % of radius
    shifts a mode by ~14 rad/s, and the helix phase at the nut start makes the growth rate
    oscillate in R with a period of about 1 %), so each of at most `MAX_GEOMETRY_FIELDS` such
    fields gets `GEOMETRY_NODES` geometries at equally spaced quantiles of the samples (dense
    where the samples are); at each node the friction and damping expansion gives every
    sample's margin, interpolated (multi-)linearly between the nodes at the sample's
    coordinates. That costs one eigen-solve per node (9, or 5 x 5 for two fields) per
    operating point; samples whose growth rate is within a few hundredths of 1/s of zero
    may be misjudged (measured: within 0.025 of the reference for a 1 % radius scatter at the
    band edge, 0.04 for radius and helix angle together).

    Parameters
    ----------
    params : ScrewParameters
        Nominal parameters (the scatter is relative to them).
    geometry : Geometry
        The geometry of `params` (modes and contact integrals).
    samples : Samples
        Scatter samples in replicates (`scatter.draw`).

    Raises
    ------
    ParameterError
        More than `MAX_GEOMETRY_FIELDS` geometry fields scatter.
    """

    def __init__(self, params: ScrewParameters, geometry: Geometry, samples: Samples):
        self.params, self.samples = params, samples
        count, scatter = samples.count, samples.scatter
        values = {k: v.ravel() for k, v in scatter.values(params, samples.u).items()}
        # the samples' friction fields (count,) and the nominal value last (`_Expansion`)
        self._friction = {
            k: np.append(np.broadcast_to(values.get(k, getattr(params, k)), (count,)), v)
            for k in ("mu_static", "mu_kinetic", "friction_decay_s_m")
            for v in (getattr(params, k),)
        }
        self._damping = np.broadcast_to(
            values.get("modal_damping", params.modal_damping) - params.modal_damping, (count,)
        )
        self._reach_damping = float(np.abs(self._damping).max())
        self._shape = samples.u.shape[:2]
        self._nominal = _Expansion(geometry, self._friction)
        fields = geometry_fields(scatter)
        self._nodes = self._geometry_nodes(fields, values) if fields else None

    @property
    def interpolates(self) -> bool:
        """Geometry fields scatter: the estimate interpolates between node geometries, one
        operating point at a time (`probability`; `estimates` takes none)."""
        return self._nodes is not None

    def with_geometry(self, params: ScrewParameters, geometry: Geometry) -> FirstOrderProbability:
        """The estimate for other parameters that differ from this one's only in geometry
        fields that do not scatter (a moved nut): the samples' friction and damping are the
        same, only the expansion is new. With scattered geometry the nodes move too: built
        anew.

        Parameters
        ----------
        params : ScrewParameters
            The new parameters.
        geometry : Geometry
            Their geometry.

        Returns
        -------
        FirstOrderProbability
            The estimate for `params`, sharing the samples.
        """
        if self._nodes is not None:
            return FirstOrderProbability(params, geometry, self.samples)
        new = copy.copy(self)
        new.params, new._nominal = params, _Expansion(geometry, self._friction, self._nominal)
        return new

    def _geometry_nodes(self, fields: list[str], values: dict) -> tuple:
        """Node geometries on a grid over the samples' range of each geometry field, and
        every sample's cell and weights in it."""
        per = GEOMETRY_NODES[len(fields)]
        axes, cells, fractions = [], [], []
        for name in fields:
            x = values[name]
            axis = np.quantile(x, np.linspace(0.0, 1.0, per))  # dense where samples are
            cell = np.clip(np.searchsorted(axis, x, side="right") - 1, 0, per - 2)
            axes.append(axis)
            cells.append(cell)
            step = axis[cell + 1] - axis[cell]
            fractions.append(np.divide(x - axis[cell], step, out=np.zeros_like(x), where=step > 0))
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(fields))
        expansions: list[_Expansion | None] = []
        for point in grid:
            try:  # a corner of two fields may leave the valid domain: no node
                node = self.params.with_(**dict(zip(fields, point.tolist(), strict=True)))
                expansions.append(_Expansion(build_geometry(node), self._friction))
            except ParameterError:
                expansions.append(None)
        # multilinear interpolation: 2^d corners, each a flat node index and a weight
        corners = []
        for bits in np.ndindex(*(2,) * len(fields)):
            index = np.ravel_multi_index(
                [c + b for c, b in zip(cells, bits, strict=True)], (per,) * len(fields)
            )
            weight = np.prod(
                [f if b else 1 - f for f, b in zip(fractions, bits, strict=True)], axis=0
            )
            corners.append((index, weight))
        return expansions, corners

    def margins(self, pairs: EigenPairs, load: float) -> np.ndarray:
        """Per sample, the largest growth rate beyond the squeak threshold over the modes.

        Parameters
        ----------
        pairs : EigenPairs
            The nominal eigen-solve at the operating point.
        load : float
            Axial load F_z [N].

        Returns
        -------
        ndarray
            Shape (count,) [1/s]; > 0: the sample squeaks.
        """
        if self._nodes is None:
            return self._nominal.margins(pairs, load, self._damping, self._reach_damping)
        expansions, corners = self._nodes
        speed, rows = pairs.speed, []
        for e in expansions:
            if e is None or abs(speed) >= e.geometry.basis.omega_rad_s.min():
                rows.append(np.full(self.samples.count, _OUTSIDE))  # not valid: no squeak
                continue
            node_pairs = EigenPairs.solve(e.geometry, speed, load)
            rows.append(
                e.margins(node_pairs, load, self._damping, self._reach_damping, prune=False)
            )
        at = np.array(rows)
        columns = np.arange(self.samples.count)
        return sum((w * at[index, columns] for index, w in corners), np.zeros(self.samples.count))

    def probability(
        self, speed: float, load: float, eigen: Eigen, matrix: np.ndarray | None = None
    ) -> tuple[float, float]:
        """P(squeak) and its standard error at an operating point, from its eigen-solve.

        Parameters
        ----------
        speed : float
            Screw speed Omega [rad/s].
        load : float
            Axial load F_z [N].
        eigen : Eigen
            The eigen-solve of the nominal state matrix there (`stability.eig_both`; without
            left vectors, `stability.left_rows` gives them).
        matrix : numpy.ndarray, optional
            That state matrix (built again when needed and not given: a defective one).

        Returns
        -------
        tuple of float
            P(squeak) in [0, 1] and its standard error (`estimate`).
        """
        if self._nodes is not None:
            return estimate(self.hits(self._pairs(speed, load, eigen), load))
        expansion = self._nominal
        n, osc, vr = expansion.geometry.n, eigen.osc, eigen.vr
        lam = eigen.lam[osc]
        y_lower = self._left(eigen.vr, osc, speed, load, matrix)
        q = np.empty((n, len(osc)), complex)  # the displacement halves, C-ordered
        q.real, q.imag = vr[:n, osc], vr[:n, osc + 1]
        hits = hits_of(
            growth_rates(expansion.units, float(speed), lam, q, y_lower),
            GROWTH_TOL * np.abs(lam) - lam.real,
            expansion.changes(speed, load, self._damping),
        )
        # no sample: (0, 0) as `estimate` gives it for equal replicates
        return (0.0, 0.0) if hits is None else estimate(hits.reshape(self._shape))

    def estimates(
        self,
        speeds: np.ndarray,
        loads: np.ndarray,
        groups: list[tuple[list[int], Solves]],
        matrices: np.ndarray | None = None,
        units: np.ndarray | None = None,
        rows: np.ndarray | None = None,
    ) -> list[tuple[float, float] | None]:
        """`probability` at many operating points (J,) at once: the samples' friction at all
        of them in one step, the rates of the solves with the same number of modes in one
        array step each, the growth over the samples only where a mode can cross.

        Parameters
        ----------
        speeds, loads : numpy.ndarray
            The operating points [rad/s], [N].
        groups : list of (list of int, Solves)
            Their eigen-solves, grouped (`stability.solves_of`).
        matrices : numpy.ndarray, optional
            Their state matrices (J, 2N, 2N) (built again where needed and not given).
        units : numpy.ndarray, optional
            `Geometry.lower_half_units` of other contacts (D, 5, N * 2N) than this estimate's
            (`assembly.lower_half_units_at`: other nut positions); the samples are the same.
        rows : numpy.ndarray, optional
            With `units`: each point's contact, a row of `units` (J,); without, `units` has
            one per point (J, 5, N * 2N).

        Returns
        -------
        list of tuple of float or None
            P(squeak) and its standard error at each point (None at a point in no group).

        Raises
        ------
        ParameterError
            Scattered geometry fields (their estimate interpolates between node geometries:
            `probability`, one point at a time).
        """
        if self._nodes is not None:
            raise ParameterError("scattered geometry: one point at a time (probability)")
        expansion = self._nominal
        own = (
            None
            if units is None
            else units_on_displacements(units, expansion.geometry.basis.omega_rad_s)
        )
        change = expansion.changes(speeds, loads, self._damping)  # (3, J, count)
        hi, lo = change.max(axis=2).T, change.min(axis=2).T  # (J, 3): the ends of each change
        out: list[tuple[float, float] | None] = [None] * len(speeds)
        for index, solves in groups:
            rates = growth_rates(
                expansion.units
                if own is None
                else own[index]
                if rows is None
                else own[rows[index]],
                speeds[index],
                solves.lam,
                solves.q,
                self._lefts(index, solves, speeds, loads, matrices),
            )
            threshold = GROWTH_TOL * np.abs(solves.lam) - solves.lam.real
            reach = _reach(rates, hi[index][:, :, None], lo[index][:, :, None], threshold)
            crosses = reach.any(axis=1)
            for i in np.asarray(index)[~crosses].tolist():
                out[i] = (0.0, 0.0)  # no mode can reach its threshold: as `probability`
            at = np.flatnonzero(crosses)
            points = np.asarray(index)[at]
            for start in range(0, len(at), _POINTS_PER_STEP):
                g, i = (
                    at[start : start + _POINTS_PER_STEP],
                    points[start : start + _POINTS_PER_STEP],
                )
                hits = _hits_many(rates[g], threshold[g], reach[g], change.transpose(1, 0, 2)[i])
                for k, e in zip(i.tolist(), _estimates(hits, self._shape), strict=True):
                    out[k] = e
        return out

    def _lefts(
        self,
        index: list[int],
        solves: Solves,
        speeds: np.ndarray,
        loads: np.ndarray,
        matrices: np.ndarray | None,
    ) -> np.ndarray:
        """The lower halves of y^H of stacked solves (G, M, N): from their right vectors in
        one stacked solve, one point at a time (`_left`) where some are not a basis."""
        try:
            return left_rows_many(solves.vr, solves.osc, self._nominal.geometry.n)
        except np.linalg.LinAlgError:
            return np.array(
                [
                    self._left(
                        vr, osc, speeds[i], loads[i], None if matrices is None else matrices[i]
                    )
                    for i, vr, osc in zip(index, solves.vr, solves.osc, strict=True)
                ]
            )

    def _left(
        self,
        vr: np.ndarray,
        osc: np.ndarray,
        speed: float,
        load: float,
        matrix: np.ndarray | None,
    ) -> np.ndarray:
        """The lower halves of y^H of one solve: from its right vectors, or LAPACK's left ones
        where those are not a basis (a defective `matrix`, built again if not given)."""
        n = self._nominal.geometry.n
        try:
            return left_rows(vr, osc, n)
        except np.linalg.LinAlgError:
            a = self._nominal.geometry.state_matrices(speed, load) if matrix is None else matrix
            return EigenPairs(self._nominal.geometry, float(speed), eig_both(a)).y_h[:, n:]

    def _pairs(self, speed: float, load: float, eigen: Eigen) -> EigenPairs:
        """The nominal eigenpairs of `eigen`; LAPACK's left vectors where the right ones are
        not a basis."""
        try:
            return EigenPairs(self._nominal.geometry, speed, eigen)
        except np.linalg.LinAlgError:
            return EigenPairs.solve(self._nominal.geometry, speed, load)

    def hits(self, pairs: EigenPairs, load: float) -> np.ndarray:
        """Whether each sample squeaks at the operating point of `pairs`, by the expansion.

        Parameters
        ----------
        pairs : EigenPairs
            The nominal eigen-solve at the operating point.
        load : float
            Axial load F_z [N].

        Returns
        -------
        ndarray of bool
            Shape (replicates, per_replicate).
        """
        return (self.margins(pairs, load) > 0).reshape(self._shape)


def _hits_many(
    rates: np.ndarray, threshold: np.ndarray, reach: np.ndarray, change: np.ndarray
) -> np.ndarray:
    """`_hits` of P points in one array step: `rates` (P, 3, M), `threshold` (P, M), the modes
    that can cross `reach` (P, M; some at every point), the samples' `change` (P, 3, count);
    (P, count). Each point's candidates first, padded to the most any point has with modes
    whose threshold is out of reach."""
    width = int(reach.sum(axis=1).max())
    first = np.argsort(~reach, axis=1, kind="stable")[:, :width]  # the candidates first
    r = np.take_along_axis(rates, first[:, None, :], 2)  # (P, 3, width)
    t = np.where(
        np.take_along_axis(reach, first, 1), np.take_along_axis(threshold, first, 1), np.inf
    )
    growth = np.matmul(r.transpose(0, 2, 1), change)  # (P, width, count)
    growth -= t[:, :, None]
    return growth.max(axis=1) > 0


def _estimates(hits: np.ndarray, shape: tuple[int, ...]) -> list[tuple[float, float]]:
    """`estimate` of each row of `hits` (P, count), the samples of shape (replicates,
    per_replicate)."""
    replicates, per = shape
    share = np.count_nonzero(hits.reshape(len(hits), replicates, per), axis=2) / per
    mean = share.mean(axis=1)
    stderr = np.sqrt(((share - mean[:, None]) ** 2).sum(axis=1) / (replicates - 1) / replicates)
    return list(zip(mean.tolist(), stderr.tolist(), strict=True))


def estimate(hits: np.ndarray) -> tuple[float, float]:
    """P and its standard error from per-sample verdicts of shape (replicates, per_replicate):
    the spread of the replicate means."""
    per = hits.shape[1]
    share = [c / per for c in np.count_nonzero(hits, axis=1).tolist()]
    mean = sum(share) / len(share)
    var = sum((x - mean) ** 2 for x in share) / (len(share) - 1)
    return mean, math.sqrt(var / len(share))
