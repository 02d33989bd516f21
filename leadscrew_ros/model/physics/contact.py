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
likewise, so the rounding error does not grow with the number of turns to the nut. Where
omega alpha / 2 is near 0 (omega = 0 or a resonance of thread and mode), whose split loses
digits, sin(x) / x is taken directly. The terms depend on the pair (i, j) only through the two
distinct wavenumbers and on the kinds of the two modes only through c_m, so a table of every
kind block (a, b) over the distinct wavenumbers (one small matrix product) holds every entry.

test/test_model_contact.py compares with adaptive quadrature: within 1e-12 of each matrix's
largest entry. One limit: where the mode shapes are small over the whole contact (k z << 1,
a nut within about a millimetre of an end of the screw), the exponentials that make up
sin(k_i z) sin(k_j z) cancel, and the error relative to the largest entry grows like
eps / (k_max d)^2, d the nut's reach from that end (1e-13 at d = 1 mm with 6/6 modes, 1e-11
at 0.1 mm); it stays at eps of A^2 alpha in absolute terms.
"""

from __future__ import annotations

import cmath
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np

from .kernels import HARMONICS, MATRICES, kernel_harmonics
from .modes import ModalBasis
from .parameters import ScrewParameters

_DIRECT = 0.1  # |x| = |omega alpha / 2| below which sin(x) / x is taken directly
_M = len(HARMONICS)
_BLAS_ONE_THREAD = 65536 * 4  # m n k of a product below which OpenBLAS uses one thread
_SIGNS = np.array([-1j, 1j])  # e^{-i x}, e^{i x}
_I_HARMONICS = 1j * HARMONICS  # e^{i m angle} = exp(angle * this)


def contact_angles(p: ScrewParameters) -> tuple[float, float]:
    """(alpha_o, alpha): helix angles of the nut start and the contact length (A.9)."""
    return p.nut_position_m / p.lead_per_rad_m, p.nut_length_m / p.lead_per_rad_m


def _harmonics(angle: float) -> np.ndarray:
    """e^{i m angle} for m in HARMONICS, shape (M, 1)."""
    one, two = cmath.exp(1j * angle), cmath.exp(2j * angle)
    return np.array([[two.conjugate()], [one.conjugate()], [1.0], [one], [two]])


@dataclass(frozen=True, eq=False)
class HelixContact:
    """What the contact integrals need from the screw, its modes and the kernels: everything
    but the nut (position and length), precomputed once per screw (`helix_contact`).

    The terms are laid out (M, 2, P): M = len(HARMONICS), the two frequencies omega^- (sign
    +1) and omega^+ (sign -1), and P = U * U pairs of the U distinct (wavenumber, amplitude)
    of the N modes (x and y bending modes share theirs)."""

    lead_per_rad_m: float  # R tan(beta), m/rad
    wavenumber: np.ndarray  # (U,) distinct k of the mode shapes, rad/m
    weight: np.ndarray  # (M, 2P) sign A_i A_j / omega (0 where omega = 0)
    level: np.ndarray  # (M, 2P) sign A_i A_j where omega = 0, else 0
    near: np.ndarray  # flat indices of the other terms by ascending |omega|
    near_omega: np.ndarray  # their omega, 1/rad
    near_amplitude: np.ndarray  # their sign A_i A_j
    kernels: np.ndarray  # (len(MATRICES) * 9, 4M): Re c_m, -Im c_m of each block
    index: np.ndarray  # (N, N) entry of mode pair (I, J) in one matrix's table
    near_abs: np.ndarray = field(init=False)
    near_out: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "near_abs", np.abs(self.near_omega))
        pairs = len(self.wavenumber) ** 2  # (M, 2P) index -> (M, 2, 2, P)
        m, rest = np.divmod(self.near, 2 * pairs)
        object.__setattr__(
            self, "near_out", m * 4 * pairs + rest // pairs * 2 * pairs + rest % pairs
        )

    def integrals(self, nut_position_m: float, nut_length_m: float) -> ContactIntegrals:
        """The contact integrals of a nut at z_o = `nut_position_m` of length b =
        `nut_length_m` [m]."""
        lead = self.lead_per_rad_m
        return ContactIntegrals(
            alpha_o=nut_position_m / lead,
            alpha=nut_length_m / lead,
            helix=self,
            exponentials=self.exponentials(np.array([nut_position_m]), nut_length_m)[0],
        )

    def exponentials(self, nut_positions_m: np.ndarray, nut_length_m: float) -> np.ndarray:
        """`ContactIntegrals.exponentials` of nuts of length b = `nut_length_m` at each of the
        positions z_o = `nut_positions_m` (D,) [m], in one vectorised step: (D, 4M, P). Only
        the phases depend on the position (what depends on the length alone is `_nut_terms`,
        cached); the same operations per element for one nut as for many."""
        nut = _nut_terms(self, nut_length_m)
        d, pairs = len(nut_positions_m), len(self.wavenumber) ** 2
        z_c = nut_positions_m + nut_length_m / 2  # the contact's middle
        at_z = np.exp(np.multiply.outer(np.multiply.outer(z_c, _SIGNS), self.wavenumber))
        pq_z = at_z[:, 1, None, :, None] * at_z[:, :, None, :]  # e^{i k_i z_c} e^{-+i k_j z_c}
        starts = np.exp(np.multiply.outer(nut_positions_m / self.lead_per_rad_m, _I_HARMONICS))
        starts *= nut.turn  # e^{i m alpha_o} e^{i m alpha / 2}, (D, M)
        phase = starts[:, :, None] * pq_z.reshape(d, 1, -1)  # e^{i omega theta_c}, (D, M, 2P)
        # sign A A F(omega) / 2 = phase g, stored (D, M, 2 signs, Re / Im, P)
        out = np.empty((d, _M, 2, 2, pairs))
        wide = phase.reshape(d, _M, 2, pairs)
        np.multiply(wide.real, nut.g, out=out[:, :, :, 0])
        np.multiply(wide.imag, nut.g, out=out[:, :, :, 1])
        if len(nut.near):  # sin from the split loses digits near 0
            f = phase.reshape(d, -1)[:, nut.near] * nut.near_factor
            flat = out.reshape(d, -1)
            flat[:, nut.near_out] = f.real
            flat[:, nut.near_out + pairs] = f.imag
        return out.reshape(d, 4 * _M, -1)

    def table(
        self, exponentials: np.ndarray, kernels: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """Every kind block (a, b) of every matrix of `kernels` (rows: combinations of the
        rows of `self.kernels`) over the distinct pairs, Re sum_m c_m A A (F^- - F^+) / 2:
        (rows of `kernels`, U * U), or (D, rows, U * U) of D nuts' `exponentials` (D, 4M,
        U * U); written to `out` when given.

        In column blocks small enough that OpenBLAS stays on one thread: woken, its threads
        spin on the other core through the eigen-solve that follows (and on a loaded 2-core
        machine a threaded product of this size took 10-30x longer, measured at 20/20 modes)."""
        if out is None:
            out = np.empty(exponentials.shape[:-2] + (len(kernels), exponentials.shape[-1]))
        step = max(1, _BLAS_ONE_THREAD // kernels.size)
        for c in range(0, exponentials.shape[-1], step):
            np.matmul(kernels, exponentials[..., c : c + step], out=out[..., c : c + step])
        return out


@dataclass(frozen=True, eq=False)
class _NutTerms:
    """The part of the contact terms that depends on the nut's length b, not on its position:
    (M, 2, P) as `HelixContact` lays them out."""

    turn: np.ndarray  # (M,) e^{i m alpha / 2}
    g: np.ndarray  # (M, 2, P) sign A_i A_j sin(omega alpha / 2) / omega; alpha / 2 sign A A at 0
    near: np.ndarray  # flat (M, 2P) indices of the terms whose sin(x) / x is taken directly
    near_out: np.ndarray  # their flat indices (real parts) in (M, 2 signs, Re / Im, P)
    near_factor: np.ndarray  # their alpha / 2 sign A A sin(x) / x


@lru_cache(maxsize=16)
def _nut_terms(helix: HelixContact, nut_length_m: float) -> _NutTerms:
    """`_NutTerms` of a nut of length b = `nut_length_m` [m] on `helix`'s screw: computed
    once per length (a moved nut keeps its length)."""
    h = nut_length_m / helix.lead_per_rad_m / 2
    half = nut_length_m / 2
    # e^{i k_i x} e^{-+i k_j x} for x = b / 2
    at_half = np.exp(np.multiply.outer(half * _SIGNS, helix.wavenumber))
    pq_half = (at_half[1, None, :, None] * at_half[:, None, :]).reshape(1, -1)
    turn = _harmonics(h)  # e^{i m alpha / 2}
    sin_x = (turn * pq_half).imag  # sin(omega alpha / 2)
    n = np.searchsorted(helix.near_abs, _DIRECT / h)
    x = helix.near_omega[:n] * h
    return _NutTerms(
        turn=turn.ravel(),
        g=(sin_x * helix.weight + h * helix.level).reshape(_M, 2, -1),
        near=helix.near[:n],
        near_out=helix.near_out[:n],
        near_factor=(h * helix.near_amplitude[:n]) * (np.sin(x) / x),
    )


@dataclass(frozen=True, eq=False)
class ContactIntegrals:
    """integral k_ab(theta) [Phi_i^a Phi_j^b](R tan(beta) theta) dtheta over the contact (A.9)
    for every W of `kernels.MATRICES`."""

    alpha_o: float  # rad, start angle of the contact (A.9)
    alpha: float  # rad, contact angle b / (R tan beta)
    helix: HelixContact
    exponentials: np.ndarray  # (4M, P) sign A_i A_j F(omega) / 2: rows m, sign, Re / Im

    @cached_property
    def unit(self) -> dict[str, np.ndarray]:
        """W1..W5qdot with unit scale factor (N x N)."""
        helix = self.helix
        table = helix.table(self.exponentials, helix.kernels).reshape(len(MATRICES), -1)
        return {w: table[i, helix.index] for i, w in enumerate(MATRICES)}


def helix_contact(p: ScrewParameters, basis: ModalBasis) -> HelixContact:
    """The nut-independent part of the contact integrals for this screw and formulation."""
    distinct, pick = np.unique(
        np.stack((basis.wavenumber, basis.amplitude), 1), axis=0, return_inverse=True
    )
    pick = pick.ravel()
    k, amp = distinct.T
    u, lead = len(k), p.lead_per_rad_m
    pairs = np.stack((k[:, None] - k[None, :], k[:, None] + k[None, :])).reshape(1, 2, -1)
    omega = (HARMONICS[:, None, None] + lead * pairs).reshape(_M, -1)  # (M, 2P)
    amp2 = np.broadcast_to(
        (np.outer(amp, amp).ravel() * np.array([[1.0], [-1.0]])).ravel(), omega.shape
    )  # F^- - F^+
    zero = omega == 0
    with np.errstate(divide="ignore"):
        weight = np.where(zero, 0.0, amp2 / omega)
    near = np.flatnonzero(~zero)
    near = near[np.argsort(np.abs(omega.ravel()[near]), kind="stable")]
    c = kernel_harmonics(p.formulation, p.helix_angle_rad, p.radius_m)  # (W, 3, 3, M)
    c = np.stack((c.real, -c.imag), -1).reshape(len(MATRICES) * 9, _M, 1, 2)
    kernels = np.broadcast_to(c, c.shape[:2] + (2, 2)).reshape(len(MATRICES) * 9, -1)
    return HelixContact(
        lead_per_rad_m=lead,
        wavenumber=k,
        weight=weight,
        level=np.where(zero, amp2, 0.0),
        near=near,
        near_omega=omega.ravel()[near],
        near_amplitude=amp2.ravel()[near],
        kernels=kernels,
        index=(3 * basis.kind[:, None] + basis.kind[None, :]) * u * u
        + pick[:, None] * u
        + pick[None, :],
    )


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
