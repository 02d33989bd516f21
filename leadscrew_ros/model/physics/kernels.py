# SPDX-License-Identifier: Apache-2.0
"""Contact kernels of the friction matrices W1..W5 for the two formulations.

Every friction matrix of eq. (27) has the form

    W = s(Omega, F_z) * integral over theta of  sum_ab k_ab(theta) [Phi_i^a Phi_j^b]  dtheta,

with a scalar scale s that depends on the operating point only and a kernel k_ab(theta) that
depends on the geometry only (a, b in x, y, 0 = torsion; row a is the equation). This module
holds both halves; `contact` integrates the kernels once per geometry and `assembly` rescales.

Common scale factors (derived in README "Physics"; the paper's printed prefactors map onto
them by moving R and sin^2(beta) into the kernels):

    W1, W2  : sign(Omega) mu_o |F_z| / (alpha R)   * c_f      stiffness, friction level
    W3, W4  : mu_o |F_z| / (alpha R |Omega|)       * c_f      damping, friction level
    W5q     : Omega gamma |F_z| / alpha            * c_5      stiffness, friction slope
    W5qdot  : gamma |F_z| / alpha                  * c_5      damping, friction slope

paper:      c_f = 1,                 c_5 = 1 - tan^2(beta)      (A.3)-(A.8) as printed
consistent: c_f = c_5 = 1 / (1 + s mu_o tan(beta)), s = sign(Omega F_z)   (9) with the flank

Reverse rotation and the other flank follow from the linearisation of (10): the matrices that
multiply Omega in the derivation (G, W1, W2, W5q) change sign with Omega, the others depend on
|Omega|; the normal traction is constant, so only |F_z| enters.

Every kernel entry is a product of at most two of sin(theta), cos(theta) and constants: a
trigonometric polynomial of degree 2, k_ab(theta) = sum_{m=-2..2} c_m e^{i m theta}.
`kernel_harmonics` gives the c_m, with which `contact` integrates in closed form.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .friction import SteadyFriction
from .modes import KIND_T, KIND_X, KIND_Y
from .parameters import ParamsLike

X, Y, T = KIND_X, KIND_Y, KIND_T


def _blocks(n: int, entries: dict[tuple[int, int], np.ndarray]) -> np.ndarray:
    out = np.zeros((3, 3, n))
    for (a, b), v in entries.items():
        out[a, b] = v
    return out


def paper_kernels(theta: np.ndarray, beta: float, radius_m: float) -> dict[str, np.ndarray]:
    """Appendix A as printed ((A.3)-(A.8), the second "W5q" read as the matrix of qdot; README
    "Two formulations"), each (3, 3, len(theta))."""
    return _paper(np.sin(theta), np.cos(theta), beta, radius_m)


def _paper(s: np.ndarray, c: np.ndarray, beta: float, radius_m: float) -> dict[str, np.ndarray]:
    """`paper_kernels` as polynomials in s = sin(theta), c = cos(theta)."""
    n = len(s)
    sb2, cb2, R = np.sin(beta) ** 2, np.cos(beta) ** 2, radius_m
    return {
        "W1": _blocks(
            n,
            {
                (X, X): s * c * cb2,
                (X, Y): -(c**2 + s**2 * sb2),  # (A.3)
                (Y, X): s**2 + c**2 * sb2,
                (Y, Y): -s * c * cb2,
            },
        ),
        "W2": _blocks(
            n,
            {
                (X, T): -R * c,
                (Y, T): -R * s,  # (A.4)
                (T, X): R * c * sb2,
                (T, Y): R * s * sb2,
            },
        ),
        "W3": _blocks(
            n,
            {
                (X, X): c**2 + s**2 * sb2,
                (X, Y): -s * c * cb2,  # (A.5)
                (Y, X): -s * c * sb2,
                (Y, Y): c**2 * sb2,
                (T, T): np.full(n, sb2),
            },
        ),
        "W4": _blocks(
            n,
            {
                (X, T): -R * sb2 * s,
                (Y, T): R * sb2 * c,  # (A.6)
                (T, X): -R * sb2 * s,
                (T, Y): R * sb2 * c,
            },
        ),
        "W5q": _blocks(
            n,
            {
                (X, X): -s * c,
                (Y, Y): c * s,
                (X, Y): -(s**2),  # (A.7)
                (Y, X): c**2,
                (T, X): R * c,
                (T, Y): R * s,
            },
        ),
        "W5qdot": _blocks(
            n,
            {
                (X, X): -(s**2),
                (Y, Y): c**2,
                (X, Y): -c * s,  # (A.8)
                (Y, X): c * s,
                (T, X): R * s,
                (T, Y): R * c,
                (X, T): -R * s,
                (Y, T): R * c,
                (T, T): np.full(n, R**2),
            },
        ),
    }


def consistent_kernels(theta: np.ndarray, beta: float, radius_m: float) -> dict[str, np.ndarray]:
    """First-principles linearisation of the friction work (13) with (3)-(12).

    Contact point displacement per unit modal coordinate of kind a: w_a = i, j, R e_theta (14);
    its velocity perturbation from q is Omega k x w_a, from qdot w_a (3); sliding direction
    e = cos(beta) e_theta + sin(beta) k. Linearising f = -mu N_o Vc/|Vc| gives the kernels
    w_a.(I - e e)(k x w_b) (W1, W2), w_a.(I - e e) w_b (W3, W4), (e.w_a)(e.k x w_b)/cos^2 beta
    (W5q) and (e.w_a)(e.w_b)/cos^2 beta (W5qdot). tools/derive_consistent.py re-derives them
    symbolically and a test compares. The components are taken in the frame (e_r, e_theta, k)
    of the contact point, where k x (u_r, u_theta, u_z) = (-u_theta, u_r, 0), and
    I - e e = e_r e_r + f f with f = -sin(beta) e_theta + cos(beta) k: no small difference of
    large terms at small beta, and each kernel a polynomial of degree 2 in sin, cos theta.
    """
    return _consistent(np.sin(theta), np.cos(theta), beta, radius_m)


def _consistent(
    s: np.ndarray, c: np.ndarray, beta: float, radius_m: float
) -> dict[str, np.ndarray]:
    """`consistent_kernels` as polynomials in s = sin(theta), c = cos(theta)."""
    zero, r = np.zeros(len(s)), np.full(len(s), radius_m)
    sb, cb = np.sin(beta), np.cos(beta)
    # i = c e_r - s e_theta, j = s e_r + c e_theta, R e_theta; rows a, components (r, theta, z)
    w = np.array([[c, -s, zero], [s, c, zero], [zero, r, zero]])
    kw = np.array([[s, c, zero], [-c, s, zero], [-r, zero, zero]])  # k x w_a
    ew, ekw = cb * w[:, 1] + sb * w[:, 2], cb * kw[:, 1] + sb * kw[:, 2]  # e . w_a
    fw, fkw = cb * w[:, 2] - sb * w[:, 1], cb * kw[:, 2] - sb * kw[:, 1]  # f . w_a
    proj_kw = w[:, None, 0] * kw[None, :, 0] + fw[:, None] * fkw[None, :]
    proj_w = w[:, None, 0] * w[None, :, 0] + fw[:, None] * fw[None, :]
    bend = np.zeros((3, 3, 1), bool)
    bend[:2, :2] = bend[T, T] = True  # W1/W3 vs W2/W4 split
    return {
        "W1": np.where(bend, proj_kw, 0.0),
        "W2": np.where(bend, 0.0, proj_kw),
        "W3": np.where(bend, proj_w, 0.0),
        "W4": np.where(bend, 0.0, proj_w),
        "W5q": ew[:, None] * ekw[None, :] / cb**2,
        "W5qdot": ew[:, None] * ew[None, :] / cb**2,
    }


KERNELS = {"paper": paper_kernels, "consistent": consistent_kernels}
MATRICES = ("W1", "W2", "W3", "W4", "W5q", "W5qdot")
HARMONICS = np.arange(-2, 3)  # m of e^{i m theta}: every kernel has degree <= 2
_POLYNOMIALS = {"paper": _paper, "consistent": _consistent}
# (s, c) where a polynomial of degree 2 in s and c is sampled to find its six coefficients;
# 0 and +-1 keep the products in the kernels exact
_S, _C = np.array([(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1), (1, 1)], float).T


def kernel_harmonics(formulation: str, beta: float, radius_m: float) -> np.ndarray:
    """Fourier coefficients of the kernels: k_ab(theta) = sum_m c[w, a, b, m] e^{i m theta}.

    Every kernel is a polynomial of degree 2 in s = sin(theta) and c = cos(theta),
    p00 + p10 s + p01 c + p20 s^2 + p11 s c + p02 c^2; its values at six points (s, c) give
    the p (exactly: the points make the kernels' products exact), and s^2 = (1 - cos 2 theta)
    / 2, s c = sin(2 theta) / 2, c^2 = (1 + cos 2 theta) / 2 the harmonics. A test checks
    them against the kernels at arbitrary theta.

    Parameters
    ----------
    formulation : str
        'paper' or 'consistent' (`KERNELS`).
    beta : float
        Helix angle [rad].
    radius_m : float
        Screw radius R [m].

    Returns
    -------
    numpy.ndarray
        Complex, shape (len(MATRICES), 3, 3, len(HARMONICS)): c for m = -2..2 (HARMONICS)
        of every matrix W in MATRICES order and block (a, b), in the kernel's unit.
    """
    k = _POLYNOMIALS[formulation](_S, _C, beta, radius_m)
    v = np.moveaxis(np.stack([k[name] for name in MATRICES]), -1, 0)  # (6, W, 3, 3)
    p00 = v[0]
    p10, p20 = (v[1] - v[2]) / 2, (v[1] + v[2]) / 2 - p00
    p01, p02 = (v[3] - v[4]) / 2, (v[3] + v[4]) / 2 - p00
    p11 = v[5] - p00 - p10 - p01 - p20 - p02
    c1, c2 = (p01 - 1j * p10) / 2, (p02 - p20 - 1j * p11) / 4  # a cos + b sin
    return np.stack([c2.conj(), c1.conj(), p00 + (p20 + p02) / 2 + 0j, c1, c2], axis=-1)


def thread_factors(
    p: ParamsLike, mu_o_value: ArrayLike, speed_rad_s: ArrayLike, load_n: ArrayLike
) -> tuple[Any, Any, Any]:
    """(c_f, c_5, d c / d mu_o) of the module docstring: the factors of the friction level and
    slope terms, and their derivative with respect to mu_o (the same for both; 0 for paper)."""
    tb = np.tan(p.helix_angle_rad)
    if p.formulation == "paper":
        return 1.0, 1.0 - tb**2, 0.0
    flank = np.where(load_n == 0, 1.0, np.sign(load_n)) * np.sign(speed_rad_s)  # (9)
    c = 1.0 / (1.0 + flank * mu_o_value * tb)
    return c, c, -flank * tb * c * c


def level_slope(
    p: ParamsLike,
    speed_rad_s: ArrayLike,
    load_n: ArrayLike,
    alpha: float,
    friction: SteadyFriction | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Friction level l = mu_o |F_z| c_f / (alpha R) (W1-W4) and friction slope
    s = gamma |F_z| c_5 / alpha (W5), broadcast over speed, load and the fields of `p` (arrays
    of scattered friction parameters too); `friction` the law of `p` when it is at hand
    (`SteadyFriction`: its speed-free factors computed once)."""
    if type(speed_rad_s) is float and type(load_n) is float:  # a live point: no 0-d arrays
        speed, load = speed_rad_s, abs(load_n)
    else:
        speed = np.asarray(speed_rad_s, dtype=float)
        load = np.abs(np.asarray(load_n, dtype=float))
    m0, g = (SteadyFriction(p) if friction is None else friction)(speed)
    c_f, c_5, _ = thread_factors(p, m0, speed, load_n)
    # the operating point's factors first: one operation on the samples each (paper)
    return m0 * (load / (alpha * p.radius_m) * c_f), g * (load / alpha * c_5)


def scales(
    p: ParamsLike, speed_rad_s: ArrayLike, load_n: ArrayLike, alpha: float
) -> dict[str, np.ndarray]:
    """Scalar factors of W1..W5qdot at operating points (broadcast over speed and load)."""
    speed = np.asarray(speed_rad_s, dtype=float)
    level, slope = level_slope(p, speed, load_n, alpha)
    w1, w3, w5q, w5qdot = coefficients(speed, level, slope)
    return {"W1": w1, "W2": w1, "W3": w3, "W4": w3, "W5q": w5q, "W5qdot": w5qdot}


def coefficients(speed_rad_s: Any, level: Any, slope: Any) -> tuple[Any, Any, Any, Any]:
    """The factors of (W1 = W2, W3 = W4, W5q, W5qdot) from the friction level and slope at
    the screw speed [rad/s] (`level_slope`; module docstring): floats for a float speed (a
    live point's state matrix), else arrays (at zero speed numpy's inf, as for arrays)."""
    if type(speed_rad_s) is float and speed_rad_s:
        sign = math.copysign(1.0, speed_rad_s)
        return sign * level, level / abs(speed_rad_s), speed_rad_s * slope, slope
    return (
        np.sign(speed_rad_s) * level,
        level / np.abs(speed_rad_s),
        speed_rad_s * slope,
        slope,
    )
