# SPDX-License-Identifier: Apache-2.0
"""Eigenvalue sensitivities of the least-stable mode against finite differences."""

import numpy as np
import pytest

from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.studies.sensitivity import FRICTION, GEOMETRY, sensitivities

NAMES = (*FRICTION, "modal_damping", "speed_rad_s", "load_n", *GEOMETRY)
MODELS = {f: SqueakModel(ScrewParameters(formulation=f)) for f in ("paper", "consistent")}
# In the band, near its upper edge, reverse rotation, the other flank (load sign), both readings.
CASES = [
    ("paper", 40.0, 200.0),
    ("paper", 54.0, 200.0),
    ("paper", -30.0, 200.0),
    ("paper", 30.0, -150.0),
    ("consistent", 45.0, 200.0),
    ("consistent", 49.0, 200.0),
    ("consistent", -45.0, 200.0),
    ("consistent", 40.0, -200.0),
]
STEP = 1e-4


def _growth(model, speed, load, near):
    lam = np.linalg.eigvals(model.state_matrix(speed, load))
    return lam[np.argmin(abs(lam - near))].real


def _finite_difference(model, speed, load, name, near):
    """d Re(lambda) / d ln p by a fourth-order central difference, the mode followed by
    nearest eigenvalue."""

    def at(k):
        x = 1 + k * STEP
        if name == "speed_rad_s":
            return _growth(model, speed * x, load, near)
        if name == "load_n":
            return _growth(model, speed, load * x, near)
        value = getattr(model.params, name)
        return _growth(model.with_params(**{name: value * x}), speed, load, near)

    return (8 * (at(1) - at(-1)) - (at(2) - at(-2))) / (12 * STEP)


@pytest.mark.parametrize("formulation, speed, load", CASES)
def test_growth_rate_derivatives_match_finite_differences(formulation, speed, load):
    model = MODELS[formulation]
    s = sensitivities(model, speed, load)
    assert set(s.growth_per_log) == set(NAMES)
    for name in NAMES:
        fd = _finite_difference(model, speed, load, name, s.eigenvalue)
        assert s.growth_per_log[name] == pytest.approx(fd, rel=1e-5), name


def test_the_mode_is_the_least_stable_oscillatory_one():
    model = MODELS["paper"]
    p = model.predict(40.0, 200.0)
    s = sensitivities(model, 40.0, 200.0, geometry=False)
    assert s.eigenvalue.real == pytest.approx(p.modes[0].growth_rate, rel=1e-12)
    assert s.eigenvalue.imag / (2 * np.pi) == pytest.approx(p.modes[0].frequency_hz, rel=1e-12)
    assert not set(GEOMETRY) & set(s.growth_per_log)


def test_friction_difference_drives_squeak_and_damping_stabilises():
    """The falling friction law (mu_s - mu_k) feeds the squeak mode; damping takes it away."""
    for f, speed in (("paper", 40.0), ("consistent", 45.0)):
        g = sensitivities(MODELS[f], speed, 200.0, geometry=False).growth_per_log
        assert g["mu_static"] > 0 > g["mu_kinetic"] and g["modal_damping"] < 0


def test_outside_validity_there_are_no_sensitivities():
    assert sensitivities(MODELS["paper"], 0.1, 200.0) is None
