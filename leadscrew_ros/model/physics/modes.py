# SPDX-License-Identifier: Apache-2.0
"""Modal basis of the uncoupled screw: mass-normalised bending (hinged-hinged, x and y) and
torsion (clamped-free) modes, eqs. (21)-(26) mass-normalised against the energies (15)-(17)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .parameters import ScrewParameters

# Mode kinds, used to pick the block [Phi_i^a Phi_j^b] a kernel entry belongs to.
KIND_X, KIND_Y, KIND_T = 0, 1, 2


@dataclass(frozen=True)
class ModalBasis:
    """The assumed modes of the screw, eqs. (24)-(26). Ordering: B1x, B1y, B2x, B2y, ...,
    then T1..Tn (row i = equation of mode i).

    Attributes
    ----------
    labels : tuple of str
        B1x, B1y, ..., T1, ...
    kind : ndarray
        (N,) KIND_X / KIND_Y / KIND_T.
    order : ndarray
        (N,) n of sin(n pi z / L), or (2n-1) of the torsion shape.
    wavenumber : ndarray
        (N,) [rad/m]: n pi / L or (2n-1) pi / (2L).
    amplitude : ndarray
        (N,) mass-normalising factor [1/sqrt(kg) or 1/sqrt(kg m^2)].
    omega_rad_s : ndarray
        (N,) natural frequencies [rad/s].
    """

    labels: tuple[str, ...]
    kind: np.ndarray
    order: np.ndarray
    wavenumber: np.ndarray
    amplitude: np.ndarray
    omega_rad_s: np.ndarray

    @property
    def n(self) -> int:
        """Number of modes N."""
        return len(self.labels)

    @property
    def frequency_hz(self) -> np.ndarray:
        """(N,) natural frequencies [Hz]."""
        return self.omega_rad_s / (2 * math.pi)

    def shapes(self, z_m: np.ndarray) -> np.ndarray:
        """Phi_i(z) for every mode i at the positions z, eqs. (24)-(26).

        Parameters
        ----------
        z_m : ndarray
            Positions along the screw [m].

        Returns
        -------
        ndarray
            (N, len(z_m)).
        """
        return self.amplitude[:, None] * np.sin(self.wavenumber[:, None] * np.asarray(z_m)[None, :])


def modal_basis(p: ScrewParameters) -> ModalBasis:
    """The assumed modes of the screw, mass-normalised: bending (hinged-hinged, x and y) and
    torsion (clamped-free).

    Parameters
    ----------
    p : ScrewParameters
        Dimensions, material and the numbers of modes `n_bending`, `n_torsion`.

    Returns
    -------
    ModalBasis
        2 * n_bending bending modes, then n_torsion torsion modes.
    """
    area = math.pi * p.radius_m**2
    polar = math.pi * p.radius_m**4 / 2  # J = I_zz
    inertia = math.pi * p.radius_m**4 / 4  # I_xx = I_yy
    nb, nt = p.n_bending, p.n_torsion
    n_b = np.repeat(np.arange(1, nb + 1), 2)
    n_t = 2 * np.arange(1, nt + 1) - 1
    k_b = n_b * math.pi / p.length_m
    k_t = n_t * math.pi / (2 * p.length_m)
    omega_b = k_b**2 * math.sqrt(p.youngs_modulus_pa * inertia / (p.density_kg_m3 * area))
    omega_t = k_t * math.sqrt(p.shear_modulus_pa / p.density_kg_m3)
    labels = tuple(f"B{n}{'xy'[i % 2]}" for i, n in enumerate(n_b)) + tuple(
        f"T{n}" for n in range(1, nt + 1)
    )
    kind = np.concatenate([np.tile([KIND_X, KIND_Y], nb), np.full(nt, KIND_T)])
    amp_b = math.sqrt(2 / (p.density_kg_m3 * area * p.length_m))
    amp_t = math.sqrt(2 / (p.density_kg_m3 * polar * p.length_m))
    return ModalBasis(
        labels=labels,
        kind=kind,
        order=np.concatenate([n_b, n_t]),
        wavenumber=np.concatenate([k_b, k_t]),
        amplitude=np.concatenate([np.full(2 * nb, amp_b), np.full(nt, amp_t)]),
        omega_rad_s=np.concatenate([omega_b, omega_t]),
    )
