# SPDX-License-Identifier: Apache-2.0
"""`model.physics.display.exact`: numbers in messages are short, read back as the same
float, and are never rounded onto the limit they violate."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from leadscrew_ros.model.physics.display import exact


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_the_text_reads_back_as_the_same_float(v):
    assert float(exact(v)) == v


@pytest.mark.parametrize(
    "value, text",
    [
        (0.24, "0.24"),
        (200.0, "200"),
        (0.005, "0.005"),
        (1e7, "1e+07"),
        (-3.5, "-3.5"),
        (0.1 + 0.2, "0.30000000000000004"),  # the float, not the decimal one meant
        (1.0000001e7, "1.0000001e+07"),  # not '1e+07' (%g), not '10000001'
        (0.2400001, "0.2400001"),
    ],
)
def test_short_when_possible_exact_always(value, text):
    assert exact(value) == text


def test_a_value_just_beyond_a_limit_does_not_print_as_the_limit():
    limit = 1e7
    beyond = math.nextafter(limit, math.inf)
    assert exact(limit) == f"{limit:g}" and exact(beyond) != exact(limit)
    assert float(exact(beyond)) > limit
