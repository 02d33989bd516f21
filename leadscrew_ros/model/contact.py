# SPDX-License-Identifier: Apache-2.0
"""Contact integrals over the thread helix, computed once per geometry.

The nut touches the screw along the helix z = R tan(beta) theta, theta in
[alpha_o, alpha_o + alpha] (A.9); over ~22 turns the integrands oscillate, so the integrals use
composite Gauss-Legendre quadrature with a fixed number of nodes per turn (its convergence is
tested in test/test_model_contact.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .kernels import KERNELS
from .modes import ModalBasis
from .parameters import ScrewParameters

_PANEL_NODES = 8


@dataclass(frozen=True)
class ContactIntegrals:
    alpha_o: float                 # rad, start angle of the contact (A.9)
    alpha: float                   # rad, contact angle b / (R tan beta)
    theta: np.ndarray              # quadrature nodes, rad
    weights: np.ndarray            # quadrature weights, rad
    unit: dict[str, np.ndarray]    # W1..W5qdot with unit scale factor (N x N)


def contact_angles(p: ScrewParameters) -> tuple[float, float]:
    """(alpha_o, alpha): helix angles of the nut start and the contact length (A.9)."""
    return p.nut_position_m / p.lead_per_rad_m, p.nut_length_m / p.lead_per_rad_m


def helix_quadrature(start: float, span: float, nodes_per_turn: int) -> tuple[np.ndarray, np.ndarray]:
    """Composite Gauss-Legendre nodes and weights on [start, start + span]."""
    panels = max(1, math.ceil(span / (2 * math.pi) * nodes_per_turn / _PANEL_NODES))
    x, w = np.polynomial.legendre.leggauss(_PANEL_NODES)
    edges = start + span * np.arange(panels + 1) / panels
    half = 0.5 * np.diff(edges)
    theta = (edges[:-1, None] + half[:, None] * (x[None, :] + 1)).ravel()
    return theta, (half[:, None] * w[None, :]).ravel()


def integrate_kernels(basis: ModalBasis, kernels: dict[str, np.ndarray], theta: np.ndarray,
                      weights: np.ndarray, lead_per_rad: float) -> dict[str, np.ndarray]:
    """integral k_ab(theta) [Phi_i^a Phi_j^b](R tan(beta) theta) dtheta for every matrix,
    one (modes of kind a) x (modes of kind b) product per non-zero block."""
    shape = basis.shapes(lead_per_rad * theta)
    weighted = shape * weights[None, :]
    rows = [np.flatnonzero(basis.kind == a) for a in range(3)]
    out = {}
    for name, k in kernels.items():
        m = np.zeros((basis.n, basis.n))
        for a, b in zip(*np.nonzero(np.any(k != 0, axis=-1))):
            m[np.ix_(rows[a], rows[b])] = (weighted[rows[a]] * k[a, b]) @ shape[rows[b]].T
        out[name] = m
    return out


def contact_integrals(p: ScrewParameters, basis: ModalBasis,
                      nodes_per_turn: int | None = None) -> ContactIntegrals:
    alpha_o, alpha = contact_angles(p)
    theta, weights = helix_quadrature(alpha_o, alpha, nodes_per_turn or p.quadrature_nodes_per_turn)
    kernels = KERNELS[p.formulation](theta, p.helix_angle_rad, p.radius_m)
    unit = integrate_kernels(basis, kernels, theta, weights, p.lead_per_rad_m)
    return ContactIntegrals(alpha_o=alpha_o, alpha=alpha, theta=theta, weights=weights, unit=unit)
