# SPDX-License-Identifier: Apache-2.0
"""The `consistent` kernels equal the symbolic linearisation of tools/derive_consistent.py, and
the printed appendix (`paper`) differs from it exactly where doc/theory/formulations.md says."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from leadscrew_ros.model import ScrewParameters
from leadscrew_ros.model.physics.contact import contact_angles
from leadscrew_ros.model.physics.friction import mu_o, sliding_speed
from leadscrew_ros.model.physics.kernels import consistent_kernels, paper_kernels, scales

_spec = importlib.util.spec_from_file_location(
    "derive_consistent", Path(__file__).parents[1] / "tools" / "derive_consistent.py"
)
derivation = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(derivation)

STIFFNESS, DAMPING = ("W1", "W2", "W5q"), ("W3", "W4", "W5qdot")


@pytest.fixture(scope="module")
def symbolic():
    d = derivation.derive()
    args = (
        derivation.theta,
        derivation.beta,
        derivation.R,
        derivation.Omega,
        derivation.F,
        derivation.alpha,
        derivation.h,
        derivation.mu0,
        derivation.mu1,
        derivation.flank,
    )
    return {
        name: [[sp.lambdify(args, d[name][a, b], "numpy") for b in range(3)] for a in range(3)]
        for name in ("K", "D")
    }


def _numeric(p: ScrewParameters, speed: float, load: float, theta: np.ndarray):
    alpha = contact_angles(p)[1]
    s = scales(p, speed, load, alpha)
    k = consistent_kernels(theta, p.helix_angle_rad, p.radius_m)
    return (sum(float(s[n]) * k[n] for n in STIFFNESS), sum(float(s[n]) * k[n] for n in DAMPING))


CASES = [  # (R, beta deg, speed, load, mu_s, mu_k, d)
    (0.005, 5.0, 20.0, 200.0, 0.25, 0.20, 10.0),
    (0.005, 5.0, -20.0, 200.0, 0.25, 0.20, 10.0),  # reverse rotation
    (0.005, 5.0, 20.0, -200.0, 0.25, 0.20, 10.0),  # other flank
    (0.005, 5.0, -35.0, -80.0, 0.25, 0.20, 10.0),
    (0.008, 12.0, 3.0, 650.0, 0.40, 0.15, 30.0),
    (0.003, 30.0, -150.0, 50.0, 0.9, 0.6, 2.0),  # large helix angle, overhauling
]


@pytest.mark.parametrize("R, beta_deg, speed, load, mus, muk, d", CASES)
def test_consistent_kernels_equal_symbolic_linearisation(
    symbolic, R, beta_deg, speed, load, mus, muk, d
):
    p = ScrewParameters(
        radius_m=R,
        helix_angle_rad=math.radians(beta_deg),
        mu_static=mus,
        mu_kinetic=muk,
        friction_decay_s_m=d,
        formulation="consistent",
    )
    theta = np.linspace(0.3, 40.0, 57)
    K_num, D_num = _numeric(p, speed, load, theta)
    m0 = float(mu_o(p, speed))
    m1 = -(mus - muk) * d * math.exp(-d * float(sliding_speed(p, speed)))  # dmu/d|V|
    alpha = contact_angles(p)[1]
    args = (theta, p.helix_angle_rad, R, speed, load, alpha, 1e-3, m0, m1, math.copysign(1, load))
    for name, num in (("K", K_num), ("D", D_num)):
        ref = np.array(
            [[np.broadcast_to(f(*args), theta.shape) for f in row] for row in symbolic[name]],
            dtype=float,
        )
        scale = np.abs(ref).max()
        np.testing.assert_allclose(num, ref, rtol=1e-10, atol=1e-12 * scale)


def test_paper_kernels_differ_from_first_principles_only_in_w3_and_w5qdot():
    beta, R = math.radians(5.0), 0.005
    theta = np.linspace(0.1, 20.0, 101)
    paper, consistent = paper_kernels(theta, beta, R), consistent_kernels(theta, beta, R)
    for name in ("W1", "W2", "W4", "W5q"):
        np.testing.assert_allclose(paper[name], consistent[name], atol=1e-15)
    sb2 = math.sin(beta) ** 2
    s, c = np.sin(theta), np.cos(theta)
    X, Y, T = 0, 1, 2
    # W3: [y y] lost sin^2(theta), [0 0] lost R^2, [x y] and [y x] differ
    # (doc/theory/formulations.md).
    np.testing.assert_allclose(consistent["W3"][Y, Y] - paper["W3"][Y, Y], s**2, atol=1e-15)
    np.testing.assert_allclose(paper["W3"][T, T] / consistent["W3"][T, T], 1 / R**2)
    assert not np.allclose(paper["W3"][X, Y], consistent["W3"][X, Y])
    assert not np.allclose(paper["W3"][Y, X], consistent["W3"][Y, X])
    # W5qdot: the first-principles term is the symmetric rank-one (e.w_a)(e.w_b); the printed
    # one flips the sign of [x x], [y x] and [0 x].
    for a, b in ((X, X), (Y, X), (T, X)):
        np.testing.assert_allclose(paper["W5qdot"][a, b], -consistent["W5qdot"][a, b], atol=1e-15)
    for a, b in ((Y, Y), (X, Y), (X, T), (Y, T), (T, Y), (T, T)):
        np.testing.assert_allclose(paper["W5qdot"][a, b], consistent["W5qdot"][a, b], atol=1e-15)
    # the printed W3 [y y] keeps only the thread's share, cos^2(theta) sin^2(beta)
    np.testing.assert_allclose(paper["W3"][Y, Y], c**2 * sb2, atol=1e-15)
