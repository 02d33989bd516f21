# SPDX-License-Identifier: Apache-2.0
"""First-order eigenvalue perturbation of (27), and the fast P(squeak) built on it.

For a simple eigenvalue lambda of the state matrix A with right and left eigenvectors x, y
(A x = lambda x, y^H A = lambda y^H, y^H x = 1):

    d lambda = y^H (dA) x

`EigenPairs` holds the oscillatory eigenvalues (Im > 0) of one eigen-solve with x and y^H
(`stability.eig_both`), so the prediction and the probability share one LAPACK call.

`FirstOrderProbability` is the live estimator of P(squeak) over scatter samples. Friction and
damping enter A only through three scalars at a fixed operating point: the friction level
l = mu_o |F_z| c_f / (alpha R) (W1-W4), the friction slope s = gamma |F_z| c_5 / alpha (W5) and
the damping ratio xi; A is affine in them (`kernels.scales`). Each oscillatory eigenvalue is
expanded to first order in them while l, s and xi of every sample are computed exactly (the
friction law is the nonlinear part). A scattered geometry parameter (radius, nut position, ...)
enters through the derivative of A by a central difference of two geometries (built once per
parameter set), to first order in the parameter. P is the share of samples in which some mode's
expanded growth rate exceeds the squeak threshold of `stability.unstable_mask`, so the modes'
correlation (one friction scatter drives them all) is kept.
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from .assembly import Geometry, build_geometry
from .kernels import thread_factors
from .parameters import ScrewParameters, field_info
from .scatter import Samples
from .stability import GROWTH_TOL, Eigen, eig_both

GEOMETRY_STEP = 1e-6          # relative step of a state-matrix difference in a geometry field


class EigenPairs:
    """The oscillatory eigenvalues (Im > 0) of A with right and left eigenvectors.

    Parameters
    ----------
    geometry : Geometry
        The geometry A was built from (its unit matrices give dA).
    speed : float
        Screw speed of A [rad/s].
    eigen : Eigen
        The eigen-solve of A with the oscillatory modes' vectors (`stability.eig_both`).
    """

    def __init__(self, geometry: Geometry, speed: float, eigen: Eigen):
        self.geometry, self.speed = geometry, speed
        self.lam, self.x = eigen.lam[eigen.osc], eigen.right
        y_h = eigen.left.conj().T
        self.y_h = y_h / np.einsum("ij,ji->i", y_h, self.x)[:, None]    # y_i^H x_i = 1

    @classmethod
    def solve(cls, geometry: Geometry, speed: float, load: float) -> "EigenPairs":
        """Eigen-solve A at one operating point [rad/s], [N]."""
        return cls(geometry, speed, eig_both(geometry.state_matrices(speed, load)))

    @cached_property
    def unit_rates(self) -> np.ndarray:
        """d lambda per unit of each coefficient (W1, W5q, W3, W5qdot, Omega) of
        `Geometry.state_matrices` (dA = -[0; U_k]), shape (5, M)."""
        n = self.geometry.n
        units = self.geometry.lower_half_units.reshape(-1, n, 2 * n)
        return -np.einsum("ij,kji->ki", self.y_h[:, n:], units @ self.x)

    def coefficient_rate(self, dc) -> np.ndarray:
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


def geometry_derivative(params: ScrewParameters, name: str, speed: float, load: float
                        ) -> np.ndarray:
    """dA / d(name) by a central difference of two geometries (relative step GEOMETRY_STEP);
    the geometries are cached, so a parameter set pays for them once."""
    h = GEOMETRY_STEP * getattr(params, name)
    hi, lo = (build_geometry(params.with_(**{name: getattr(params, name) + s}))
              .state_matrices(speed, load) for s in (h, -h))
    return (hi - lo) / (2 * h)


class FirstOrderProbability:
    """P(squeak) over scatter samples from one eigen-solve (see the module docstring).

    Parameters
    ----------
    params : ScrewParameters
        Nominal parameters (the scatter is relative to them).
    geometry : Geometry
        The geometry of `params` (modes and contact integrals).
    samples : Samples
        Scatter samples in replicates (`scatter.draw`).
    """

    def __init__(self, params: ScrewParameters, geometry: Geometry, samples: Samples):
        self.params, self.geometry, self.samples = params, geometry, samples
        count, n = samples.count, geometry.n
        values = {k: v.ravel() for k, v in samples.scatter.values(params, samples.u).items()}
        self.geometry_fields = tuple(k for k in values if field_info(k)["geometry"])
        if self.geometry_fields:
            raise ValueError("geometry scatter: see FirstOrderProbability")
        ms, mk, d = (np.broadcast_to(values.get(k, getattr(params, k)), (count,))
                     for k in ("mu_static", "mu_kinetic", "friction_decay_s_m"))
        self._friction = (mk, ms - mk, d, (ms - mk) * d)
        self._change = np.zeros((3, count))                # level, slope, damping ratio
        self._change[2] = values.get("modal_damping", params.modal_damping) \
            - params.modal_damping
        self._reach_damping = float(np.abs(self._change[2]).max())
        # dA per unit coefficient (W1, W5q, W3, W5qdot) and per unit of xi, lower half
        damping = np.zeros((n, 2 * n))
        damping[np.arange(n), n + np.arange(n)] = -2 * geometry.basis.omega_rad_s   # (A.1)
        self._units = np.concatenate([-geometry.lower_half_units[:4].reshape(4 * n, 2 * n),
                                      damping])           # dA = -[0; U_k], [0; damping]
        self._shape = samples.u.shape[:2]

    def _level_slope(self, mk, dm, d, dm_d, speed: float, load: float) -> tuple:
        """Friction level l and slope s of `kernels.scales` (arrays or floats; dm = mu_s -
        mu_k): l = mu_o |F_z| c_f / (alpha R), s = gamma |F_z| c_5 / alpha."""
        p = self.params
        cb = math.cos(p.helix_angle_rad)
        v = p.radius_m * abs(speed) / cb                                    # (11)
        e = np.exp(-v * d)
        m0, g = mk + dm * e, -cb * dm_d * e                                 # (12), (A.11)
        c_f, c_5, _ = thread_factors(p, m0, speed, load)
        f = abs(load) / self.geometry.contact.alpha
        return m0 * (c_f * f / p.radius_m), g * (c_5 * f)

    def margins(self, pairs: EigenPairs, load: float) -> np.ndarray:
        """Per sample, the largest growth rate beyond the squeak threshold over the modes by
        the expansion [1/s] (> 0: squeak; -inf: no mode can reach it), shape (count,)."""
        p, speed, n = self.params, pairs.speed, self.geometry.n
        level0, slope0 = self._level_slope(p.mu_kinetic, p.mu_static - p.mu_kinetic,
                                           p.friction_decay_s_m, (p.mu_static - p.mu_kinetic)
                                           * p.friction_decay_s_m, speed, load)
        level, slope = self._level_slope(*self._friction, speed, load)
        change = self._change
        np.subtract(level, level0, out=change[0])
        np.subtract(slope, slope0, out=change[1])
        # d lambda per unit coefficient: y^H dA x over the lower half of A (one product)
        r = np.einsum("ij,kji->ki", pairs.y_h[:, n:],
                      (self._units @ pairs.x).reshape(5, n, -1)).real
        # level l: W1 = sign l, W3 = l / |Omega|; slope s: W5q = Omega s, W5qdot = s
        rates = np.stack([math.copysign(1.0, speed) * r[0] + r[2] / abs(speed),
                          speed * r[1] + r[3], r[4]])                  # (3, M)
        threshold = GROWTH_TOL * np.abs(pairs.lam) - pairs.lam.real    # growth beyond it
        reach = [abs(level - level0).max(), abs(slope - slope0).max(), self._reach_damping]
        candidates = np.flatnonzero(np.dot(reach, np.abs(rates)) > threshold)
        if not len(candidates):                                        # no mode can reach it
            return np.full(change.shape[1], -np.inf)
        growth = rates[:, candidates].T @ change                       # (Mc, count)
        growth -= threshold[candidates, None]
        return growth.max(axis=0)

    def hits(self, pairs: EigenPairs, load: float) -> np.ndarray:
        """Whether each sample squeaks at the operating point of `pairs`, by the expansion;
        shape (replicates, per_replicate)."""
        return (self.margins(pairs, load) > 0).reshape(self._shape)


def estimate(hits: np.ndarray) -> tuple[float, float]:
    """P and its standard error from per-sample verdicts of shape (replicates, per_replicate):
    the spread of the replicate means."""
    per = hits.shape[1]
    share = [c / per for c in np.count_nonzero(hits, axis=1).tolist()]
    mean = sum(share) / len(share)
    var = sum((x - mean) ** 2 for x in share) / (len(share) - 1)
    return mean, math.sqrt(var / len(share))

