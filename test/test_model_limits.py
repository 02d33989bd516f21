# SPDX-License-Identifier: Apache-2.0
"""Limits with known answers and convergence in the number of modes."""

import numpy as np
import pytest

from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.studies.sweep import sweep

SPEEDS = np.linspace(0.5, 120, 60)


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
@pytest.mark.parametrize("speed", [3.0, 200.0, -150.0])
def test_frictionless_undamped_screw_has_gyroscopic_split(formulation, speed):
    m = SqueakModel(
        ScrewParameters(mu_static=0.0, mu_kinetic=0.0, modal_damping=0.0, formulation=formulation)
    )
    lam = np.linalg.eigvals(m.state_matrix(speed, 200.0))
    assert np.abs(lam.real).max() < 1e-6 * np.abs(lam).max()  # purely imaginary
    om = m.geometry.basis.omega_rad_s
    bend, tors = om[:12:2], om[12:]
    expected = np.sort(
        np.concatenate([bend + abs(speed), bend - abs(speed), np.sqrt(tors**2 - speed**2)])
    )
    np.testing.assert_allclose(np.sort(lam.imag[lam.imag > 0]), expected, rtol=1e-9)
    p = m.predict(speed, 200.0)
    assert p.valid and p.stable and not p.squeak_modes


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
def test_damped_frictionless_screw_decays_at_xi_omega_at_rest(formulation):
    p = ScrewParameters(
        mu_static=0.0, mu_kinetic=0.0, min_speed_rad_s=1e-6, formulation=formulation
    )
    m = SqueakModel(p)
    pred = m.predict(1e-4, 200.0)
    assert all(mode.growth_rate < 0 for mode in pred.modes)
    om = np.sort(m.geometry.basis.omega_rad_s)
    lam = np.linalg.eigvals(m.state_matrix(1e-4, 200.0))
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    np.testing.assert_allclose(-lam.real, p.modal_damping * om, rtol=1e-4)
    np.testing.assert_allclose(np.abs(lam), om, rtol=1e-6)
    assert pred.margin == pytest.approx(p.modal_damping, rel=1e-3)
    assert pred.probability == 0.0  # damping scatter alone never makes it squeak


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
def test_converged_in_number_of_modes(formulation):
    """N = 18 (6 + 6 + 6) against N = 24 (8 + 8 + 8): same boundaries and squeak modes."""
    base = SqueakModel(ScrewParameters(formulation=formulation))
    fine = base.with_params(n_bending=8, n_torsion=8)
    a, b = sweep(base, "speed_rad_s", SPEEDS), sweep(fine, "speed_rad_s", SPEEDS)
    assert len(a.boundaries) == len(b.boundaries) >= 1
    np.testing.assert_allclose(a.boundaries, b.boundaries, rtol=1e-4)
    pa, pb = base.predict(20.0), fine.predict(20.0)
    assert [m.label for m in pa.squeak_modes] == [m.label for m in pb.squeak_modes]
    np.testing.assert_allclose(
        [m.growth_rate for m in pa.squeak_modes],
        [m.growth_rate for m in pb.squeak_modes],
        rtol=1e-3,
    )
