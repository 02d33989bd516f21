# SPDX-License-Identifier: Apache-2.0
"""Countermeasures: ranked 10 % changes with the new P(squeak) computed."""

import pytest

from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.studies.countermeasures import (
    DESIGN,
    FRICTION,
    OPERATING,
    STEP,
    Countermeasure,
    advice_text,
    changed_by,
    countermeasures,
)
from leadscrew_ros.model.studies.probability import linearised
from leadscrew_ros.model.uncertainty.scatter import Scatter, draw

MODEL = SqueakModel()
SAMPLES = draw(MODEL.params, Scatter(), 1024)


def test_changes_are_ranked_and_each_new_probability_is_computed():
    now, found = countermeasures(MODEL, 55.0, 200.0, SAMPLES)
    assert now == linearised(MODEL, 55.0, 200.0, SAMPLES).probability
    assert [c.probability for c in found] == sorted(c.probability for c in found)
    assert all(c.probability < now for c in found) and len(found) >= 4
    assert {c.name for c in found} <= set(DESIGN + FRICTION + OPERATING)
    for c in found:
        assert c.factor in (1 + STEP, 1 - STEP)
        model, speed, load = changed_by(MODEL, 55.0, 200.0, c.name, c.factor)
        assert c.probability == linearised(model, speed, load, SAMPLES).probability


def test_each_lever_changes_what_it_says():
    p = MODEL.params
    drop = changed_by(MODEL, 55.0, 200.0, "friction_drop", 0.9)[0].params
    assert drop.mu_kinetic == p.mu_kinetic
    assert drop.mu_static - drop.mu_kinetic == pytest.approx(0.9 * (p.mu_static - p.mu_kinetic))
    assert changed_by(MODEL, 55.0, 200.0, "speed_rad_s", 1.1)[1:] == (55.0 * 1.1, 200.0)
    assert changed_by(MODEL, 55.0, 200.0, "load_n", 0.9)[1:] == (55.0, 200.0 * 0.9)
    assert changed_by(MODEL, 55.0, 200.0, "radius_m", 1.1)[0].params.radius_m == pytest.approx(
        1.1 * p.radius_m
    )


def test_a_smaller_stribeck_drop_lowers_the_probability_near_an_edge():
    now, found = countermeasures(MODEL, 57.0, 200.0, SAMPLES)
    drop = {c.name: c for c in found}["friction_drop"]
    assert drop.factor == 1 - STEP and drop.probability < now - 0.01


def test_more_damping_lowers_the_probability_near_an_edge():
    """The damping scatter is relative: a 10 % higher nominal damping moves every sample."""
    now, found = countermeasures(MODEL, 60.0, 200.0, SAMPLES)
    damping = {c.name: c for c in found}["modal_damping"]
    assert damping.factor == 1 + STEP and damping.probability < now


def test_a_change_off_the_valid_domain_is_not_offered():
    """With the nut 5 mm from the end of its travel, +10 % would put it off the screw."""
    model = SqueakModel(ScrewParameters(nut_position_m=0.235))
    _, found = countermeasures(model, 50.0, 200.0, draw(model.params, Scatter(), 256))
    nut = [c for c in found if c.name == "nut_position_m"]
    assert all(c.factor == 1 - STEP for c in nut)


def test_outside_validity_there_is_no_advice():
    assert countermeasures(MODEL, 0.1, 200.0, SAMPLES) is None


def test_advice_is_one_line():
    found = [
        Countermeasure("radius_m", 1.1, 0.01),
        Countermeasure("friction_drop", 0.9, 0.05),
        Countermeasure("speed_rad_s", 0.9, 0.06),
    ]
    assert advice_text(0.114, found) == "P(squeak) 0.11: raise the radius or lower mu_s - mu_k"
    assert advice_text(0.0, []) == "P(squeak) 0.00"
    assert (
        advice_text(0.5, []) == "P(squeak) 0.50: no 10 % change of one parameter lowers it by 0.01"
    )
    assert advice_text(0.995, [Countermeasure("radius_m", 1.1, 0.99)]).endswith("by 0.01")


@pytest.mark.parametrize("formulation, speed", [("paper", 60.0), ("consistent", 49.0)])
def test_the_radius_is_the_strongest_lever_at_table_1(formulation, speed):
    model = SqueakModel(ScrewParameters(formulation=formulation))
    _, found = countermeasures(model, speed, 200.0, draw(model.params, Scatter(), 1024))
    assert found[0].name == "radius_m" and found[0].factor == 1 + STEP
