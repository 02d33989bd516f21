# SPDX-License-Identifier: Apache-2.0
"""`review.jsonsafe.json_safe`: what the replay and fleet reports write is strict JSON (no NaN
or infinity, which strict readers reject) with the same values, numpy types as Python's."""

import json
import math

import numpy as np

from leadscrew_ros.review.jsonsafe import json_safe


def test_non_finite_numbers_become_null_and_numpy_becomes_python():
    doc = {
        "p": np.float64(0.25),
        "nan": math.nan,
        "inf": np.float32(np.inf),
        "n": np.int64(3),
        "ok": np.bool_(True),
        "rates": np.array([1.5, np.nan, -np.inf]),
        "pairs": [(1, np.float64(2.0)), {"deep": [np.nan]}],
        7: "key",
        "s": "text",
        "none": None,
    }
    safe = json_safe(doc)
    text = json.dumps(safe, allow_nan=False)  # strict: raises on NaN / inf
    assert json.loads(text) == {
        "p": 0.25,
        "nan": None,
        "inf": None,
        "n": 3,
        "ok": True,
        "rates": [1.5, None, None],
        "pairs": [[1, 2.0], {"deep": [None]}],
        "7": "key",
        "s": "text",
        "none": None,
    }
    assert type(safe["p"]) is float and type(safe["n"]) is int and type(safe["ok"]) is bool
    assert doc["rates"][1] != doc["rates"][1]  # the input is left as it was


def test_finite_values_are_kept_exactly():
    values = np.random.default_rng(0).normal(size=100) * 10.0 ** np.arange(-50, 50)
    assert json.loads(json.dumps(json_safe(values), allow_nan=False)) == values.tolist()
