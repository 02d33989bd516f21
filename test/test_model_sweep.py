# SPDX-License-Identifier: Apache-2.0
"""Sweeps and maps: batched results equal single predictions; boundaries are refined roots."""

import numpy as np
import pytest

from leadscrew_ros.model import ParameterError, SqueakModel
from leadscrew_ros.model.studies import fields, stability_map as map_module
from leadscrew_ros.model.studies.fields import growth_field
from leadscrew_ros.model.studies.roots import find_roots
from leadscrew_ros.model.studies.stability_map import stability_map
from leadscrew_ros.model.studies.sweep import sweep


@pytest.fixture(scope="module")
def model():
    return SqueakModel()


def test_batched_growth_equals_single_predictions(model):
    speeds = np.array([0.2, 1.0, 7.0, 20.0, 60.0, 400.0, 2000.0])
    loads = np.array([[10.0], [200.0], [-300.0]])
    gf = growth_field(model, speeds[None, :], loads)
    for j, f in enumerate(loads[:, 0]):
        for i, w in enumerate(speeds):
            p = model.predict(w, f)
            assert gf.valid[j, i] == p.valid
            if p.valid:
                assert gf.max_growth_rate[j, i] == pytest.approx(p.max_growth_rate, rel=1e-9,
                                                                 abs=1e-9)
                assert gf.peak_frequency_hz[j, i] == pytest.approx(p.modes[0].frequency_hz,
                                                                   rel=1e-9)
            else:
                assert np.isnan(gf.max_growth_rate[j, i])


def test_predict_many_equals_predict(model):
    many = model.predict_many([0.1, 5.0, 20.0, -30.0], [200.0, 100.0, 200.0, 50.0])
    for p in many:
        q = model.predict(p.speed_rad_s, p.load_n)
        assert p.valid == q.valid and p.reason == q.reason
        assert [m.label for m in p.modes] == [m.label for m in q.modes]
        np.testing.assert_allclose([m.growth_rate for m in p.modes],
                                   [m.growth_rate for m in q.modes], rtol=1e-9, atol=1e-9)


def test_speed_sweep_bands_are_refined_to_the_root(model):
    r = sweep(model, "speed_rad_s", np.linspace(0.5, 120, 25))
    assert len(r.unstable_bands) == 1
    lo, hi = r.unstable_bands[0]
    grid_step = (120 - 0.5) / 24
    for edge in (lo, hi):
        assert abs(model.predict(edge).max_growth_rate) < 1e-6           # a root, not a cell
        assert model.predict(edge - 1e-3).stable != model.predict(edge + 1e-3).stable
    fine = sweep(model, "speed_rad_s", np.linspace(0.5, 120, 200)).unstable_bands[0]
    np.testing.assert_allclose(fine, (lo, hi), rtol=1e-7)
    assert grid_step > 1.0                                                 # coarse grid, exact edge
    d = r.as_dict()
    assert d["unstable_bands_rad_s"] == [[lo, hi]] and len(d["max_growth_rate"]) == 25


def test_sweep_over_a_geometry_parameter_and_invalid_values(model):
    r = sweep(model, "nut_position_m", np.linspace(0.0, 0.3, 7), speed_rad_s=20.0)
    valid = [p.valid for p in r.predictions]
    assert valid == [True] * 5 + [False] * 2                              # z_o + b > L
    assert "z_o + b <= L" in r.predictions[-1].reason
    with pytest.raises(ParameterError, match="cannot sweep"):
        sweep(model, "formulation", [0, 1])


def test_map_boundary_points_are_roots_and_grid_matches(model):
    m = stability_map(model, "speed_rad_s", np.linspace(1.0, 80.0, 12), "load_n",
                      np.linspace(5.0, 400.0, 10))
    assert m.field.max_growth_rate.shape == (10, 12)
    assert m.field.max_growth_rate[5, 4] == pytest.approx(
        model.predict(m.x[4], m.y[5]).max_growth_rate, rel=1e-9)
    assert len(m.boundary) >= 10
    for x, y in m.boundary:
        assert abs(model.predict(x, y).max_growth_rate) < 1e-5
    d = m.as_dict()
    assert len(d["max_growth_rate"]) == 10 and len(d["boundary"]) == len(m.boundary)


def test_probability_and_margin_track_the_band(model):
    """Deep in the band P is 1, far outside 0, near the upper edge in between; the margin
    (least damping ratio) is negative exactly where a mode squeaks."""
    inside, near, outside = model.predict(20.0), model.predict(55.0), model.predict(100.0)
    assert inside.probability > 0.99 and outside.probability == 0.0
    assert 0.1 < near.probability < 0.9
    assert inside.margin < 0 < outside.margin
    assert near.margin == min(m.damping_ratio for m in near.modes)


def test_divergence_is_reported_separately_from_squeak(model):
    """Small radius, paper formulation: a real eigenvalue > 0 (divergence) exists."""
    small = model.with_params(radius_m=0.0027)
    p = small.predict(20.0, 400.0)
    assert p.divergence_rates and all(r > 0 for r in p.divergence_rates)
    assert p.stable is False
    gf = growth_field(small, np.array([20.0]), np.array([400.0, 50.0]))
    assert gf.divergence_rate[0] == pytest.approx(p.divergence_rates[0], rel=1e-9)
    q = small.predict(20.0, 50.0)
    assert gf.divergence_rate[1] == pytest.approx(max(q.divergence_rates, default=0.0), rel=1e-9)


def test_find_roots_solves_all_brackets_together():
    """Different functions per bracket, one batched call per iteration: smooth roots to the
    tolerance and far below it, a root at an end, and NaN inside a bracket (no crash, an end)."""
    c = np.array([2.0, 3.0, 10.0, 0.125, 7.0])
    calls = []

    def f(x, cells):
        calls.append(cells.size)
        y = x ** 3 - c[cells]
        return np.where(cells == 4, np.nan, y)

    lo, hi = np.array([0.0, 1.0, 2.0, 0.5, 0.0]), np.array([2.0, 2.0, 3.0, 1.0, 2.0])
    roots = find_roots(f, lo, hi, lo ** 3 - c, hi ** 3 - c, np.full(5, 1e-9))
    np.testing.assert_allclose(roots[:4], np.cbrt(c[:4]), rtol=1e-12)
    assert roots[3] == lo[3]                                         # f = 0 at an end
    assert roots[4] in (0.0, 2.0)                                    # undefined inside
    assert len(calls) <= 12 and calls[0] == 4                        # batched over brackets


def test_map_boundary_is_refined_in_a_few_batched_calls(model, monkeypatch):
    """The whole boundary (rows and columns) costs a few growth_field calls, not one per
    root, and its points are as exact as a scalar root finder's."""
    calls = []
    real = map_module.growth_field

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    for module in (fields, map_module):                 # the grid, then the root finding
        monkeypatch.setattr(module, "growth_field", counting)
    m = stability_map(model, "speed_rad_s", np.linspace(1.0, 100.0, 30), "load_n",
                      np.linspace(10.0, 600.0, 30))
    assert len(m.boundary) > 40 and len(calls) <= 10
    x, y = np.array(m.boundary).T
    assert np.abs(real(model, x, y).max_growth_rate).max() < 1e-8


@pytest.mark.parametrize("field", [fields.growth_field, fields.probability_field])
@pytest.mark.parametrize("bad", [dict(speed_rad_s=[20.0, np.nan]), dict(load_n=[200.0, np.inf]),
                                 dict(radius_m=[0.005, np.nan])])
def test_fields_refuse_non_finite_values_with_one_error(model, field, bad):
    """Both fields take their points through one broadcast with one finiteness check."""
    args = {"speed_rad_s": 20.0, "load_n": 200.0, **bad}
    with pytest.raises(ParameterError, match="finite"):
        field(model, args.pop("speed_rad_s"), args.pop("load_n"), **args)
