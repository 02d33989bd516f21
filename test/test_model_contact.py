# SPDX-License-Identifier: Apache-2.0
"""Contact integrals: quadrature convergence, computed once per geometry, operating-point scaling."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from leadscrew_ros.model import ScrewParameters, SqueakModel, modal_basis
from leadscrew_ros.model.contact import contact_angles, contact_integrals
from leadscrew_ros.model.friction import gamma, mu_o
from leadscrew_ros.model.kernels import paper_kernels


def test_contact_angles_match_notes():
    alpha_o, alpha = contact_angles(ScrewParameters())
    assert alpha_o == pytest.approx(343, rel=0.01)
    assert alpha == pytest.approx(137, rel=0.01)
    assert alpha / (2 * math.pi) == pytest.approx(21.8, rel=0.01)


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
def test_quadrature_converges_with_nodes_per_turn(formulation):
    p = ScrewParameters(formulation=formulation)
    basis = modal_basis(p)
    results = {n: contact_integrals(p, basis, nodes_per_turn=n).unit for n in (16, 32, 64, 128)}
    for name, ref in results[128].items():
        scale = np.abs(ref).max()
        err = {n: np.abs(results[n][name] - ref).max() / scale for n in (16, 32, 64)}
        assert err[32] < 1e-9, (name, err)       # the default is converged
        assert err[64] <= err[16] + 1e-14         # and the error does not grow with refinement


def test_quadrature_matches_adaptive_reference():
    """One oscillatory entry against scipy's adaptive quadrature of the raw integrand."""
    p = ScrewParameters()
    basis = modal_basis(p)
    unit = contact_integrals(p, basis).unit
    alpha_o, alpha = contact_angles(p)
    lead = p.radius_m * math.tan(p.helix_angle_rad)
    i, j = basis.labels.index("B1x"), basis.labels.index("B2y")     # [x y] block of W1 (A.3)

    def integrand(t):
        k = paper_kernels(np.array([t]), p.helix_angle_rad, p.radius_m)["W1"][0, 1, 0]
        phi = basis.shapes(np.array([lead * t]))[:, 0]
        return k * phi[i] * phi[j]

    ref = quad(integrand, alpha_o, alpha_o + alpha, limit=2000, epsabs=0, epsrel=1e-12)[0]
    assert unit["W1"][i, j] == pytest.approx(ref, rel=1e-9)


def test_geometry_is_computed_once_and_reused():
    m = SqueakModel()
    same = m.with_params(mu_static=0.3, modal_damping=0.01, axial_load_n=50.0)
    assert same.geometry.contact is m.geometry.contact          # no re-integration
    moved = m.with_params(nut_position_m=0.1)
    assert moved.geometry.contact is not m.geometry.contact
    assert not np.allclose(moved.geometry.contact.unit["W3"], m.geometry.contact.unit["W3"])


def test_operating_point_only_rescales_matrices():
    """W1, W2 ~ mu_o F; W3, W4 ~ mu_o F / Omega; W5q ~ F gamma Omega; W5qdot ~ F gamma; G ~ Omega."""
    m = SqueakModel()
    p = m.params
    a, b = m.geometry.matrices(10.0, 100.0), m.geometry.matrices(30.0, 250.0)
    mu_ratio = mu_o(p, 30.0) / mu_o(p, 10.0)
    g_ratio = gamma(p, 30.0) / gamma(p, 10.0)
    expected = {"W1": mu_ratio * 2.5, "W2": mu_ratio * 2.5, "W3": mu_ratio * 2.5 / 3,
                "W4": mu_ratio * 2.5 / 3, "W5q": g_ratio * 2.5 * 3, "W5qdot": g_ratio * 2.5}
    for name, ratio in expected.items():
        np.testing.assert_allclose(b.W[name], ratio * a.W[name], rtol=1e-12, atol=0)
    np.testing.assert_allclose(b.G, 3 * a.G)
    np.testing.assert_allclose(b.C, a.C)


def test_state_matrix_is_eq_27_in_first_order_form():
    m = SqueakModel()
    s = m.geometry.matrices(20.0, 200.0)
    om = m.geometry.basis.omega_rad_s
    K = np.diag(om ** 2 - 20.0 ** 2) + s.W["W1"] + s.W["W2"] + s.W["W5q"]
    D = s.C + s.G + s.W["W3"] + s.W["W4"] + s.W["W5qdot"]
    n = len(om)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-K, -D]])
    np.testing.assert_allclose(m.state_matrix(20.0, 200.0), A, rtol=1e-12, atol=1e-9)
    batch = m.geometry.state_matrices(np.array([20.0, 5.0]), np.array([200.0, 80.0]))
    np.testing.assert_allclose(batch[0], A, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(batch[1], m.state_matrix(5.0, 80.0), rtol=1e-12, atol=1e-9)


def test_lead_and_travel_are_the_helix_and_the_screw_less_the_nut():
    """The derived quantities every layer uses: the helix advances 2 pi R tan(beta) per turn,
    so the contact spans alpha = b / (R tan(beta)) rad from alpha_o = z_o / (R tan(beta));
    the nut can travel to L - b."""
    p = ScrewParameters(radius_m=0.006, helix_angle_rad=0.1, nut_position_m=0.05,
                        nut_length_m=0.04, length_m=0.25)
    assert p.lead_per_rad_m == pytest.approx(0.006 * math.tan(0.1), rel=1e-15)
    assert p.nut_travel_m == pytest.approx(0.21, rel=1e-15)
    alpha_o, alpha = contact_angles(p)
    assert alpha_o * p.lead_per_rad_m == pytest.approx(0.05, rel=1e-14)
    assert alpha * p.lead_per_rad_m == pytest.approx(0.04, rel=1e-14)
