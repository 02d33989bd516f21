# SPDX-License-Identifier: Apache-2.0
"""The `paper` formulation against Appendix A as printed, entry by entry.

test/data/appendix_a_printed.json holds (A.3)-(A.8) transcribed once from the paper: each
printed prefactor and every term of each integrand. The implemented friction matrix is
scale(Omega, F_z) * kernel(theta) (model/physics/kernels.py moves R and sin^2(beta) between the
two), so the test compares scale * kernel with prefactor * printed term, for every (row, column)
entry, at several theta, beta, R and operating points. Any changed sign or factor of one term
(e.g. of sin^2(beta) in W3[x x], which moves the band edge by only 0.2 %) fails here.
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from leadscrew_ros.model.physics.friction import gamma, mu_o
from leadscrew_ros.model.physics.kernels import KERNELS, scales
from leadscrew_ros.model.physics.modes import KIND_T, KIND_X, KIND_Y
from leadscrew_ros.model.physics.parameters import ScrewParameters

PRINTED = json.loads(
    (Path(__file__).parent / "data" / "appendix_a_printed.json").read_text(encoding="utf-8")
)["matrices"]
KIND = {"x": KIND_X, "y": KIND_Y, "0": KIND_T}
THETA = np.linspace(-3.0, 9.5, 23)  # covers every quadrant, more than a turn
GEOMETRIES = [
    (math.radians(deg), radius)
    for deg in (2.0, 4.76, 15.0, 33.0)
    for radius in (0.002, 0.005, 0.0137)
]
OPERATING = [(0.7, 35.0), (20.0, 200.0), (310.0, 1250.0)]  # (Omega rad/s, F_z N)
ALPHA = 7.3  # contact angle span, rad


def _evaluate(expr: str, **symbols) -> np.ndarray:
    names = {"sin": np.sin, "cos": np.cos, "tan": np.tan, "__builtins__": {}}
    return np.asarray(eval(expr, names, symbols), float)


def printed_integrand(name: str, theta: np.ndarray, beta: float, radius_m: float) -> np.ndarray:
    """(3, 3, len(theta)): the printed integrand of one matrix, rows = equations."""
    out = np.zeros((3, 3, theta.size))
    for row, col, coefficient in PRINTED[name]["terms"]:
        assert not out[KIND[row], KIND[col]].any(), f"{name}[{row} {col}] printed twice"
        out[KIND[row], KIND[col]] = _evaluate(coefficient, t=theta, b=beta, R=radius_m)
    return out


def test_transcription_is_complete():
    assert set(PRINTED) == {"W1", "W2", "W3", "W4", "W5q", "W5qdot"}
    assert [PRINTED[n]["equation"] for n in sorted(PRINTED)] == [
        "A.3",
        "A.4",
        "A.5",
        "A.6",
        "A.7",
        "A.8",
    ]
    assert sum(len(m["terms"]) for m in PRINTED.values()) == 4 + 4 + 5 + 4 + 6 + 9


@pytest.mark.parametrize("name", sorted(PRINTED))
@pytest.mark.parametrize("beta, radius_m", GEOMETRIES)
def test_paper_kernels_match_appendix_a_entry_by_entry(name, beta, radius_m):
    params = ScrewParameters(radius_m=radius_m, helix_angle_rad=beta)
    kernel = KERNELS["paper"](THETA, beta, radius_m)[name]
    printed = printed_integrand(name, THETA, beta, radius_m)
    for speed, load in OPERATING:
        scale = float(scales(params, speed, load, ALPHA)[name])
        prefactor = float(
            _evaluate(
                PRINTED[name]["prefactor"],
                mu=mu_o(params, speed),
                gamma=gamma(params, speed),
                F=load,
                Omega=speed,
                alpha=ALPHA,
                R=radius_m,
                b=beta,
            )
        )
        assert prefactor != 0.0
        for a in "xy0":
            for b in "xy0":
                np.testing.assert_allclose(
                    scale * kernel[KIND[a], KIND[b]],
                    prefactor * printed[KIND[a], KIND[b]],
                    rtol=1e-12,
                    atol=1e-12 * abs(prefactor),
                    err_msg=f"{name}[{a} {b}] ({PRINTED[name]['equation']}) at "
                    f"beta = {beta:.4f} rad, R = {radius_m} m, Omega = {speed} rad/s",
                )
