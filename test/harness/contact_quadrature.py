# SPDX-License-Identifier: Apache-2.0
"""Test-only reference for the contact integrals: composite Gauss-Legendre quadrature over the
helix (the package's method before the closed form of `model.physics.contact`), independent of
`kernels.kernel_harmonics` and of the closed form: it samples the kernels and mode shapes."""

import math

import numpy as np

from leadscrew_ros.model.physics.contact import contact_angles
from leadscrew_ros.model.physics.kernels import KERNELS
from leadscrew_ros.model.physics.modes import ModalBasis
from leadscrew_ros.model.physics.parameters import ScrewParameters

PANEL_NODES = 8


def helix_quadrature(
    start: float, span: float, nodes_per_turn: int
) -> tuple[np.ndarray, np.ndarray]:
    """Composite Gauss-Legendre nodes and weights on [start, start + span] [rad]."""
    panels = max(1, math.ceil(span / (2 * math.pi) * nodes_per_turn / PANEL_NODES))
    x, w = np.polynomial.legendre.leggauss(PANEL_NODES)
    edges = start + span * np.arange(panels + 1) / panels
    half = 0.5 * np.diff(edges)
    theta = (edges[:-1, None] + half[:, None] * (x[None, :] + 1)).ravel()
    return theta, (half[:, None] * w[None, :]).ravel()


def quadrature_integrals(
    p: ScrewParameters, basis: ModalBasis, nodes_per_turn: int
) -> dict[str, np.ndarray]:
    """integral k_ab(theta) [Phi_i^a Phi_j^b](R tan(beta) theta) dtheta for every matrix by
    quadrature, one (modes of kind a) x (modes of kind b) product per non-zero block."""
    alpha_o, alpha = contact_angles(p)
    theta, weights = helix_quadrature(alpha_o, alpha, nodes_per_turn)
    kernels = KERNELS[p.formulation](theta, p.helix_angle_rad, p.radius_m)
    shape = basis.shapes(p.lead_per_rad_m * theta)
    weighted = shape * weights[None, :]
    rows = [np.flatnonzero(basis.kind == a) for a in range(3)]
    out = {}
    for name, k in kernels.items():
        m = np.zeros((basis.n, basis.n))
        for a, b in zip(*np.nonzero(np.any(k != 0, axis=-1)), strict=True):
            m[np.ix_(rows[a], rows[b])] = (weighted[rows[a]] * k[a, b]) @ shape[rows[b]].T
        out[name] = m
    return out
