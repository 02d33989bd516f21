# SPDX-License-Identifier: Apache-2.0
"""Numbers in messages and parameter files: short, yet never rounded onto the limit they
violate; as YAML that reads back with its type."""

from __future__ import annotations

import json


def exact(value: float) -> str:
    """The shortest %g text of `value` that reads back as the same float.

    `exact(1.0000001e7)` is '1.0000001e+07' where '%g' prints '1e+07', which would make
    "1e+07 N exceeds 1e+07 N" out of a value just beyond a limit.
    """
    v = float(value)
    for digits in range(6, 18):
        text = f"{v:.{digits}g}"
        if float(text) == v:
            if "e" in f"{v:.6g}" and "e" not in text:  # 1.0000001e+07 beside 1e+07,
                text = f"{v:.{digits - 1}e}"  # not 10000001
            return text
    return repr(v)


def yaml_value(value: object) -> str:
    """A value as YAML that PyYAML and rcl read back with its type: floats always with a
    decimal point (ROS rejects an integer YAML value for a double parameter; YAML 1.1 reads
    '1e-05' as text), text quoted."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        text = repr(value)
        mantissa, e, exponent = text.partition("e")
        return text if "." in mantissa or not e else f"{mantissa}.0e{exponent}"
    if isinstance(value, str):
        return json.dumps(value)
    return str(value)
