#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Symbolic first-principles linearisation of the contact friction (the `consistent` formulation).

Starts from the paper's kinematics and friction law, not from the printed appendix:
  contact velocity (3)-(5), (11) at r = R, with u, v, zeta the screw deflections;
  friction f = -mu(|Vc|) N_o Vc / |Vc| (10), mu from (12);
  normal traction from the axial load balance (6)-(9) on the loaded flank;
  virtual work (13) with the contact deflection (14).
For each pair of mode kinds (a, b) in {x, y, 0} it returns the stiffness and damping entries per
unit contact angle, K_ab(theta) = -dQ_a/dq_b and D_ab(theta) = -dQ_a/dqdot_b, which is what the
assumed-modes matrices integrate against [Phi_i^a Phi_j^b]. test/test_derivation.py compares
them with leadscrew_ros.model.physics.kernels (kernels * scales) at random points, both flanks
and both directions of rotation.

Run it to print the kernels:  python tools/derive_consistent.py
"""

from __future__ import annotations

from functools import cache

import sympy as sp

KINDS = ("x", "y", "0")
theta, beta, Omega = sp.symbols("theta beta Omega", real=True)
R = sp.Symbol("R", positive=True)
F, alpha, h = sp.symbols("F_z alpha h", real=True)
mu0, mu1 = sp.symbols("mu_o mu_prime", real=True)  # mu(|V0|) and dmu/d|V| at |V0|
flank = sp.Symbol("sigma", real=True)  # +1: loaded flank of (7)-(8); -1: other


def _frame():
    i, j, k = sp.Matrix([1, 0, 0]), sp.Matrix([0, 1, 0]), sp.Matrix([0, 0, 1])
    e_r = sp.Matrix([sp.cos(theta), sp.sin(theta), 0])
    e_t = sp.Matrix([-sp.sin(theta), sp.cos(theta), 0])
    return i, j, k, e_r, e_t


@cache
def derive() -> dict[str, sp.Matrix]:
    """Return {'K': 3x3, 'D': 3x3} per unit contact angle, and 'n' the normal force per radian."""
    i, j, k, e_r, e_t = _frame()
    x, y, z, xd, yd, zd = sp.symbols("u v zeta u_dot v_dot zeta_dot", real=True)
    # Contact velocity (3) with (2), (4), (5) at r = R: steady part plus perturbation.
    omega = Omega * k
    r_ba = R * e_r + x * i + y * j + R * z * e_t
    v_rel = xd * i + yd * j + R * zd * e_t
    v_c = R * Omega * sp.tan(beta) * k + v_rel + omega.cross(r_ba)
    speed = sp.sqrt(v_c.dot(v_c))
    # mu(|Vc|) to first order about the steady sliding speed |V0|.
    v0 = sp.sqrt(
        (v_c.subs({x: 0, y: 0, z: 0, xd: 0, yd: 0, zd: 0})).dot(
            v_c.subs({x: 0, y: 0, z: 0, xd: 0, yd: 0, zd: 0})
        )
    )
    mu = mu0 + mu1 * (speed - v0)
    # Normal traction from the axial load balance (6) on the flank with normal sigma*e_n (8).
    e_n = -sp.sin(beta) * e_t + sp.cos(beta) * k
    e_s0 = (v_c / speed).subs({x: 0, y: 0, z: 0, xd: 0, yd: 0, zd: 0})
    n_o = sp.Symbol("N_o", positive=True)
    area = h * R * alpha / sp.cos(beta)  # helix strip h x (R alpha / cos beta)
    load = area * ((-flank * n_o * e_n).dot(-k) + (-mu0 * n_o * e_s0).dot(-k))
    n_o_value = sp.solve(sp.Eq(load, F), n_o)[0]
    per_radian = n_o_value * h * R / sp.cos(beta)  # normal force per radian of helix
    # Generalised friction force per radian for each kind (13), (14).
    f = -mu * per_radian * v_c / speed
    w = {"x": i, "y": j, "0": R * e_t}
    coords = {"x": (x, xd), "y": (y, yd), "0": (z, zd)}
    zero = {s: 0 for s in (x, y, z, xd, yd, zd)}
    K, D = sp.zeros(3, 3), sp.zeros(3, 3)
    for a_idx, a in enumerate(KINDS):
        q_a = f.dot(w[a])
        for b_idx, b in enumerate(KINDS):
            q, qd = coords[b]
            K[a_idx, b_idx] = -sp.diff(q_a, q).subs(zero)
            D[a_idx, b_idx] = -sp.diff(q_a, qd).subs(zero)
    return {"K": K, "D": D, "n": per_radian}


def main() -> None:
    out = derive()
    pos = {Omega: sp.Symbol("Omega", positive=True), flank: 1, F: sp.Symbol("F_z", positive=True)}
    print(
        "normal force per radian (sigma = +1, Omega > 0):",
        sp.simplify(out["n"].subs(pos).replace(sp.Abs, lambda arg: arg)),
    )
    for name in ("K", "D"):
        for a_idx, a in enumerate(KINDS):
            for b_idx, b in enumerate(KINDS):
                expr = out[name][a_idx, b_idx].subs(pos).replace(sp.Abs, lambda arg: arg)
                expr = sp.factor(sp.simplify(expr))
                print(f"{name}[{a}{b}] =", expr)


if __name__ == "__main__":
    main()
