# SPDX-License-Identifier: Apache-2.0
"""The prediction as it was computed before issue 23 (commit 29b3546), kept here only as the
reference of test_fast_path.py: one LAPACK dgeev with left and right vectors, the labels from
the packed right vectors, P(squeak) from the first-order expansion with LAPACK's left vectors
(normalised y^H x = 1) and the modes pruned by |rate| x reach of the scatter. It uses only the
model's public parts (state matrix, contact units, samples, the friction law) and LAPACK, so
the package's faster path is compared with an independent implementation.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from scipy.linalg import lapack

from leadscrew_ros.model import SqueakModel
from leadscrew_ros.model.physics.kernels import level_slope

IMAG_TOL, GROWTH_TOL = 1e-9, 1e-10  # as stability had them


def reference(model: SqueakModel, speed: float, load: float) -> tuple:
    """(modes, divergence rates, P, stderr) of a valid operating point as the code before issue
    23 gave them; modes as (label, frequency_hz, growth_rate, damping_ratio, unstable)."""
    a = model.state_matrix(speed, load)
    wr, wi, vl, vr, info = lapack.dgeev(a, compute_vl=1, compute_vr=1)
    assert info == 0
    lam_all = wr + 1j * wi
    osc = np.flatnonzero(wi > IMAG_TOL * np.abs(lam_all))
    lam = lam_all[osc]
    x = vr[:, osc] + 1j * vr[:, osc + 1]
    n = model.geometry.n
    re, im = vr[:n, osc], vr[:n, osc + 1]
    dominant = (re * re + im * im).argmax(axis=0)
    order = np.argsort(-lam.real, kind="stable")
    modes = tuple(
        (model.labels[d], i / (2 * math.pi), r, -r / g, r > GROWTH_TOL * g)
        for d, r, i, g in zip(
            dominant[order].tolist(),
            lam[order].real.tolist(),
            lam[order].imag.tolist(),
            np.abs(lam[order]).tolist(),
            strict=True,
        )
    )
    mag = np.abs(lam_all)
    real = lam_all.real[
        (np.abs(lam_all.imag) <= IMAG_TOL * mag) & (lam_all.real > GROWTH_TOL * mag)
    ]
    divergence = tuple(sorted(real.tolist(), reverse=True))
    if not model.scatter.names:
        return modes, divergence, float(any(m[4] for m in modes)), None
    y_h = (vl[:, osc] + 1j * vl[:, osc + 1]).conj().T
    y_h = y_h / np.einsum("ij,ji->i", y_h, x)[:, None]
    hits = _margins(model, speed, load, lam, x, y_h) > 0
    per = hits.reshape(model.samples.u.shape[:2])
    share = [c / per.shape[1] for c in np.count_nonzero(per, axis=1).tolist()]
    mean = sum(share) / len(share)
    var = sum((s - mean) ** 2 for s in share) / (len(share) - 1)
    return modes, divergence, mean, math.sqrt(var / len(share))


def _margins(
    model: SqueakModel, speed: float, load: float, lam: np.ndarray, x: np.ndarray, y_h: np.ndarray
) -> np.ndarray:
    """Per sample the largest expanded growth beyond the squeak threshold over the modes whose
    |rate| x reach can reach it (-inf where none can)."""
    p, g, n = model.params, model.geometry, model.geometry.n
    values = {k: v.ravel() for k, v in model.scatter.values(p, model.samples.u).items()}
    count = model.samples.count
    friction = {
        k: np.broadcast_to(values.get(k, getattr(p, k)), (count,))
        for k in ("mu_static", "mu_kinetic", "friction_decay_s_m")
    }
    damping = np.broadcast_to(
        values.get("modal_damping", p.modal_damping) - p.modal_damping, (count,)
    )
    sampled = SimpleNamespace(**{**p.as_dict(), **friction})
    unit_damping = np.zeros((n, 2 * n))
    unit_damping[np.arange(n), n + np.arange(n)] = -2 * g.basis.omega_rad_s
    units = np.concatenate([-g.lower_half_units[:4].reshape(4 * n, 2 * n), unit_damping]).astype(
        complex
    )
    change = np.empty((3, count))
    change[2] = damping
    level0, slope0 = level_slope(p, speed, load, g.contact.alpha)
    level, slope = level_slope(sampled, speed, load, g.contact.alpha)
    change[0], change[1] = level - level0, slope - slope0
    r = np.einsum("ij,kji->ki", y_h[:, n:], (units @ x).reshape(5, n, -1)).real
    rates = (
        np.array(
            [
                [math.copysign(1.0, speed), 0.0, 1.0 / abs(speed), 0.0, 0.0],
                [0.0, speed, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 0.0, 1.0],
            ]
        )
        @ r
    )
    threshold = GROWTH_TOL * np.abs(lam) - lam.real
    reach = [abs(change[0]).max(), abs(change[1]).max(), float(np.abs(damping).max())]
    candidates = np.flatnonzero(np.dot(reach, np.abs(rates)) > threshold)
    if not len(candidates):
        return np.full(count, -np.inf)
    growth = rates[:, candidates].T @ change - threshold[candidates, None]
    return growth.max(axis=0)
