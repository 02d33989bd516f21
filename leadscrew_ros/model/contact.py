# SPDX-License-Identifier: Apache-2.0
"""Contact integrals over the thread helix, in closed form.

The nut touches the screw along the helix z = R tan(beta) theta, theta in
[alpha_o, alpha_o + alpha] (A.9). Every kernel is a trigonometric polynomial of degree 2 in
theta, k(theta) = sum_m c_m e^{i m theta}, m = -2..2 (`kernels.kernel_harmonics`), and every
mode shape is A sin(k z) (`modes`), so with sin(k_i z) sin(k_j z) = (cos((k_i - k_j) z) -
cos((k_i + k_j) z)) / 2 each integral is

    integral k Phi_i Phi_j dtheta = A_i A_j / 2 Re sum_m c_m (F(omega_m^-) - F(omega_m^+)),
    omega_m^-+ = m + R tan(beta) (k_i -+ k_j),
    F(omega) = integral e^{i omega theta} dtheta = alpha e^{i omega theta_c} sinc(omega alpha / 2)

over the contact, theta_c = alpha_o + alpha / 2 its middle. The phase omega theta_c is taken
apart into the thread's m alpha_o + m alpha / 2 (exact multiples of the angles) and the modes'
(k_i -+ k_j) z_c (z_c = z_o + b / 2: at most a few hundred rad), and sin(omega alpha / 2)
likewise, so the rounding error does not grow with the number of turns to the nut; sinc takes
its Taylor series near 0. The terms depend on the pair (i, j) only through the two distinct
wavenumbers and on the kinds of the two modes only through c_m, so a table of every kind block
(a, b) over the distinct wavenumbers (one small matrix product) holds every entry.
test/test_model_contact.py compares with adaptive quadrature.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .kernels import HARMONICS, MATRICES, kernel_harmonics
from .modes import ModalBasis
from .parameters import ScrewParameters

_TAYLOR = 0.1          # |x| below which sinc(x) takes its series (truncation error < 3e-18)
_M = len(HARMONICS)


def contact_angles(p: ScrewParameters) -> tuple[float, float]:
    """(alpha_o, alpha): helix angles of the nut start and the contact length (A.9)."""
    return p.nut_position_m / p.lead_per_rad_m, p.nut_length_m / p.lead_per_rad_m


def _sinc_series(x: np.ndarray) -> np.ndarray:
    """sin(x) / x for |x| < _TAYLOR."""
    x2 = x * x
    return 1 - x2 / 6 * (1 - x2 / 20 * (1 - x2 / 42 * (1 - x2 / 72)))


@dataclass(frozen=True, eq=False)
class HelixContact:
    """What the contact integrals need from the screw, its modes and the kernels: everything
    but the nut (position and length), precomputed once per screw (`helix_contact`).

    U is the number of distinct (wavenumber, amplitude) pairs of the N modes (x and y bending
    modes share theirs), M = len(HARMONICS)."""

    lead_per_rad_m: float          # R tan(beta), m/rad
    wavenumber: np.ndarray         # (U,) distinct k of the mode shapes, rad/m
    omega: np.ndarray              # (M, 2, U, U) omega_m^-+ of the pairs, 1/rad
    weight: np.ndarray             # (M, 2, U, U) +-A_i A_j / omega (0 where omega = 0)
    half_amplitude: np.ndarray     # (2, U, U) +-A_i A_j / 2
    kernels: np.ndarray            # (len(MATRICES), 9 * 2M): Re c_m, -Im c_m of each block
    index: np.ndarray              # (N, N) column of mode pair (I, J) in a table row
    abs_omega: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "abs_omega", np.abs(self.omega))

    def integrals(self, nut_position_m: float, nut_length_m: float) -> ContactIntegrals:
        """The contact integrals of a nut at z_o = `nut_position_m` of length b =
        `nut_length_m` [m]."""
        lead, k = self.lead_per_rad_m, self.wavenumber
        alpha_o, alpha = nut_position_m / lead, nut_length_m / lead
        half = nut_length_m / 2
        z = nut_position_m + half
        # e^{-+i k z_c}, e^{-+i k b/2} per mode, then per pair e^{i (k_i -+ k_j) (z_c, b/2)}
        single = np.exp(np.multiply.outer((-1j * z, 1j * z, -1j * half, 1j * half), k))
        single = single.reshape(2, 2, -1)
        pair = single[:, 1, None, :, None] * single[:, :, None, :]             # (2, 2, U, U)
        thread = np.exp(np.multiply.outer(1j * HARMONICS, (alpha_o, alpha / 2)))   # (M, 2)
        turn = thread[:, 1, None, None, None]                           # e^{i m alpha / 2}
        sin_x = (turn * pair[1]).imag                                   # sin(omega alpha / 2)
        phase = (thread[:, 0, None, None, None] * turn) * pair[0]       # e^{i omega theta_c}
        f = phase * (sin_x * self.weight)                               # A A F(omega) / 2
        small = np.flatnonzero(self.abs_omega < _TAYLOR / (alpha / 2))
        f.flat[small] = (phase.flat[small] * alpha * self.half_amplitude.flat[small % f[0].size]
                         * _sinc_series(self.omega.flat[small] * (alpha / 2)))
        both = f.sum(axis=1).reshape(_M, -1)                            # F^- - F^+
        return ContactIntegrals(alpha_o=alpha_o, alpha=alpha, helix=self,
                                exponentials=np.concatenate((both.real, both.imag)))

    def table(self, exponentials: np.ndarray, kernels: np.ndarray,
              out: np.ndarray | None = None) -> np.ndarray:
        """Every kind block (a, b) of every matrix over the distinct pairs: Re sum_m c_m E_m,
        (len(kernels) * 9, U * U), written to `out` when given."""
        return np.matmul(kernels.reshape(-1, 2 * _M), exponentials, out=out)


@dataclass(frozen=True, eq=False)
class ContactIntegrals:
    """integral k_ab(theta) [Phi_i^a Phi_j^b](R tan(beta) theta) dtheta over the contact (A.9)
    for every W of `kernels.MATRICES`."""

    alpha_o: float                 # rad, start angle of the contact (A.9)
    alpha: float                   # rad, contact angle b / (R tan beta)
    helix: HelixContact
    exponentials: np.ndarray       # (2M, U * U) Re, Im of A_i A_j (F(omega^-) - F(omega^+)) / 2

    @cached_property
    def unit(self) -> dict[str, np.ndarray]:
        """W1..W5qdot with unit scale factor (N x N)."""
        helix = self.helix
        table = helix.table(self.exponentials, helix.kernels)
        return dict(zip(MATRICES, table.reshape(len(MATRICES), -1)[:, helix.index]))


def helix_contact(p: ScrewParameters, basis: ModalBasis) -> HelixContact:
    """The nut-independent part of the contact integrals for this screw and formulation."""
    distinct, pick = np.unique(np.stack((basis.wavenumber, basis.amplitude), 1), axis=0,
                               return_inverse=True)
    pick = pick.ravel()
    k, amp = distinct.T
    u = len(k)
    lead = p.lead_per_rad_m
    sign = np.array([1.0, -1.0])[:, None, None]                          # F^- - F^+
    omega = HARMONICS[:, None, None, None] + lead * np.stack(
        (k[:, None] - k[None, :], k[:, None] + k[None, :]))
    amp2 = sign * np.outer(amp, amp)
    with np.errstate(divide="ignore"):
        weight = np.where(omega == 0, 0.0, amp2 / omega)
    c = kernel_harmonics(p.formulation, p.helix_angle_rad, p.radius_m)   # (W, 3, 3, M)
    kernels = np.concatenate((c.real, -c.imag), axis=-1).reshape(len(MATRICES), -1)
    block = 3 * basis.kind[:, None] + basis.kind[None, :]
    return HelixContact(lead_per_rad_m=lead, wavenumber=k, omega=omega, weight=weight,
                        half_amplitude=amp2 / 2, kernels=kernels,
                        index=block * u * u + pick[:, None] * u + pick[None, :])


def contact_integrals(p: ScrewParameters, basis: ModalBasis) -> ContactIntegrals:
    """The contact integrals of these parameters, in closed form.

    Parameters
    ----------
    p : ScrewParameters
        Screw and nut geometry, formulation.
    basis : ModalBasis
        The modes of this screw (`modes.modal_basis(p)`).

    Returns
    -------
    ContactIntegrals
        The angles of the contact and (`unit`) the N x N matrices with unit scale factor.
    """
    return helix_contact(p, basis).integrals(p.nut_position_m, p.nut_length_m)
