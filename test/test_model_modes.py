# SPDX-License-Identifier: Apache-2.0
"""Modal basis: Table 2 of the paper, mass normalisation, labels, gyroscopic coupling (A.2)."""

import numpy as np
import pytest
from scipy.integrate import quad

from leadscrew_ros.model import ScrewParameters, modal_basis
from leadscrew_ros.model.physics.assembly import gyroscopic_unit
from leadscrew_ros.model.physics.modes import KIND_T

# Table 2: the uncoupled screw (Hz) and the mode(s) at each frequency.
TABLE_2 = [
    (224, ("B1x", "B1y")),
    (898, ("B2x", "B2y")),
    (2020, ("B3x", "B3y")),
    (2654, ("T1",)),
    (3592, ("B4x", "B4y")),
    (5612, ("B5x", "B5y")),
    (7961, ("T2",)),
    (8082, ("B6x", "B6y")),
]


@pytest.fixture(scope="module")
def basis():
    return modal_basis(ScrewParameters())


@pytest.mark.parametrize("f_table, labels", TABLE_2)
def test_table_2_frequencies_within_half_percent(basis, f_table, labels):
    for label in labels:
        f = basis.frequency_hz[basis.labels.index(label)]
        assert f == pytest.approx(f_table, rel=0.005), label


def test_labels_and_ordering(basis):
    assert basis.labels[:4] == ("B1x", "B1y", "B2x", "B2y")
    assert basis.labels[12:] == ("T1", "T2", "T3", "T4", "T5", "T6")
    assert basis.n == 18 == ScrewParameters().n_modes


def test_shapes_are_mass_normalised(basis):
    """rho A int Phi_i Phi_j dz = delta_ij for bending, rho J int ... for torsion (reading 1)."""
    p = ScrewParameters()
    area, polar = np.pi * p.radius_m**2, np.pi * p.radius_m**4 / 2
    for i in (0, 3, 11, 12, 17):
        mass = p.density_kg_m3 * (polar if basis.kind[i] == KIND_T else area)
        for j in (i, i + 2 if i + 2 < 18 and basis.kind[i + 2] == basis.kind[i] else i):
            val = quad(
                lambda z, i=i, j=j: (
                    basis.shapes(np.array([z]))[i, 0] * basis.shapes(np.array([z]))[j, 0]
                ),
                0,
                p.length_m,
                limit=200,
            )[0]
            assert mass * val == pytest.approx(1.0 if i == j else 0.0, abs=1e-9)


def test_hinged_and_clamped_free_boundary_conditions(basis):
    p = ScrewParameters()
    ends = basis.shapes(np.array([0.0, p.length_m]))
    assert np.allclose(ends[basis.kind != KIND_T], 0.0, atol=1e-9)  # hinged-hinged
    assert np.allclose(ends[basis.kind == KIND_T, 0], 0.0, atol=1e-9)  # clamped at z = 0
    free = basis.amplitude[basis.kind == KIND_T]
    assert np.allclose(np.abs(ends[basis.kind == KIND_T, 1]), free)  # free end: extremum


def test_gyroscopic_matrix_couples_each_bending_pair_by_two(basis):
    g = gyroscopic_unit(basis)
    assert np.allclose(g, -g.T)
    i, j = basis.labels.index("B3x"), basis.labels.index("B3y")
    assert g[i, j] == -2.0 and g[j, i] == 2.0  # (A.2), x row: -2 Omega
    assert np.count_nonzero(g) == 2 * 6
