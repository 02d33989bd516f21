# SPDX-License-Identifier: Apache-2.0
"""Input validation: clear errors naming field, value and range; valid input never gives NaN."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from leadscrew_ros.model import (
    OperatingPointError,
    ParameterError,
    ScrewParameters,
    SqueakModel,
    Validity,
    squeak_model,
)
from leadscrew_ros.model.physics.parameters import MAX_CONTACT_TURNS, field_info, field_names
from leadscrew_ros.model.studies.sweep import sweep


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"radius_m": -0.001}, ["radius_m", "-0.001", "out of range"]),
        ({"radius_m": float("nan")}, ["radius_m", "finite"]),
        ({"length_m": float("inf")}, ["length_m", "finite"]),
        ({"nut_position_m": 0.25}, ["z_o + b <= L"]),
        ({"helix_angle_rad": 0.0}, ["helix_angle_rad", "(0, 1.5708)"]),
        ({"helix_angle_rad": math.pi / 2}, ["helix_angle_rad"]),
        ({"mu_kinetic": 0.3}, ["mu_kinetic", "mu_static"]),
        ({"mu_kinetic": -0.1}, ["mu_kinetic", "out of range"]),
        ({"n_bending": 0}, ["n_bending"]),
        ({"n_torsion": 2.5}, ["n_torsion", "int"]),
        ({"formulation": "printed"}, ["formulation", "paper", "consistent"]),
        ({"modal_damping": 1.0}, ["modal_damping"]),
        ({"thread_height_m": 0.01}, ["thread_height_m", "radius_m"]),
        ({"helix_angle_rad": 1e-6}, ["turns"]),
    ],
)
def test_invalid_parameters_raise_a_named_error(changes, words):
    with pytest.raises(ParameterError) as err:
        ScrewParameters(**changes)
    for w in words:
        assert w in str(err.value)


def test_with_rejects_unknown_fields_and_coerces_strings():
    p = ScrewParameters()
    with pytest.raises(ParameterError, match="unknown parameter"):
        p.with_(radius=0.004)
    assert p.with_(radius_m="0.004", n_bending="7").radius_m == 0.004
    with pytest.raises(ParameterError, match="not a valid"):
        p.with_(radius_m="four")


@pytest.mark.parametrize(
    "speed, load",
    [
        (float("nan"), 200.0),
        (20.0, float("inf")),
        (float("-inf"), 1.0),
        ("20", 200.0),
        (None, 1.0),
        (True, 1.0),
        (20.0, 1e12),
    ],
)
def test_bad_operating_points_raise(speed, load):
    with pytest.raises(OperatingPointError):
        SqueakModel().predict(speed, load)


@pytest.mark.parametrize("speed", [0.0, 0.1, -0.2, 1410.6, 5000.0, -3000.0])
def test_outside_validity_gives_reason_not_number(speed):
    p = SqueakModel().predict(speed, 200.0)
    assert not p.valid and "outside the model's validity" in p.reason
    assert p.probability is None and p.stable is None and p.max_growth_rate is None and not p.modes
    d = p.as_dict()
    assert d["valid"] is False and d["probability"] is None


# A thread that self-locks: mu_o tan(beta) = 1.56 >= 1 (consistent formulation only).
SELF_LOCKING = dict(formulation="consistent", mu_static=1.0, mu_kinetic=1.0, helix_angle_rad=1.0)


@pytest.mark.parametrize(
    "changes, speed, load, validity",
    [
        ({}, 20.0, 200.0, Validity.OK),
        ({}, 0.1, 200.0, Validity.BELOW_MIN_SPEED),
        ({}, -0.2, 200.0, Validity.BELOW_MIN_SPEED),
        ({}, 1410.6, 200.0, Validity.AT_CRITICAL_SPEED),
        ({}, -3000.0, 200.0, Validity.AT_CRITICAL_SPEED),
        (SELF_LOCKING, 20.0, -200.0, Validity.SELF_LOCKING),  # overhauling load
        (SELF_LOCKING, -20.0, 200.0, Validity.SELF_LOCKING),
        (SELF_LOCKING, 20.0, 200.0, Validity.OK),  # driving load: sliding
        ({**SELF_LOCKING, "formulation": "paper"}, 20.0, -200.0, Validity.OK),
    ],
)
def test_the_model_sets_the_validity_of_each_point(changes, speed, load, validity):
    m = SqueakModel(ScrewParameters(**changes))
    p = m.predict(speed, load)
    assert p.validity is validity and p.valid == (validity is Validity.OK)
    assert bool(p.reason) == (validity is not Validity.OK)
    assert int(m.validity_code(speed, load)) == validity
    (q,) = m.predict_many([speed], [load])  # the batched path agrees
    assert q.validity is validity and q.reason == p.reason


def test_a_failed_eigen_solve_is_its_own_validity(monkeypatch):
    def broken(_matrix, _left=True):
        raise np.linalg.LinAlgError("Eigenvalues did not converge")

    monkeypatch.setattr(squeak_model, "eig_both", broken)
    p = SqueakModel().predict(20.0, 200.0)
    assert p.validity is Validity.SOLVER_FAILED and not p.valid and p.probability is None
    assert "did not converge" in p.reason


def test_parameters_not_allowed_at_a_sweep_point_are_their_own_validity():
    r = sweep(SqueakModel(), "nut_position_m", [0.1, 0.3], speed_rad_s=20.0)
    assert [p.validity for p in r.predictions] == [Validity.OK, Validity.PARAMETERS_REJECTED]


def test_every_validity_has_a_short_name_and_a_sentence():
    labels = [v.label for v in Validity]
    assert len(set(labels)) == len(labels)
    for v in Validity:
        assert v.label and len(v.label) <= 50 and len(v.sentence) > len(v.label)


@pytest.mark.parametrize("formulation", ["paper", "consistent"])
def test_reverse_rotation_and_other_flank_give_finite_predictions(formulation):
    m = SqueakModel().with_params(formulation=formulation)
    for speed, load in ((-20.0, 200.0), (20.0, -200.0), (-20.0, -200.0), (20.0, 0.0)):
        p = m.predict(speed, load)
        assert p.valid and 0.0 <= p.probability <= 1.0
        assert all(
            np.isfinite([x.frequency_hz, x.growth_rate, x.damping_ratio]).all() for x in p.modes
        )
    # Zero load: no contact, no friction: stable.
    assert m.predict(20.0, 0.0).stable


def _finite_in(name, lo=None, hi=None):
    info = field_info(name)
    lo = info["lo"] if lo is None else lo
    hi = info["hi"] if hi is None else hi
    return st.floats(
        lo,
        hi,
        allow_nan=False,
        allow_infinity=False,
        exclude_min=info["lo_open"],
        exclude_max=info["hi_open"],
    )


@st.composite
def valid_parameters(draw):
    R = draw(_finite_in("radius_m", 1e-3, 0.05))
    L = draw(_finite_in("length_m", 0.05, 3.0))
    beta = draw(st.floats(math.radians(1.0), math.radians(60.0)))
    max_b = 0.99 * MAX_CONTACT_TURNS * 2 * math.pi * R * math.tan(beta)
    b = draw(st.floats(0.01 * L, min(0.9 * L, max_b)))
    z0 = draw(st.floats(0.0, L - b))
    mus = draw(_finite_in("mu_static"))
    return dict(
        radius_m=R,
        length_m=L,
        nut_length_m=b,
        nut_position_m=z0,
        helix_angle_rad=beta,
        thread_height_m=draw(st.floats(0.01 * R, 0.9 * R)),
        mu_static=mus,
        mu_kinetic=draw(st.floats(0.0, mus)),
        friction_decay_s_m=draw(_finite_in("friction_decay_s_m", 0.0, 100.0)),
        modal_damping=draw(_finite_in("modal_damping", 0.0, 0.2)),
        youngs_modulus_pa=draw(st.floats(1e9, 4e11)),
        shear_modulus_pa=draw(st.floats(1e9, 2e11)),
        density_kg_m3=draw(st.floats(1e3, 2e4)),
        n_bending=draw(st.integers(1, 8)),
        n_torsion=draw(st.integers(1, 8)),
        formulation=draw(st.sampled_from(["paper", "consistent"])),
    )


@settings(
    max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(valid_parameters(), st.floats(-1e4, 1e4), st.floats(-1e5, 1e5))
def test_valid_inputs_never_raise_and_never_give_nan(params, speed, load):
    p = SqueakModel(ScrewParameters(**params)).predict(speed, load)
    d = p.as_dict()
    if p.valid:
        assert 0.0 <= d["probability"] <= 1.0 and isinstance(d["stable"], bool)
        values = [
            v for m in d["modes"] for v in (m["frequency_hz"], m["growth_rate"], m["damping_ratio"])
        ]
        assert np.all(np.isfinite(values + d["unstable_frequencies_hz"] + d["divergence_rates"]))
    else:
        assert d["reason"] and d["probability"] is None and not d["modes"]


@settings(max_examples=80, deadline=None, derandomize=True)
@given(
    st.sampled_from([n for n in field_names() if field_info(n)["type"] == "float"]),
    st.one_of(
        st.just(float("nan")),
        st.just(float("inf")),
        st.just(-float("inf")),
        st.floats(-1e15, -1e-300),
        st.floats(1e3, 1e15),
    ),
)
def test_invalid_values_raise_parameter_error_or_are_accepted_in_range(name, value):
    info = field_info(name)
    in_range = (
        math.isfinite(value)
        and (value > info["lo"] if info["lo_open"] else value >= info["lo"])
        and (value < info["hi"] if info["hi_open"] else value <= info["hi"])
    )
    try:
        p = ScrewParameters().with_(**{name: value})
    except ParameterError as exc:
        assert name in str(exc) or "z_o + b" in str(exc) or "turns" in str(exc)
        return
    assert in_range and getattr(p, name) == value
