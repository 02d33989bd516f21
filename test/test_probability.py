# SPDX-License-Identifier: Apache-2.0
"""Squeak probability over the parameter scatter: samples, the Monte Carlo reference."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadscrew_ros.model import ParameterError, ScrewParameters, SqueakModel
from leadscrew_ros.model.studies.probability import linearised, monte_carlo, squeaks
from leadscrew_ros.model.uncertainty.scatter import (
    DEFAULT_SCATTER,
    Scatter,
    draw,
    scatterable,
    valid_mask,
)

MODEL = SqueakModel()
CONSISTENT = SqueakModel(ScrewParameters(formulation="consistent"))


def test_default_scatter_is_the_documented_assumption():
    assert dict(Scatter().sd) == {
        "friction_decay_s_m": 0.10,
        "modal_damping": 0.35,
        "mu_kinetic": 0.05,
        "mu_static": 0.05,
    }
    assert set(DEFAULT_SCATTER) <= set(scatterable())


@pytest.mark.parametrize(
    "sd, message",
    [
        ({"mu_static": -0.1}, "scatter.mu_static = -0.1 must be a number in [0, 1]"),
        ({"mu_static": math.nan}, "scatter.mu_static = nan"),
        ({"mu_static": True}, "scatter.mu_static = True"),
        ({"axial_load_n": 0.1}, "scatter.axial_load_n: not a scatterable parameter"),
        ({"nonsense": 0.1}, "scatter.nonsense: not a scatterable parameter"),
    ],
)
def test_bad_scatter_is_one_clear_error(sd, message):
    with pytest.raises(
        ParameterError,
        match="^" + message.replace("[", r"\[").replace("]", r"\]").replace(".", r"\."),
    ):
        Scatter(sd)


@pytest.mark.parametrize("count, replicates", [(1000, 8), (4096, 1), (0, 8), (4096.0, 8)])
def test_bad_work_size_is_one_clear_error(count, replicates):
    with pytest.raises(ParameterError):
        draw(MODEL.params, Scatter(), count, replicates)


def test_samples_stay_in_the_valid_domain():
    """A wide scatter of mu_k crosses mu_s often: those samples are redrawn."""
    s = draw(MODEL.params, Scatter({"mu_static": 0.3, "mu_kinetic": 0.3}), 2048)
    assert s.redrawn > 100
    assert valid_mask(MODEL.params, s.values).all()
    assert (s.values["mu_static"] >= s.values["mu_kinetic"]).all()
    assert (s.values["mu_kinetic"] >= 0).all()


def test_same_seed_same_samples():
    a, b = (draw(MODEL.params, Scatter(), 256, seed=3) for _ in range(2))
    np.testing.assert_array_equal(a.u, b.u)
    assert not np.array_equal(a.u, draw(MODEL.params, Scatter(), 256, seed=4).u)


def test_samples_follow_the_distributions():
    s = draw(MODEL.params, Scatter(), 4096)
    p = MODEL.params
    mu = s.values["mu_kinetic"] / p.mu_kinetic - 1
    assert abs(mu.mean()) < 0.005 and mu.std() == pytest.approx(0.05, rel=0.05)
    ln = np.log(s.values["modal_damping"] / p.modal_damping)
    assert abs(ln.mean()) < 0.02 and ln.std() == pytest.approx(0.35, rel=0.05)


@pytest.mark.parametrize(
    "model, speed, scatter",
    [
        (MODEL, 60.0, Scatter()),
        (CONSISTENT, 52.0, Scatter()),
        (MODEL, -57.0, Scatter()),
        (MODEL, 57.5, Scatter({"modal_damping": 0.35})),
        (MODEL, 59.0, Scatter({"mu_kinetic": 0.1})),
    ],
)
def test_estimator_equals_a_loop_over_the_model(model, speed, scatter):
    """Every sample's verdict is what SqueakModel(sample).predict says, exactly (also reverse
    rotation and a single scattered parameter)."""
    s = draw(model.params, scatter, 512, seed=1)
    hits = squeaks(model, speed, 200.0, s.values)
    flat = {k: v.ravel() for k, v in s.values.items()}
    loop = [
        bool(
            SqueakModel(model.params.with_(**{k: float(v[i]) for k, v in flat.items()}))
            .predict(speed, 200.0)
            .squeak_modes
        )
        for i in range(s.count)
    ]
    assert hits.ravel().tolist() == loop
    assert 0 < sum(loop) < len(loop)  # the point is near a band edge


def test_table_1_at_60_rad_s_squeaks_about_one_drive_in_ten():
    e = monte_carlo(MODEL, 60.0, 200.0, draw(MODEL.params, Scatter(), 4096))
    assert not MODEL.predict(60.0, 200.0).squeak_modes  # nominal: stable
    assert 0.08 < e.probability < 0.18 and 0 < e.stderr < 0.01


@pytest.mark.parametrize("speed", [20.0, 50.0, 55.0, 60.0, 70.0, -30.0])
def test_zero_scatter_is_the_nominal_verdict(speed):
    for sc in (Scatter({}), Scatter({"mu_static": 0.0})):
        e = monte_carlo(MODEL, speed, 200.0, draw(MODEL.params, sc, 256))
        assert e.probability == float(bool(MODEL.predict(speed, 200.0).squeak_modes))
        assert e.stderr is None and e.count == 0


def test_outside_validity_there_is_no_probability():
    assert monte_carlo(MODEL, 0.1, 200.0, draw(MODEL.params, Scatter(), 256)) is None


def test_standard_error_shrinks_with_the_samples_and_describes_the_spread():
    """Quadrupling the samples four times (n x 16) cuts the error at least as 1/sqrt(n) (QMC is
    faster), and the quoted error matches the spread of independent estimates."""

    def runs(n):
        return [
            monte_carlo(MODEL, 55.0, 200.0, draw(MODEL.params, Scatter(), n, seed=k))
            for k in range(6)
        ]

    small, large = runs(256), runs(4096)
    ratio = np.mean([e.stderr for e in large]) / np.mean([e.stderr for e in small])
    assert 1 / 16 < ratio < 1.5 / 4
    spread = np.std([e.probability for e in small], ddof=1)
    assert 0.3 < spread / np.mean([e.stderr for e in small]) < 3


def test_probability_grows_with_the_scatter_near_an_edge():
    """60 rad/s is just above the band's upper edge: more scatter, more drives squeak."""
    p = [
        monte_carlo(
            MODEL,
            60.0,
            200.0,
            draw(MODEL.params, Scatter({n: k * s for n, s in DEFAULT_SCATTER.items()}), 2048),
        ).probability
        for k in (0.25, 0.5, 1.0, 2.0)
    ]
    assert p == sorted(p) and p[0] < 0.01 and p[-1] > 0.2


@pytest.mark.parametrize(
    "speed, sd", [(57.0, {"radius_m": 0.01}), (52.0, {"nut_position_m": 0.1, "mu_kinetic": 0.05})]
)
def test_geometry_scatter_fast_estimator_follows_the_model_per_sample(speed, sd):
    """A scattered geometry field: the reference builds a model per sample; the fast estimator
    expands A to first order in it (a difference of two geometries) on the same samples."""
    s = draw(MODEL.params, Scatter(sd), 256, seed=5)
    mc, fast = monte_carlo(MODEL, speed, 200.0, s), linearised(MODEL, speed, 200.0, s)
    assert 0.02 < mc.probability < 0.98  # near the band edge
    assert fast.probability == pytest.approx(mc.probability, abs=0.03)


def test_prediction_carries_the_fast_probability():
    """`predict` shares its eigen-solve with the estimator: the same number as `linearised`
    on the model's own samples; with no scatter it is the nominal verdict, stderr None."""
    for speed in (50.0, 55.0, 60.0, -57.0):
        p = MODEL.predict(speed, 200.0)
        e = linearised(MODEL, speed, 200.0, MODEL.samples)
        assert (p.probability, p.probability_stderr) == (e.probability, e.stderr)
        none = MODEL.with_scatter(Scatter({})).predict(speed, 200.0)
        assert none.probability == float(bool(none.squeak_modes))
        assert none.probability_stderr is None
    assert MODEL.samples.count == 1024
    assert MODEL.predict(60.0, 200.0).margin == pytest.approx(
        min(m.damping_ratio for m in MODEL.predict(60.0, 200.0).modes)
    )


@settings(max_examples=25, deadline=None)
@given(
    sd=st.dictionaries(st.sampled_from(sorted(DEFAULT_SCATTER)), st.floats(0.0, 1.0), max_size=4),
    speed=st.floats(-500.0, 500.0),
    load=st.floats(-1e4, 1e4),
)
def test_probability_is_a_probability(sd, speed, load):
    samples = draw(MODEL.params, Scatter(sd), 64, seed=0)
    valid = MODEL.validity(speed, load)[0].name == "OK"
    for e in (monte_carlo(MODEL, speed, load, samples), linearised(MODEL, speed, load, samples)):
        assert (e is None) == (not valid)
        if e is not None:
            assert 0.0 <= e.probability <= 1.0 and not math.isnan(e.probability)
            assert e.stderr is None or (math.isfinite(e.stderr) and e.stderr >= 0)


@settings(max_examples=30, deadline=None)
@given(
    sd=st.dictionaries(st.sampled_from(scatterable()), st.floats(0.0, 0.3), max_size=4),
    speed=st.floats(-2000.0, 2000.0),
    load=st.floats(-1e5, 1e5),
)
def test_any_scatter_setting_gives_a_probability_or_a_clear_error(sd, speed, load):
    """Random scatter of any scatterable field (geometry too) through `predict`: a P in
    [0, 1] with a finite stderr, or a one-line ParameterError (too many geometry fields, a
    domain the samples cannot stay in)."""
    try:
        model = MODEL.with_scatter(Scatter(sd), 64)
        p = model.predict(speed, load)
    except ParameterError as exc:
        assert "\n" not in str(exc) and str(exc)
        return
    if p.valid:
        assert 0.0 <= p.probability <= 1.0
        assert p.probability_stderr is None or (
            math.isfinite(p.probability_stderr) and p.probability_stderr >= 0
        )
    else:
        assert p.probability is None


FAST_GRID_SPEEDS = (5.0, 20.0, 40.0, 50.0, 55.0, 60.0, 70.0, -40.0)  # band, both edges
FAST_GRID_LOADS = (50.0, 200.0, 600.0)


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
def test_fast_estimator_is_within_0_03_of_the_reference(formulation):
    """The live estimator on 1024 samples against Monte Carlo on 2048 other samples over a
    speed x load grid that crosses the band edges."""
    model = MODEL if formulation == "paper" else CONSISTENT
    ref = draw(model.params, Scatter(), 2048, seed=11)
    live = draw(model.params, Scatter(), 1024, seed=12)
    errors, inside = [], 0
    for load in FAST_GRID_LOADS:
        for speed in FAST_GRID_SPEEDS:
            mc, fast = monte_carlo(model, speed, load, ref), linearised(model, speed, load, live)
            assert (mc is None) == (fast is None)
            if mc is not None:
                errors.append(abs(fast.probability - mc.probability))
                inside += 0.05 < mc.probability < 0.95
    assert max(errors) <= 0.03 and inside >= 4  # several points near an edge


def test_fast_estimator_on_the_same_samples_is_nearly_exact():
    s = draw(MODEL.params, Scatter(), 4096)
    for speed in (50.0, 55.0, 60.0):
        assert linearised(MODEL, speed, 200.0, s).probability == pytest.approx(
            monte_carlo(MODEL, speed, 200.0, s).probability, abs=0.005
        )


def test_fast_estimator_with_zero_scatter_is_the_nominal_verdict():
    for speed in (20.0, 60.0, -30.0):
        e = linearised(MODEL, speed, 200.0, draw(MODEL.params, Scatter({}), 64))
        assert e.probability == float(bool(MODEL.predict(speed, 200.0).squeak_modes))


def test_predict_is_thread_safe():
    """Two threads predicting on one model (the node's executor and its background safe-speed
    search) get the numbers one thread gets."""
    from concurrent.futures import ThreadPoolExecutor

    speeds = [50.0, 55.0, 57.0, 60.0] * 25
    alone = [MODEL.predict(s, 200.0).probability for s in speeds]
    with ThreadPoolExecutor(2) as pool:
        for _ in range(3):
            assert list(pool.map(lambda s: MODEL.predict(s, 200.0).probability, speeds)) == alone


@pytest.mark.parametrize(
    "scatter",
    [
        None,
        Scatter({"mu_static": 0.05, "radius_m": 0.01}),
        Scatter({"nut_length_m": 0.05, "mu_kinetic": 0.05}),
    ],
)
def test_moved_nut_shares_the_samples_and_predicts_as_a_new_model(scatter):
    """with_params(nut_position_m=...) reuses the samples (and, without geometry scatter, the
    per-sample friction) instead of drawing them again: the predictions are those of a model
    built from scratch, bit for bit."""
    base = SqueakModel(scatter=scatter, samples=256)
    base.predict(50.0, 200.0)
    for nut in (0.03, 0.0512, 0.08):
        moved = base.with_params(nut_position_m=nut)
        fresh = SqueakModel(base.params.with_(nut_position_m=nut), base.scatter, 256)
        for speed, load in ((20.0, 200.0), (50.0, 200.0), (55.0, -150.0)):
            assert moved.predict(speed, load) == fresh.predict(speed, load)
    if "nut_length_m" not in base.scatter.names:
        assert moved.samples is base.samples
