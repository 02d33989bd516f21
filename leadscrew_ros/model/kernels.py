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
"""

from __future__ import annotations

import numpy as np

from .friction import gamma, mu_o
from .modes import KIND_T, KIND_X, KIND_Y
from .parameters import ScrewParameters

X, Y, T = KIND_X, KIND_Y, KIND_T


def _blocks(n: int, entries: dict[tuple[int, int], np.ndarray]) -> np.ndarray:
    out = np.zeros((3, 3, n))
    for (a, b), v in entries.items():
        out[a, b] = v
    return out


def paper_kernels(theta: np.ndarray, beta: float, radius_m: float) -> dict[str, np.ndarray]:
    """Appendix A as printed ((A.3)-(A.8), the second "W5q" read as the matrix of qdot; README "Two formulations"), each (3, 3, len(theta))."""
    s, c, n = np.sin(theta), np.cos(theta), len(theta)
    sb2, cb2, R = np.sin(beta) ** 2, np.cos(beta) ** 2, radius_m
    return {
        "W1": _blocks(n, {(X, X): s * c * cb2, (X, Y): -(c ** 2 + s ** 2 * sb2),      # (A.3)
                          (Y, X): s ** 2 + c ** 2 * sb2, (Y, Y): -s * c * cb2}),
        "W2": _blocks(n, {(X, T): -R * c, (Y, T): -R * s,                            # (A.4)
                          (T, X): R * c * sb2, (T, Y): R * s * sb2}),
        "W3": _blocks(n, {(X, X): c ** 2 + s ** 2 * sb2, (X, Y): -s * c * cb2,        # (A.5)
                          (Y, X): -s * c * sb2, (Y, Y): c ** 2 * sb2,
                          (T, T): np.full(n, sb2)}),
        "W4": _blocks(n, {(X, T): -R * sb2 * s, (Y, T): R * sb2 * c,                 # (A.6)
                          (T, X): -R * sb2 * s, (T, Y): R * sb2 * c}),
        "W5q": _blocks(n, {(X, X): -s * c, (Y, Y): c * s, (X, Y): -s ** 2,            # (A.7)
                           (Y, X): c ** 2, (T, X): R * c, (T, Y): R * s}),
        "W5qdot": _blocks(n, {(X, X): -s ** 2, (Y, Y): c ** 2, (X, Y): -c * s,        # (A.8)
                              (Y, X): c * s, (T, X): R * s, (T, Y): R * c,
                              (X, T): -R * s, (Y, T): R * c, (T, T): np.full(n, R ** 2)}),
    }


def consistent_kernels(theta: np.ndarray, beta: float, radius_m: float) -> dict[str, np.ndarray]:
    """First-principles linearisation of the friction work (13) with (3)-(12).

    Contact point displacement per unit modal coordinate of kind a: w_a = i, j, R e_theta (14);
    its velocity perturbation from q is Omega k x w_a, from qdot w_a (3); sliding direction
    e = cos(beta) e_theta + sin(beta) k. Linearising f = -mu N_o Vc/|Vc| gives the kernels
    w_a.(I - e e)(k x w_b) (W1, W2), w_a.(I - e e) w_b (W3, W4), (e.w_a)(e.k x w_b)/cos^2 beta
    (W5q) and (e.w_a)(e.w_b)/cos^2 beta (W5qdot). tools/derive_consistent.py re-derives them
    symbolically and a test compares.
    """
    s, c, n = np.sin(theta), np.cos(theta), len(theta)
    zero, one = np.zeros(n), np.ones(n)
    sb, cb = np.sin(beta), np.cos(beta)
    w = np.array([[one, zero, zero], [zero, one, zero], [-radius_m * s, radius_m * c, zero]])
    kw = np.array([[zero, one, zero], [-one, zero, zero], [-radius_m * c, -radius_m * s, zero]])
    e = np.array([-cb * s, cb * c, np.full(n, sb)])                     # (3, n)
    ew, ekw = np.einsum("vn,avn->an", e, w), np.einsum("vn,avn->an", e, kw)
    proj_kw = np.einsum("avn,bvn->abn", w, kw) - ew[:, None] * ekw[None, :]
    proj_w = np.einsum("avn,bvn->abn", w, w) - ew[:, None] * ew[None, :]
    bend = np.zeros((3, 3, 1), bool)
    bend[:2, :2] = bend[T, T] = True                                     # W1/W3 vs W2/W4 split
    return {
        "W1": np.where(bend, proj_kw, 0.0), "W2": np.where(bend, 0.0, proj_kw),
        "W3": np.where(bend, proj_w, 0.0), "W4": np.where(bend, 0.0, proj_w),
        "W5q": ew[:, None] * ekw[None, :] / cb ** 2,
        "W5qdot": ew[:, None] * ew[None, :] / cb ** 2,
    }


KERNELS = {"paper": paper_kernels, "consistent": consistent_kernels}


def thread_factors(p: ScrewParameters, mu_o_value, speed_rad_s, load_n):
    """(c_f, c_5, d c / d mu_o) of the module docstring: the factors of the friction level and
    slope terms, and their derivative with respect to mu_o (the same for both; 0 for paper)."""
    tb = np.tan(p.helix_angle_rad)
    if p.formulation == "paper":
        return 1.0, 1.0 - tb ** 2, 0.0
    flank = np.where(load_n == 0, 1.0, np.sign(load_n)) * np.sign(speed_rad_s)   # (9)
    c = 1.0 / (1.0 + flank * mu_o_value * tb)
    return c, c, -flank * tb * c * c


def scales(p: ScrewParameters, speed_rad_s, load_n, alpha: float) -> dict[str, np.ndarray]:
    """Scalar factors of W1..W5qdot at operating points (broadcast over speed and load)."""
    speed = np.asarray(speed_rad_s, dtype=float)
    load = np.abs(np.asarray(load_n, dtype=float))
    m0, g = mu_o(p, speed), gamma(p, speed)
    c_f, c_5, _ = thread_factors(p, m0, speed, load_n)
    level = m0 * load / (alpha * p.radius_m) * c_f
    slope = g * load / alpha * c_5
    return {"W1": np.sign(speed) * level, "W2": np.sign(speed) * level,
            "W3": level / np.abs(speed), "W4": level / np.abs(speed),
            "W5q": speed * slope, "W5qdot": slope}
