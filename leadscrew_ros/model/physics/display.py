# SPDX-License-Identifier: Apache-2.0
"""Numbers in messages: short, yet never rounded onto the limit they violate."""

from __future__ import annotations


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
