# SPDX-License-Identifier: Apache-2.0
"""Sweeps and maps: batched results equal single predictions; boundaries are refined roots."""

import numpy as np
import pytest

from leadscrew_ros.model import ParameterError, SqueakModel
from leadscrew_ros.model.studies import fields
from leadscrew_ros.model.studies import stability_map as map_module
from leadscrew_ros.model.studies.fields import growth_field, probability_field
from leadscrew_ros.model.studies.roots import ROOT_RTOL, find_roots, refine_level_crossings
from leadscrew_ros.model.studies.stability_map import stability_map
from leadscrew_ros.model.studies.sweep import sweep
from leadscrew_ros.model.uncertainty.scatter import Scatter


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
                assert gf.max_growth_rate[j, i] == pytest.approx(
                    p.max_growth_rate, rel=1e-9, abs=1e-9
                )
                assert gf.peak_frequency_hz[j, i] == pytest.approx(
                    p.modes[0].frequency_hz, rel=1e-9
                )
            else:
                assert np.isnan(gf.max_growth_rate[j, i])


def test_predict_many_equals_predict(model):
    many = model.predict_many([0.1, 5.0, 20.0, -30.0], [200.0, 100.0, 200.0, 50.0])
    for p in many:
        q = model.predict(p.speed_rad_s, p.load_n)
        assert p.valid == q.valid and p.reason == q.reason
        assert [m.label for m in p.modes] == [m.label for m in q.modes]
        np.testing.assert_allclose(
            [m.growth_rate for m in p.modes], [m.growth_rate for m in q.modes], rtol=1e-9, atol=1e-9
        )


def test_speed_sweep_bands_are_refined_to_the_root(model):
    r = sweep(model, "speed_rad_s", np.linspace(0.5, 120, 25))
    assert len(r.unstable_bands) == 1
    lo, hi = r.unstable_bands[0]
    grid_step = (120 - 0.5) / 24
    for edge in (lo, hi):
        assert abs(model.predict(edge).max_growth_rate) < 1e-6  # a root, not a cell
        assert model.predict(edge - 1e-3).stable != model.predict(edge + 1e-3).stable
    fine = sweep(model, "speed_rad_s", np.linspace(0.5, 120, 200)).unstable_bands[0]
    np.testing.assert_allclose(fine, (lo, hi), rtol=1e-7)
    assert grid_step > 1.0  # coarse grid, exact edge
    d = r.as_dict()
    assert d["unstable_bands_rad_s"] == [[lo, hi]] and len(d["max_growth_rate"]) == 25


def test_sweep_over_a_geometry_parameter_and_invalid_values(model):
    r = sweep(model, "nut_position_m", np.linspace(0.0, 0.3, 7), speed_rad_s=20.0)
    valid = [p.valid for p in r.predictions]
    assert valid == [True] * 5 + [False] * 2  # z_o + b > L
    assert "z_o + b <= L" in r.predictions[-1].reason
    with pytest.raises(ParameterError, match="cannot sweep"):
        sweep(model, "formulation", [0, 1])


def test_map_boundary_points_are_roots_and_grid_matches(model):
    m = stability_map(
        model, "speed_rad_s", np.linspace(1.0, 80.0, 12), "load_n", np.linspace(5.0, 400.0, 10)
    )
    assert m.field.max_growth_rate.shape == (10, 12)
    assert m.field.max_growth_rate[5, 4] == pytest.approx(
        model.predict(m.x[4], m.y[5]).max_growth_rate, rel=1e-9
    )
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
        y = x**3 - c[cells]
        return np.where(cells == 4, np.nan, y)

    lo, hi = np.array([0.0, 1.0, 2.0, 0.5, 0.0]), np.array([2.0, 2.0, 3.0, 1.0, 2.0])
    roots = find_roots(f, lo, hi, lo**3 - c, hi**3 - c, np.full(5, 1e-9))
    np.testing.assert_allclose(roots[:4], np.cbrt(c[:4]), rtol=1e-12)
    assert roots[3] == lo[3]  # f = 0 at an end
    assert roots[4] in (0.0, 2.0)  # undefined inside
    assert len(calls) <= 12 and calls[0] == 4  # batched over brackets


def test_map_boundary_is_refined_in_a_few_batched_calls(model, monkeypatch):
    """The whole boundary (rows and columns) costs a few growth_field calls, not one per
    root, and its points are as exact as a scalar root finder's."""
    calls = []
    real = map_module.growth_field

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    for module in (fields, map_module):  # the grid, then the root finding
        monkeypatch.setattr(module, "growth_field", counting)
    m = stability_map(
        model, "speed_rad_s", np.linspace(1.0, 100.0, 30), "load_n", np.linspace(10.0, 600.0, 30)
    )
    assert len(m.boundary) > 40 and len(calls) <= 10
    x, y = np.array(m.boundary).T
    assert np.abs(real(model, x, y).max_growth_rate).max() < 1e-8


@pytest.mark.parametrize("field", [fields.growth_field, fields.probability_field])
@pytest.mark.parametrize(
    "bad",
    [
        dict(speed_rad_s=[20.0, np.nan]),
        dict(load_n=[200.0, np.inf]),
        dict(radius_m=[0.005, np.nan]),
    ],
)
def test_fields_refuse_non_finite_values_with_one_error(model, field, bad):
    """Both fields take their points through one broadcast with one finiteness check."""
    args = {"speed_rad_s": 20.0, "load_n": 200.0, **bad}
    with pytest.raises(ParameterError, match="finite"):
        field(model, args.pop("speed_rad_s"), args.pop("load_n"), **args)


# ------------------------------------------------------- what a sweep reads off its grid, refined
TABLE1_SPEEDS = np.linspace(0.5, 200.0, 100)  # 2 rad/s apart: coarse next to the band


@pytest.fixture(scope="module")
def table1_sweep(model):
    return sweep(model, "speed_rad_s", TABLE1_SPEEDS)


def test_probability_crossings_without_scatter_are_the_stability_boundaries(model):
    """P is the 0/1 verdict: every level is reached where the growth rate changes sign."""
    r = sweep(model.with_scatter(Scatter({})), "speed_rad_s", TABLE1_SPEEDS)
    np.testing.assert_allclose(r.boundaries, [0.809, 55.207], atol=1e-3)  # Table 1, 200 N
    tol = ROOT_RTOL * np.ptp(TABLE1_SPEEDS)  # 2e-7 rad/s
    for level, found in r.probability_crossings.items():
        np.testing.assert_allclose(found, r.boundaries, rtol=0, atol=tol, err_msg=str(level))


def test_probability_crossings_agree_with_a_fine_grid(model, table1_sweep):
    """Over the default scatter the lower crossings, 2 rad/s grid, equal those of a grid
    1e-3 rad/s apart to that spacing (the grid's interpolation gave 0.653, 1.497, 2.341)."""
    fine = np.linspace(0.5, 2.5, 2001)
    prob = probability_field(model, fine, 200.0)[0]
    for level in (0.1, 0.5, 0.9):
        k = np.flatnonzero((prob[:-1] >= level) != (prob[1:] >= level))
        assert len(k) == 1, level  # P rises once
        lower = table1_sweep.probability_crossings[level][0]
        assert fine[k[0]] <= lower <= fine[k[0] + 1], (level, lower)
    np.testing.assert_allclose(
        [table1_sweep.probability_crossings[v][0] for v in (0.1, 0.5, 0.9)],
        [0.579, 0.812, 1.397],
        atol=1e-3,
    )


def test_refine_level_crossings_finds_the_switch_of_a_step_function():
    """A staircase: the crossing is where f >= level switches, to the tolerance, even where the
    level equals a step's value; several levels in one batch of calls."""
    calls = []

    def staircase(x):
        calls.append(x.size)
        return np.floor(4 * x) / 4  # steps of 0.25

    x = np.array([0.0, 0.6, 1.0])
    values = np.floor(4 * x) / 4  # 0, 0.5, 1
    found = refine_level_crossings(staircase, x, values, [0.25, 0.5, 0.9, 1.5], rtol=1e-10)
    assert found[0.25] == pytest.approx([0.25], abs=1e-10)  # f = level from 0.25
    assert found[0.5] == pytest.approx([0.5], abs=1e-10)  # on the grid point
    assert found[0.9] == pytest.approx([1.0], abs=1e-10)  # at the grid end
    assert found[1.5] == []
    assert calls[0] == 3 and len(calls) <= 40  # levels batched


def test_peak_growth_is_refined_between_grid_points(model, table1_sweep):
    """The largest growth rate is not left at the best grid point (144.5 at 4.530 rad/s)."""
    fine = np.linspace(2.5, 6.5, 40001)  # 1e-4 rad/s apart
    g = growth_field(model, fine, 200.0).max_growth_rate
    i = int(np.argmax(g))
    assert table1_sweep.peak_value == pytest.approx(fine[i], abs=2e-4)  # 4.357 rad/s
    assert g[i] - 1e-9 <= table1_sweep.peak_growth_rate <= g[i] + 1e-6  # 144.54 1/s
    assert table1_sweep.peak_growth_rate > np.nanmax(table1_sweep.max_growth_rate) + 0.01
    d = table1_sweep.as_dict()
    assert d["peak_speed_rad_s"] == table1_sweep.peak_value
    assert d["peak_growth_rate"] == table1_sweep.peak_growth_rate
    none = sweep(model, "speed_rad_s", [0.01, 0.02])  # below min speed
    assert np.isnan(none.peak_value) and none.as_dict()["peak_growth_rate"] is None
