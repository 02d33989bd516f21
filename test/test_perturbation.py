# SPDX-License-Identifier: Apache-2.0
"""First-order eigenvalue perturbation (`model.uncertainty.perturbation`): the eigenvalue
rates against
finite differences of eigen-solves, and the live P(squeak) estimator's per-sample margins
against a brute-force eigen-solve of every sample's own state matrix (error of second order in
the scatter, verdicts the same)."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from leadscrew_ros.model import ParameterError, SqueakModel
from leadscrew_ros.model.physics.friction import (
    SteadyFriction,
    friction_coefficient,
    friction_slope,
    sliding_speed,
)
from leadscrew_ros.model.physics.kernels import coefficients, scales
from leadscrew_ros.model.physics.stability import (
    GROWTH_TOL,
    eig_both,
    left_rows,
    oscillatory_mask,
)
from leadscrew_ros.model.uncertainty.perturbation import (
    EigenPairs,
    FirstOrderProbability,
    _Expansion,
    estimate,
    geometry_derivative,
    geometry_fields,
    growth_rates,
    units_on_displacements,
)
from leadscrew_ros.model.uncertainty.scatter import DEFAULT_SCATTER, Scatter, draw

MODEL = SqueakModel()
GEOMETRY = MODEL.geometry
LOAD = 200.0
# Table 1: deep in the squeak band, at its edge (P ~ 0.5), just above it (P ~ 0.1)
SPEEDS = (20.0, 55.0, 60.0)


def matched(lam: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The eigenvalues of `lam` nearest to each of `reference` (a small perturbation moves
    each simple eigenvalue a little: nearest is the same branch)."""
    return lam[np.abs(lam[None, :] - reference[:, None]).argmin(axis=1)]


def exact_margins(samples, speed: float, load: float = LOAD) -> np.ndarray:
    """Per sample, brute force: the eigenvalues of the sample's own state matrix, the largest
    oscillatory growth rate beyond the squeak threshold (`stability.unstable_mask`)."""
    values = {k: v.ravel() for k, v in samples.scatter.values(MODEL.params, samples.u).items()}
    lam = np.linalg.eigvals(GEOMETRY.state_matrices(speed, load, values))
    return np.where(oscillatory_mask(lam), lam.real - GROWTH_TOL * np.abs(lam), -np.inf).max(axis=1)


def first_order_margins(samples, speed: float, load: float = LOAD) -> np.ndarray:
    """The expansion's margins of every mode's maximum (no pruning: values, not just signs)."""
    fo = FirstOrderProbability(MODEL.params, GEOMETRY, samples)
    pairs = EigenPairs.solve(GEOMETRY, speed, load)
    return _Expansion(GEOMETRY, fo._friction).margins(
        pairs, load, fo._damping, fo._reach_damping, prune=False
    )


def scaled(samples, k: float):
    """The same samples with every standard-normal coordinate times k (deviations ~k)."""
    return dataclasses.replace(samples, u=samples.u * k)


# ----------------------------------------------------------------------------- eigen pairs
@pytest.mark.parametrize("speed", SPEEDS)
def test_eigen_pairs_are_the_oscillatory_eigenvalues_with_biorthonormal_vectors(speed):
    a = GEOMETRY.state_matrices(speed, LOAD)
    pairs = EigenPairs.solve(GEOMETRY, speed, LOAD)
    lam = np.linalg.eigvals(a)
    want = np.sort_complex(lam[oscillatory_mask(lam)])
    np.testing.assert_allclose(np.sort_complex(pairs.lam), want, rtol=1e-10)
    scale = np.abs(pairs.lam)[:, None]
    np.testing.assert_allclose(a @ pairs.x, pairs.x * pairs.lam, atol=1e-9 * scale.max())
    np.testing.assert_allclose(
        pairs.y_h @ a,
        pairs.lam[:, None] * pairs.y_h,
        atol=1e-9 * scale.max() * np.abs(pairs.y_h).max(),
    )
    # y_i^H x_j = delta_ij: the normalisation the first-order formula needs
    np.testing.assert_allclose(pairs.y_h @ pairs.x, np.eye(len(pairs.lam)), atol=1e-9)


def test_the_speed_derivative_is_the_coefficients_plus_the_stiffness_term():
    """d lambda / d Omega = (d coefficients / d Omega) . unit_rates (friction, gyroscopic) +
    the -Omega^2 term of K, against central differences of eigen-solves and `matrix_rate`."""
    speed, alpha, h = 55.0, GEOMETRY.contact.alpha, 1e-4
    pairs = EigenPairs.solve(GEOMETRY, speed, LOAD)

    def coefficients(omega):
        s = scales(MODEL.params, omega, LOAD, alpha)
        return np.array([s["W1"], s["W5q"], s["W3"], s["W5qdot"], omega], float)

    dc = (coefficients(speed + h) - coefficients(speed - h)) / (2 * h)
    rate = pairs.coefficient_rate(dc) + pairs.speed_rate_of_stiffness()
    da = GEOMETRY.state_matrices(speed + h, LOAD) - GEOMETRY.state_matrices(speed - h, LOAD)
    np.testing.assert_allclose(
        pairs.matrix_rate(da) / (2 * h), rate, rtol=1e-6, atol=1e-9 * np.abs(rate).max()
    )
    hi, lo = (
        matched(np.linalg.eigvals(GEOMETRY.state_matrices(speed + s, LOAD)), pairs.lam)
        for s in (h, -h)
    )
    np.testing.assert_allclose((hi - lo) / (2 * h), rate, rtol=1e-4, atol=1e-6 * np.abs(rate).max())


def test_damping_rate_and_the_stiffness_speed_term_are_those_of_their_matrices():
    speed = 55.0
    pairs = EigenPairs.solve(GEOMETRY, speed, LOAD)
    n, om = GEOMETRY.n, GEOMETRY.basis.omega_rad_s
    xi = MODEL.params.modal_damping
    # A is affine in the damping ratio: the change of A is exactly -2 d diag(omega) in D
    d = 1e-4
    da = GEOMETRY.state_matrices(speed, LOAD, {"modal_damping": np.array([xi + d])})[
        0
    ] - GEOMETRY.state_matrices(speed, LOAD)
    np.testing.assert_allclose(pairs.matrix_rate(da) / d, pairs.damping_rate(), rtol=1e-7)
    moved = matched(
        np.linalg.eigvals(
            GEOMETRY.state_matrices(speed, LOAD, {"modal_damping": np.array([xi + d])})[0]
        ),
        pairs.lam,
    )
    np.testing.assert_allclose((moved - pairs.lam) / d, pairs.damping_rate(), rtol=1e-3)
    # more damping: every mode decays faster, by about omega (Re d lambda / d xi ~ -omega)
    assert np.all(pairs.damping_rate().real < 0)
    stiffness = np.zeros((2 * n, 2 * n))
    stiffness[n:, :n] = 2 * speed * np.eye(n)
    np.testing.assert_allclose(
        pairs.speed_rate_of_stiffness(), pairs.matrix_rate(stiffness), rtol=1e-12
    )
    assert om.min() > speed


@pytest.mark.parametrize(
    ("speed", "load"), [(20.0, LOAD), (55.0, LOAD), (-40.0, 350.0), (3.0, -80.0)]
)
def test_the_estimates_rates_are_those_of_lapacks_left_vectors(speed, load):
    """`growth_rates` as the live estimate calls it (the left vectors from the inverse of the
    right ones, `left_rows`; the units on the displacement halves) against Re(y^H dA x) of
    the same modes from LAPACK's own left vectors (`EigenPairs.solve`) and the coefficients'
    derivatives in l, s and xi (`kernels.scales`: W1 = sign l, W3 = l / |Omega|,
    W5q = Omega s, W5qdot = s)."""
    n = GEOMETRY.n
    e = eig_both(GEOMETRY.state_matrices(speed, load), False)
    pairs = EigenPairs.solve(GEOMETRY, speed, load)
    units = units_on_displacements(GEOMETRY.lower_half_units, GEOMETRY.basis.omega_rad_s)
    lam, q = e.lam[e.osc], e.vr[:n, e.osc] + 1j * e.vr[:n, e.osc + 1]
    rates = growth_rates(units, speed, lam, q, left_rows(e.vr, e.osc, n))
    w1, w5q, w3, w5qdot = pairs.unit_rates[:4]
    expected = np.array(
        [
            (np.sign(speed) * w1 + w3 / abs(speed)).real,
            (speed * w5q + w5qdot).real,
            pairs.damping_rate().real,
        ]
    )
    assert rates.shape == expected.shape == (3, len(e.osc))
    scale = np.abs(expected).max(axis=1, keepdims=True)  # each row in its own unit
    assert np.all(np.abs(rates - expected) <= 1e-9 * scale)


def test_the_friction_law_with_its_speed_free_factors_once_is_the_law():
    """`SteadyFriction` (the estimate's samples at every point) is (12) at the steady sliding
    speed: mu_o = mu(|Vc|), gamma = cos(beta) dmu/d|Vc|, for nominal parameters and arrays of
    samples, at one speed and at many."""
    p = MODEL.params
    samples = SimpleNamespace(
        **{
            **p.as_dict(),
            "mu_static": p.mu_static * np.array([0.9, 1.0, 1.2]),
            "friction_decay_s_m": p.friction_decay_s_m * np.array([1.1, 0.8, 1.0]),
        }
    )
    for params in (p, samples):
        law = SteadyFriction(params)
        for speed in (0.5, 20.0, -60.0, np.array([[1.0], [-150.0]])):
            v = sliding_speed(params, speed)
            mu, gamma = law(speed)
            np.testing.assert_allclose(mu, friction_coefficient(params, v), rtol=1e-13)
            np.testing.assert_allclose(
                gamma, np.cos(params.helix_angle_rad) * friction_slope(params, v), rtol=1e-13
            )


def test_a_live_points_coefficients_are_those_of_the_arrays():
    """`kernels.coefficients` on Python floats (a live point's state matrix) gives the factors
    of the array path, and at zero speed numpy's inf (no exception), as arrays do."""
    for speed in (0.3, 20.0, -57.5, 149.0):
        floats = coefficients(speed, 0.7, -1.3)
        arrays = coefficients(np.array([speed]), np.array([0.7]), np.array([-1.3]))
        np.testing.assert_allclose(np.ravel(floats), np.ravel(arrays), rtol=1e-15)
    with np.errstate(divide="ignore"):
        at_rest = coefficients(0.0, 0.7, -1.3)
    assert np.isinf(at_rest[1]) and at_rest[0] == 0.0


def test_coefficient_rates_give_the_eigenvalue_change_with_the_load():
    """A load change at fixed speed moves only the contact coefficients (W1, W5q, W3, W5qdot):
    the chain rule through `unit_rates` is the eigenvalues' derivative in the load."""
    speed, alpha = 55.0, GEOMETRY.contact.alpha

    def coefficients(load):
        s = scales(MODEL.params, speed, load, alpha)
        return np.array([s["W1"], s["W5q"], s["W3"], s["W5qdot"], speed], float)

    pairs = EigenPairs.solve(GEOMETRY, speed, LOAD)
    dc = coefficients(LOAD * (1 + 1e-6)) - coefficients(LOAD * (1 - 1e-6))
    da = GEOMETRY.state_matrices(speed, LOAD * (1 + 1e-6)) - GEOMETRY.state_matrices(
        speed, LOAD * (1 - 1e-6)
    )
    rate = pairs.coefficient_rate(dc)
    np.testing.assert_allclose(
        rate, pairs.matrix_rate(da), rtol=1e-6, atol=1e-9 * np.abs(rate).max()
    )
    hi, lo = (
        matched(np.linalg.eigvals(GEOMETRY.state_matrices(speed, LOAD * (1 + s))), pairs.lam)
        for s in (1e-6, -1e-6)
    )
    np.testing.assert_allclose(hi - lo, rate, rtol=1e-4, atol=1e-6 * np.abs(rate).max())
    assert np.abs(rate).max() > 0  # the load does move the modes


def test_geometry_derivative_gives_the_eigenvalue_change_with_the_radius():
    speed = 55.0
    pairs = EigenPairs.solve(GEOMETRY, speed, LOAD)
    rate = pairs.matrix_rate(geometry_derivative(MODEL.params, "radius_m", speed, LOAD))
    h = 1e-5 * MODEL.params.radius_m
    hi, lo = (
        matched(
            np.linalg.eigvals(
                SqueakModel(
                    MODEL.params.with_(radius_m=MODEL.params.radius_m + s)
                ).geometry.state_matrices(speed, LOAD)
            ),
            pairs.lam,
        )
        for s in (h, -h)
    )
    np.testing.assert_allclose((hi - lo) / (2 * h), rate, rtol=1e-3, atol=1e-4 * np.abs(rate).max())
    # 1 % of radius moves the squeak mode (B1y, ~1413 rad/s) by ~14 rad/s, the figure in
    # FirstOrderProbability's docstring
    squeak = pairs.lam.real.argmax()
    assert 10.0 < abs(rate[squeak].imag) * 0.01 * MODEL.params.radius_m < 20.0


# ----------------------------------------------------------------------------- the estimator
@pytest.mark.parametrize("speed", SPEEDS)
def test_first_order_margins_against_the_brute_force_eigen_solve_of_every_sample(speed):
    """Default scatter (friction and damping), 256 samples: the expanded margin of each sample
    is within 1 % of the samples' spread of the exact one, the error is of second order (a
    quarter when the deviations halve), and the squeak verdicts agree."""
    samples = draw(MODEL.params, Scatter(), 256, seed=1)
    errors = []
    for k in (1.0, 0.5, 0.25):
        exact = exact_margins(scaled(samples, k), speed)
        approx = first_order_margins(scaled(samples, k), speed)
        errors.append(np.abs(approx - exact).max())
        assert errors[-1] < 0.01 * np.ptp(exact), (k, errors[-1], np.ptp(exact))
        assert np.count_nonzero((approx > 0) != (exact > 0)) <= 0.01 * samples.count
    assert 3.0 < errors[0] / errors[1] < 5.5 and 3.0 < errors[1] / errors[2] < 5.5, errors


@pytest.mark.parametrize("speed", SPEEDS)
def test_pruned_margins_keep_every_verdict(speed):
    """`margins` leaves out modes that cannot reach the threshold: the same signs as the full
    expansion, the same values where a sample squeaks."""
    samples = draw(MODEL.params, Scatter(), 256, seed=2)
    fo = FirstOrderProbability(MODEL.params, GEOMETRY, samples)
    pairs = EigenPairs.solve(GEOMETRY, speed, LOAD)
    pruned, full = fo.margins(pairs, LOAD), first_order_margins(samples, speed)
    np.testing.assert_array_equal(pruned > 0, full > 0)
    np.testing.assert_allclose(pruned[full > 0], full[full > 0], rtol=1e-12)
    hits = fo.hits(pairs, LOAD)
    assert hits.shape == samples.u.shape[:2]
    np.testing.assert_array_equal(hits.ravel(), exact_margins(samples, speed) > 0)


def test_without_deviation_every_sample_is_the_nominal_prediction():
    samples = scaled(draw(MODEL.params, Scatter(), 64, seed=3), 0.0)
    for speed in SPEEDS:
        p = MODEL.predict(speed, LOAD)
        margins = first_order_margins(samples, speed)
        np.testing.assert_allclose(margins, exact_margins(samples, speed), rtol=1e-9)
        # the margin is the growth rate less the round-off threshold GROWTH_TOL |lambda|
        # (1e-10 x ~1e3 1/s for the squeak modes)
        assert margins[0] == pytest.approx(p.max_growth_rate, abs=1e-6)


def test_geometry_scatter_nodes_interpolate_to_the_samples_own_models():
    """A scattered radius: the extreme samples sit on the end nodes (quantiles 0 and 1), so
    their margin is the expansion around their own geometry; brute force there is a model
    built with the sample's radius, friction and damping."""
    speed = 57.0
    scatter = Scatter({**DEFAULT_SCATTER, "radius_m": 0.01})
    samples = draw(MODEL.params, scatter, 64, seed=5)
    fo = FirstOrderProbability(MODEL.params, GEOMETRY, samples)
    margins = fo.margins(EigenPairs.solve(GEOMETRY, speed, LOAD), LOAD)
    values = {k: v.ravel() for k, v in scatter.values(MODEL.params, samples.u).items()}
    for i in (values["radius_m"].argmin(), values["radius_m"].argmax()):
        own = SqueakModel(
            MODEL.params.with_(**{k: float(v[i]) for k, v in values.items()}), Scatter({})
        )
        assert margins[i] == pytest.approx(own.predict(speed, LOAD).max_growth_rate, abs=0.2)
    assert len({m > 0 for m in margins}) == 2  # the band edge: both verdicts


def test_a_moved_nut_keeps_the_samples_and_rebuilds_the_expansion():
    samples = draw(MODEL.params, Scatter(), 64, seed=4)
    fo = FirstOrderProbability(MODEL.params, GEOMETRY, samples)
    moved = MODEL.with_params(nut_position_m=0.05)
    shifted = fo.with_geometry(moved.params, moved.geometry)
    assert shifted.samples is samples and shifted.params == moved.params
    pairs = EigenPairs.solve(moved.geometry, 55.0, LOAD)
    np.testing.assert_array_equal(
        shifted.margins(pairs, LOAD),
        FirstOrderProbability(moved.params, moved.geometry, samples).margins(pairs, LOAD),
    )
    assert fo.params == MODEL.params  # the original is unchanged


# ----------------------------------------------------------------------------- fields, estimate
def test_geometry_fields_are_the_scattered_geometry_and_at_most_two():
    assert geometry_fields(Scatter()) == []
    assert geometry_fields(Scatter({**DEFAULT_SCATTER, "radius_m": 0.01})) == ["radius_m"]
    sd = {"radius_m": 0.01, "nut_position_m": 0.01, "helix_angle_rad": 0.01}
    with pytest.raises(ParameterError, match="3 geometry fields scatter"):
        geometry_fields(Scatter(sd))


def test_more_geometry_fields_than_the_live_estimate_takes_is_one_clear_error():
    sd = {"radius_m": 0.01, "nut_position_m": 0.01, "helix_angle_rad": 0.01}
    with pytest.raises(ParameterError, match="3 geometry fields scatter"):
        MODEL.with_scatter(Scatter(sd), 64)


def test_estimate_is_the_mean_share_and_the_spread_of_the_replicates():
    hits = np.zeros((4, 10), bool)
    for r, n in enumerate((1, 2, 3, 4)):
        hits[r, :n] = True
    p, se = estimate(hits)
    assert p == pytest.approx(0.25)
    # sample variance of the shares 0.1..0.4 is 1/60; the mean of 4 has variance 1/240
    assert se == pytest.approx((1 / 240) ** 0.5)
    assert estimate(np.ones((8, 16), bool)) == (1.0, 0.0)
