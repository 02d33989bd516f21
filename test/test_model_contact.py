# SPDX-License-Identifier: Apache-2.0
"""Contact integrals: the closed form against quadrature (test/harness/contact_quadrature.py
and scipy's adaptive quad) over a range of geometries; computed once per geometry;
operating-point scaling."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from harness.contact_quadrature import quadrature_integrals
from leadscrew_ros.model import ScrewParameters, SqueakModel, modal_basis
from leadscrew_ros.model.physics.contact import contact_angles, contact_integrals, helix_contact
from leadscrew_ros.model.physics.friction import gamma, mu_o
from leadscrew_ros.model.physics.kernels import HARMONICS, KERNELS, MATRICES, kernel_harmonics


def test_contact_angles_match_notes():
    alpha_o, alpha = contact_angles(ScrewParameters())
    assert alpha_o == pytest.approx(343, rel=0.01)
    assert alpha == pytest.approx(137, rel=0.01)
    assert alpha / (2 * math.pi) == pytest.approx(21.8, rel=0.01)


# Geometries spanning the parameter space: nut length from a fraction of a turn to hundreds of
# turns, helix angle 1 to 40 degrees, nut at either end, up to 40/40 modes; "resonance" puts
# omega = -1 + R tan(beta) (k_i + k_j) at 0 for the bending pairs with n_i + n_j = 23.
GEOMETRIES = {
    "table 1": {},
    "0.4 turn at the start": dict(nut_position_m=0.0, nut_length_m=0.0011),
    "1 mm at the far end": dict(nut_position_m=0.299, nut_length_m=0.001),
    "1e-6 m nut": dict(nut_position_m=0.1, nut_length_m=1e-6),
    "182 turns at 1 deg, far end": dict(
        helix_angle_rad=math.radians(1.0),
        nut_position_m=0.2,
        nut_length_m=0.0999,
        n_bending=8,
        n_torsion=8,
    ),
    "547 turns at 1 deg, 2 m screw": dict(
        helix_angle_rad=math.radians(1.0),
        length_m=2.0,
        nut_position_m=1.5,
        nut_length_m=0.3,
        n_bending=20,
        n_torsion=20,
    ),
    "40 deg, far end": dict(
        helix_angle_rad=math.radians(40.0), nut_position_m=0.25, nut_length_m=0.05
    ),
    "40 deg, 40/40 modes, start": dict(
        helix_angle_rad=math.radians(40.0),
        nut_position_m=0.0,
        nut_length_m=0.12,
        n_bending=40,
        n_torsion=40,
    ),
    "resonance": dict(
        helix_angle_rad=math.atan(0.3 / (23 * math.pi * 0.005)), n_bending=20, n_torsion=12
    ),
}
TOLERANCE = 1e-12  # of the largest entry of the matrix


def _params(geometry: str, formulation: str) -> ScrewParameters:
    return ScrewParameters(formulation=formulation, **GEOMETRIES[geometry])


def _nodes_per_turn(p: ScrewParameters, basis) -> int:
    """Gauss-Legendre nodes per turn that resolve the fastest term, 2 + 2 R tan(beta) k_max
    rad per rad, to rounding (8-node panels spanning at most ~1.6 rad of its phase)."""
    return int(32 * math.ceil(2 + 2 * p.lead_per_rad_m * basis.wavenumber.max()))


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
@pytest.mark.parametrize("geometry", list(GEOMETRIES))
def test_closed_form_equals_fine_gauss_legendre(geometry, formulation):
    """Every entry of every matrix against the former quadrature at a node count that resolves
    the integrands to rounding."""
    p = _params(geometry, formulation)
    basis = modal_basis(p)
    unit = contact_integrals(p, basis).unit
    ref = quadrature_integrals(p, basis, _nodes_per_turn(p, basis))
    for name, r in ref.items():
        scale = np.abs(r).max()
        assert scale > 0
        err = np.abs(unit[name] - r).max() / scale
        assert err < TOLERANCE, (name, err)


def _adaptive(p: ScrewParameters, basis, name: str, i: int, j: int, epsabs: float) -> float:
    """scipy's adaptive quadrature of the raw integrand k_ab Phi_i Phi_j, turn by turn."""
    kernel = KERNELS[p.formulation]
    a, b = basis.kind[i], basis.kind[j]

    def integrand(t: float) -> float:
        k = kernel(np.array([t]), p.helix_angle_rad, p.radius_m)[name][a, b, 0]
        phi = basis.shapes(np.array([p.lead_per_rad_m * t]))[[i, j], 0]
        return k * phi[0] * phi[1]

    alpha_o, alpha = contact_angles(p)
    edges = alpha_o + alpha * np.linspace(0, 1, math.ceil(alpha / (2 * math.pi)) + 1)
    pieces = [
        quad(integrand, lo, hi, epsabs=epsabs / math.sqrt(len(edges) - 1), epsrel=0, limit=200)
        for lo, hi in zip(edges[:-1], edges[1:], strict=True)
    ]
    return math.fsum(v for v, _ in pieces)


ENTRIES = [  # geometry, formulation, matrix, mode labels (row, column)
    ("table 1", "paper", "W1", "B1x", "B2y"),
    ("table 1", "consistent", "W4", "B3y", "T2"),
    ("0.4 turn at the start", "paper", "W3", "B6x", "B6x"),
    ("182 turns at 1 deg, far end", "consistent", "W5qdot", "T8", "B7y"),
    ("40 deg, 40/40 modes, start", "paper", "W2", "B40x", "T40"),
    ("40 deg, 40/40 modes, start", "consistent", "W5q", "B39y", "B40x"),
    ("resonance", "paper", "W3", "B3x", "B20x"),  # omega = 0 for m = -1 and +1
    ("resonance", "consistent", "W1", "B11y", "B12x"),
]


@pytest.mark.parametrize("geometry, formulation, name, row, col", ENTRIES)
def test_entries_equal_adaptive_quadrature(geometry, formulation, name, row, col):
    p = _params(geometry, formulation)
    basis = modal_basis(p)
    unit = contact_integrals(p, basis).unit[name]
    scale = np.abs(unit).max()
    i, j = basis.labels.index(row), basis.labels.index(col)
    ref = _adaptive(p, basis, name, i, j, epsabs=TOLERANCE / 4 * scale)
    assert abs(unit[i, j] - ref) < TOLERANCE * scale, (unit[i, j], ref)


def test_resonance_takes_the_direct_sinc():
    """In the resonance case omega alpha / 2 is near 0 for m != 0: the direct sin(x) / x path
    (the split product loses digits there) is taken."""
    p = _params("resonance", "paper")
    helix = helix_contact(p, modal_basis(p))
    alpha = contact_angles(p)[1]
    assert np.searchsorted(helix.near_abs, 0.1 / (alpha / 2)) > 0
    assert helix.near_abs[0] < 1e-14


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
@pytest.mark.parametrize("beta", [1e-4, math.radians(1.0), 0.3, 1.2, math.pi / 2 - 1e-3])
def test_kernels_are_trigonometric_polynomials_of_degree_2(formulation, beta):
    """kernel_harmonics reproduces the kernels at arbitrary theta: they have no harmonic
    above 2, as the closed form assumes."""
    theta = np.random.default_rng(3).uniform(-20.0, 20.0, 101)
    c = kernel_harmonics(formulation, beta, 0.007)
    rebuilt = np.einsum("wabm,mt->wabt", c, np.exp(1j * np.outer(HARMONICS, theta)))
    k = KERNELS[formulation](theta, beta, 0.007)
    ref = np.stack([k[name] for name in MATRICES])
    assert np.abs(rebuilt.imag).max() < 1e-15
    np.testing.assert_allclose(rebuilt.real, ref, rtol=0, atol=1e-14 * np.abs(ref).max())


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
def test_state_matrix_parts_are_the_contact_integrals(formulation):
    """The assembled lower half [K | D] units are the sums of the unit matrices that share a
    scale factor (W1 + W2, W5q, W3 + W4, W5qdot, G)."""
    g = SqueakModel(ScrewParameters(formulation=formulation, n_bending=5, n_torsion=7)).geometry
    u, zero = g.contact.unit, np.zeros((g.n, g.n))
    expected = np.stack(
        [
            np.hstack(pair).ravel()
            for pair in (
                (u["W1"] + u["W2"], zero),
                (u["W5q"], zero),
                (zero, u["W3"] + u["W4"]),
                (zero, u["W5qdot"]),
                (zero, g.G_unit),
            )
        ]
    )
    np.testing.assert_allclose(
        g.lower_half_units, expected, rtol=1e-14, atol=1e-14 * np.abs(expected).max()
    )


def test_geometry_is_computed_once_and_reused():
    # A screw no other test uses: the geometry cache (per nut position) outlives the smaller
    # screw cache, so a Table 1 geometry cached by an earlier test can hold the modes of a
    # screw entry evicted since (equal, not the same object).
    m = SqueakModel(ScrewParameters(length_m=0.3 * (1 + 1e-12)))
    same = m.with_params(mu_static=0.3, modal_damping=0.01, axial_load_n=50.0)
    assert same.geometry.contact is m.geometry.contact  # no re-integration
    moved = m.with_params(nut_position_m=0.1)
    assert moved.geometry.contact is not m.geometry.contact
    again = m.with_params(nut_position_m=0.1 + 1e-9)  # the modes and kernels are per screw
    assert again.geometry.basis is moved.geometry.basis
    assert again.geometry.contact.helix is moved.geometry.contact.helix
    assert not np.allclose(moved.geometry.contact.unit["W3"], m.geometry.contact.unit["W3"])


def test_operating_point_only_rescales_matrices():
    """W1, W2 ~ mu_o F; W3, W4 ~ mu_o F / Omega; W5q ~ F gamma Omega; W5qdot ~ F gamma; G ~
    Omega."""
    m = SqueakModel()
    p = m.params
    a, b = m.geometry.matrices(10.0, 100.0), m.geometry.matrices(30.0, 250.0)
    mu_ratio = mu_o(p, 30.0) / mu_o(p, 10.0)
    g_ratio = gamma(p, 30.0) / gamma(p, 10.0)
    expected = {
        "W1": mu_ratio * 2.5,
        "W2": mu_ratio * 2.5,
        "W3": mu_ratio * 2.5 / 3,
        "W4": mu_ratio * 2.5 / 3,
        "W5q": g_ratio * 2.5 * 3,
        "W5qdot": g_ratio * 2.5,
    }
    for name, ratio in expected.items():
        np.testing.assert_allclose(b.W[name], ratio * a.W[name], rtol=1e-12, atol=0)
    np.testing.assert_allclose(b.G, 3 * a.G)
    np.testing.assert_allclose(b.C, a.C)


def test_state_matrix_is_eq_27_in_first_order_form():
    m = SqueakModel()
    s = m.geometry.matrices(20.0, 200.0)
    om = m.geometry.basis.omega_rad_s
    K = np.diag(om**2 - 20.0**2) + s.W["W1"] + s.W["W2"] + s.W["W5q"]
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
    p = ScrewParameters(
        radius_m=0.006, helix_angle_rad=0.1, nut_position_m=0.05, nut_length_m=0.04, length_m=0.25
    )
    assert p.lead_per_rad_m == pytest.approx(0.006 * math.tan(0.1), rel=1e-15)
    assert p.nut_travel_m == pytest.approx(0.21, rel=1e-15)
    alpha_o, alpha = contact_angles(p)
    assert alpha_o * p.lead_per_rad_m == pytest.approx(0.05, rel=1e-14)
    assert alpha * p.lead_per_rad_m == pytest.approx(0.04, rel=1e-14)
