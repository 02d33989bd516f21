# SPDX-License-Identifier: Apache-2.0
"""The paper's claims (the trends it reports), each its own test of the `paper` formulation at
Table 1."""

import numpy as np
import pytest

from leadscrew_ros.model import SqueakModel
from leadscrew_ros.model.studies.stability_map import stability_map
from leadscrew_ros.model.studies.sweep import sweep

SPEEDS = np.linspace(0.5, 150, 150)


@pytest.fixture(scope="module")
def model():
    return SqueakModel()


def _band(model, **changes):
    m = model.with_params(**changes) if changes else model
    bands = sweep(m, "speed_rad_s", SPEEDS).unstable_bands
    assert len(bands) <= 1, bands
    return bands[0] if bands else None


def test_squeak_only_in_a_band_of_moderate_speeds(model):
    lo, hi = _band(model)
    assert 0.5 < lo < 5.0 and 20.0 < hi < 150.0
    assert model.predict(0.6).stable  # radial-slip dissipation near 0
    assert not model.predict(20.0).stable
    for speed in (hi * 1.2, 300.0, 1000.0):  # and stable at high speed
        assert model.predict(speed).stable
    # Near zero speed all real parts drop (Fig. 5).
    assert model.predict(0.6).max_growth_rate < model.predict(lo * 1.5).max_growth_rate


def test_squeak_modes_are_first_and_second_bending(model):
    p = model.predict(20.0)
    assert [m.label[:2] for m in p.squeak_modes] == ["B1", "B2"]
    np.testing.assert_allclose(p.unstable_frequencies_hz, [224, 898], rtol=0.01)
    # Across the band the most unstable mode is always the first bending mode (Fig. 11).
    lo, hi = _band(model)
    for speed in np.linspace(lo * 1.05, hi * 0.95, 12):
        assert model.predict(speed).squeak_modes[0].label.startswith("B1")


def test_larger_radius_stabilises_and_lowers_the_upper_speed_bound(model):
    uppers = [_band(model, radius_m=r)[1] for r in (0.003, 0.004, 0.005, 0.007, 0.010)]
    assert all(a > b for a, b in zip(uppers, uppers[1:], strict=False)), uppers
    assert uppers[0] > 2 * uppers[-1]
    growth = [
        model.with_params(radius_m=r).predict(20.0).max_growth_rate for r in (0.004, 0.006, 0.008)
    ]
    assert growth[0] > growth[1] > growth[2]


def test_lower_load_bound_and_load_destabilises_most_at_low_speed(model):
    assert model.predict(20.0, 5.0).stable  # below the lower load bound
    assert not model.predict(20.0, 200.0).stable
    bound = sweep(model, "load_n", np.linspace(1.0, 400.0, 40), speed_rad_s=20.0).boundaries
    assert len(bound) == 1 and 5.0 < bound[0] < 100.0
    widths = [np.diff(_band(model.with_params(axial_load_n=f)))[0] for f in (50.0, 200.0, 600.0)]
    assert widths[0] < widths[1] < widths[2]
    # More load raises the growth rate more at low speed than at high speed (Fig. 7).
    gain = {
        w: model.predict(w, 400.0).max_growth_rate - model.predict(w, 100.0).max_growth_rate
        for w in (5.0, 40.0)
    }
    assert gain[5.0] > gain[40.0] > 0


def test_squeak_propensity_largest_with_nut_near_centre(model):
    L, b = model.params.length_m, model.params.nut_length_m
    z = np.linspace(0.0, L - b, 13)
    growth = np.array(
        [model.with_params(nut_position_m=v).predict(20.0).max_growth_rate for v in z]
    )
    centre = (L - b) / 2
    assert abs(z[np.argmax(growth)] - centre) <= 0.05 * L
    uppers = np.array([_band(model, nut_position_m=v)[1] for v in z])
    assert abs(z[np.argmax(uppers)] - centre) <= 0.05 * L
    assert growth.max() > 2 * min(growth[0], growth[-1])


def test_fig9_map_load_vs_radius_at_20_rad_s(model):
    m = stability_map(
        model,
        "radius_m",
        np.linspace(0.003, 0.010, 8),
        "load_n",
        np.linspace(5.0, 600.0, 25),
        speed_rad_s=20.0,
    )
    unstable = m.field.max_growth_rate > 0
    # Smaller radius and larger load destabilise: the lowest unstable load rises with R.
    lowest = [m.y[np.argmax(col)] if col.any() else np.inf for col in unstable.T]
    assert all(a <= b for a, b in zip(lowest, lowest[1:], strict=False)) and lowest[0] < lowest[-1]
    assert len(m.boundary) > 0
    for x, y in m.boundary[:5]:
        g = model.with_params(radius_m=x).predict(20.0, y).max_growth_rate
        assert abs(g) < 1e-3


def test_fig10_map_load_vs_location_at_20_rad_s(model):
    L, b = model.params.length_m, model.params.nut_length_m
    m = stability_map(
        model,
        "nut_position_m",
        np.linspace(0.0, L - b, 9),
        "load_n",
        np.linspace(2.0, 200.0, 34),
        speed_rad_s=20.0,
    )
    unstable = m.field.max_growth_rate > 0
    lowest = np.array([m.y[np.argmax(col)] if col.any() else np.inf for col in unstable.T])
    assert np.argmin(lowest) in (3, 4, 5)  # easiest to squeak near centre
    assert lowest[4] < lowest[0] and lowest[4] < lowest[-1]
