# SPDX-License-Identifier: Apache-2.0
"""The nut's friction force on the screw, nonlinear, projected on the modes (the time-domain
simulation's contact force, `transient`).

The same kinematics and friction law as the `consistent` linearisation (`kernels`,
tools/derive_consistent.py), not linearised. At the point theta of the contact helix
(z = R tan(beta) theta), in the frame (e_r, e_theta, k) of that point, with the deflections
u_a(z) = sum_i Phi_i^a(z) q_i of the kinds a = x, y, 0 (torsion) and w_x = i, w_y = j,
w_0 = R e_theta (14):

    Vc = R Omega (e_theta + tan(beta) k) + sum_a (Omega k x w_a u_a + w_a du_a/dt)   (3)-(5), (11)
    f  = -mu(|Vc|) n g(Vc),   g(V) = tanh(|V| / v_eps) V / |V|                       (10), (12)
    Q_i = integral over the contact of f . w_a(theta) Phi_i^a(z(theta)) dtheta        (13), (14)

n is the constant normal force per radian of helix from the axial load balance (6)-(9) at
steady sliding, |F_z| / (alpha cos(beta) (1 + s mu_o tan(beta))), s = sign(Omega F_z) the
loaded flank. g is the regularisation of the direction Vc / |Vc| near zero sliding speed: a
viscous law of slope 1 / v_eps below v_eps, the exact direction above (tanh(x) = 1 to machine
precision for x > 19). Its Jacobian is continuous everywhere, which the implicit integrator
needs through stick.

The integral over the contact is a composite Gauss-Legendre rule, one panel per thread turn
(the integrand is a trigonometric polynomial of degree 2 in theta in the linear regime, and
smooth in theta beyond it). At Omega, F_z the Jacobian of -Q at q = qdot = 0 is the stiffness
W1 + W2 + W5q and the damping W3 + W4 + W5qdot of the `consistent` formulation
(test/test_transient.py checks it against the closed-form matrices of `contact`).
"""

from __future__ import annotations

import math
from typing import Literal, overload

import numpy as np

from ..physics.contact import contact_angles
from ..physics.friction import friction_coefficient, steady_friction
from ..physics.kernels import thread_factors
from ..physics.modes import ModalBasis
from ..physics.parameters import ScrewParameters

_SERIES_BELOW = 1e-2  # |V| / v_eps below which tanh(x) / x and its derivative use series


def _direction_factors(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(tanh(x) / x, x d/dx (tanh(x) / x)) for x = |V| / v_eps >= 0, with their series near 0
    (the closed forms cancel there)."""
    th = np.tanh(x)
    small = x < _SERIES_BELOW
    if not small.any():  # sliding: the common case, no series
        a = th / x
        return a, (1 - th * th) - a
    xs = np.where(small, 1.0, x)  # no 0 / 0 in the discarded branch
    a = np.where(small, 1 - x * x / 3 + 2 * x**4 / 15, th / xs)
    b = np.where(small, -2 * x * x / 3 + 8 * x**4 / 15, (1 - th * th) - th / xs)
    return a, b


class HelixFriction:
    """Friction force of the nut over the contact helix as generalised modal forces.

    Parameters
    ----------
    params : ScrewParameters
        Screw, nut and friction law (the formulation field is not used: the force is the one
        of the kinematics, whose linearisation is `consistent`).
    basis : ModalBasis
        The modes kept (any subset of `modes.modal_basis(params)`).
    speed_rad_s : float
        Screw speed Omega [rad/s] (signed).
    load_n : float
        Axial load F_z [N] (signed; the flank follows its sign).
    regularisation_m_s : float
        v_eps of the direction regularisation g [m/s], > 0.
    points_per_turn : int
        Gauss-Legendre points per thread turn of the contact.
    """

    def __init__(
        self,
        params: ScrewParameters,
        basis: ModalBasis,
        speed_rad_s: float,
        load_n: float,
        regularisation_m_s: float,
        points_per_turn: int,
    ):
        self.params, self.speed = params, float(speed_rad_s)
        self.v_eps = float(regularisation_m_s)
        alpha_o, alpha = contact_angles(params)
        panels = max(1, math.ceil(alpha / (2 * math.pi)))
        x, w = np.polynomial.legendre.leggauss(points_per_turn)
        width = alpha / panels
        theta = (alpha_o + width * (np.arange(panels)[:, None] + (x + 1) / 2)).ravel()
        weight = np.tile(w * width / 2, panels)
        s, c, r = np.sin(theta), np.cos(theta), params.radius_m
        zero, rr = np.zeros_like(theta), np.full_like(theta, r)
        # w_a and k x w_a in (e_r, e_theta, k) per kind a (x, y, 0), as in kernels._consistent
        w_kind = np.array([[c, -s, zero], [s, c, zero], [zero, rr, zero]])
        kw_kind = np.array([[s, c, zero], [-c, s, zero], [-rr, zero, zero]])
        phi = basis.shapes(params.lead_per_rad_m * theta)  # (N, P)
        w_modes = w_kind[basis.kind] * phi[:, None, :]  # (N, 3, P): w_a Phi_i per mode
        n_modes = basis.n
        self._w_flat = w_modes.reshape(n_modes, -1)
        self._kw_flat = (kw_kind[basis.kind] * phi[:, None, :]).reshape(n_modes, -1)
        self._state_velocity = np.vstack((self.speed * self._kw_flat, self._w_flat))  # (2N, 3P)
        self._weighted = w_modes * weight  # quadrature weights applied
        self._ww = self._weighted.reshape(n_modes, -1)
        beta = params.helix_angle_rad
        self.v0 = r * self.speed * np.array([0.0, 1.0, math.tan(beta)])
        mu0, _ = steady_friction(params, self.speed)
        # the loaded flank's factor 1 / (1 + s mu_o tan(beta)) of (9), as the linearisation has it
        c, _, _ = thread_factors(params.with_(formulation="consistent"), mu0, self.speed, load_n)
        self.normal_per_rad = abs(load_n) * float(c) / (alpha * math.cos(beta))

    def velocity(self, q: np.ndarray, qdot: np.ndarray) -> np.ndarray:
        """Contact velocity Vc at every quadrature point, (3, P) in (e_r, e_theta, k) [m/s].

        Parameters
        ----------
        q : numpy.ndarray
            Modal coordinates, (N,).
        qdot : numpy.ndarray
            Their rates, (N,).

        Returns
        -------
        numpy.ndarray
            Vc, (3, P).
        """
        v = np.concatenate((q, qdot)) @ self._state_velocity
        return v.reshape(3, -1) + self.v0[:, None]

    @overload
    def force(
        self, q: np.ndarray, qdot: np.ndarray, jacobian: Literal[False] = False
    ) -> np.ndarray: ...

    @overload
    def force(
        self, q: np.ndarray, qdot: np.ndarray, jacobian: Literal[True]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def force(
        self, q: np.ndarray, qdot: np.ndarray, jacobian: bool = False
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Generalised friction forces Q (N,) and, with `jacobian`, dQ/dq and dQ/dqdot (N, N).

        Parameters
        ----------
        q : numpy.ndarray
            Modal coordinates, (N,).
        qdot : numpy.ndarray
            Their rates, (N,).
        jacobian : bool
            Also return the two Jacobians.

        Returns
        -------
        numpy.ndarray or tuple of numpy.ndarray
            Q, or (Q, dQ/dq, dQ/dqdot).
        """
        vc = self.velocity(q, qdot)
        speed = np.sqrt(np.einsum("cp,cp->p", vc, vc))
        a, b = _direction_factors(speed / self.v_eps)
        mu = friction_coefficient(self.params, speed)
        phi = mu * a / self.v_eps  # f = -n phi(|V|) V
        f = -self.normal_per_rad * phi * vc
        q_force = self._ww @ f.ravel()
        if not jacobian:
            return q_force
        p = self.params
        dmu = (
            -p.friction_decay_s_m
            * (p.mu_static - p.mu_kinetic)
            * np.exp(-p.friction_decay_s_m * speed)
        )
        # df/dV = -n (phi I + |V| phi'(|V|) e e), e = V / |V|; |V| phi' = (mu' |V| a + mu b)
        # / v_eps, and |V| phi' e e = (mu' a / |V| + mu b / |V|^2) V V / v_eps (finite at 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            e = np.where(speed > 0, vc / speed, 0.0)
        radial = (dmu * speed * a + mu * b) / self.v_eps
        df = -self.normal_per_rad * (
            phi * np.eye(3)[:, :, None] + radial * e[:, None, :] * e[None, :, :]
        )  # (3, 3, P)
        left = np.einsum("icp,cdp->idp", self._weighted, df).reshape(len(q), -1)
        return q_force, self.speed * (left @ self._kw_flat.T), left @ self._w_flat.T
