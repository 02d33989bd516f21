# SPDX-License-Identifier: Apache-2.0
"""Eigenvalue sensitivities of (27): how the least-stable mode moves with each parameter.

For a simple eigenvalue lambda of the state matrix A with right and left eigenvectors x, y
(A x = lambda x, y^H A = lambda y^H):

    d lambda / dp = y^H (dA/dp) x / (y^H x)

dA/dp is analytic for the parameters that do not change the geometry. They enter A only through
the scale factors of `kernels.scales` (through mu_o and gamma of the friction law (12), (A.10),
(A.11)), the speed terms (G = Omega G_1, -Omega^2 I) and the damping diagonal -2 xi omega (A.1):

    dA/dp = -sum_k (d s_k / dp) [0; U_k]   (+ speed and damping terms)

with U_k the precomputed unit matrices of `Geometry.lower_half_units`. Geometry parameters
(radius, helix angle, nut position and length) change the modes and the contact integrals:
their dA/dp is a central difference of the state matrix (two geometries), the eigenvector
formula is the same. Reported as d(growth rate)/d(ln p) = p Re(d lambda/dp) [1/s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..physics.friction import gamma, mu_o, sliding_speed
from ..physics.kernels import scales, thread_factors
from ..squeak_model import SqueakModel, Validity, check_operating_point
from ..uncertainty.perturbation import EigenPairs, geometry_derivative

FRICTION = ("mu_static", "mu_kinetic", "friction_decay_s_m")
GEOMETRY = ("radius_m", "helix_angle_rad", "nut_position_m", "nut_length_m")


@dataclass(frozen=True)
class Sensitivity:
    """The least-stable oscillatory mode and its growth-rate derivatives.

    Attributes
    ----------
    eigenvalue : complex
        lambda of the mode [1/s] (Im > 0).
    growth_per_log : dict of str to float
        Parameter (a `ScrewParameters` field, or 'speed_rad_s' / 'load_n') -> d Re(lambda) /
        d ln p [1/s]: the change of growth rate for a relative change of p.
    """

    eigenvalue: complex
    growth_per_log: dict[str, float]


def _scale_derivatives(model: SqueakModel, speed: float, load: float) -> dict[str, np.ndarray]:
    """d s / dp of the coefficient vector (W1, W5q, W3, W5qdot, Omega) of
    `Geometry.state_matrices`, for the friction parameters, speed and load."""
    p, alpha = model.params, model.geometry.contact.alpha
    ms, mk, d = p.mu_static, p.mu_kinetic, p.friction_decay_s_m
    cb = math.cos(p.helix_angle_rad)
    v = float(sliding_speed(p, speed))
    dv_dw = p.radius_m * math.copysign(1.0, speed) / cb  # d|Vc|/dOmega
    e = math.exp(-d * v)
    m0, g = float(mu_o(p, speed)), float(gamma(p, speed))  # (12), (A.11)
    # (d mu_o, d gamma) per parameter: the friction law differentiated
    dm = {
        "mu_static": (e, -d * e * cb),
        "mu_kinetic": (1 - e, d * e * cb),
        "friction_decay_s_m": (-(ms - mk) * v * e, -(ms - mk) * cb * e * (1 - d * v)),
        "speed_rad_s": (-(ms - mk) * d * e * dv_dw, (ms - mk) * d * d * e * cb * dv_dw),
    }
    f = abs(load)
    c_f, c_5, dc = (float(c) for c in thread_factors(p, m0, speed, load))
    s = scales(p, speed, load, alpha)
    level, slope = float(s["W3"]) * abs(speed), float(s["W5qdot"])
    sgn, w = math.copysign(1.0, speed), abs(speed)

    def coef(d_level, d_slope, d_speed=0.0):
        return np.array(
            [
                sgn * d_level,
                speed * d_slope + d_speed * slope,
                d_level / w - d_speed * sgn * level / (w * w),
                d_slope,
                d_speed,
            ]
        )

    out = {}
    for name, (d_m0, d_g) in dm.items():
        d_level = f / (alpha * p.radius_m) * (c_f + m0 * dc) * d_m0
        d_slope = f / alpha * (c_5 * d_g + g * dc * d_m0)
        out[name] = coef(d_level, d_slope, 1.0 if name == "speed_rad_s" else 0.0)
    out["load_n"] = coef(level / load, slope / load) if load else coef(0.0, 0.0)
    return out


def mode_derivatives(
    model: SqueakModel, speed: float, load: float, geometry: bool = True
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Oscillatory eigenvalues (Im > 0) and d lambda / d ln p of each, per parameter.

    Parameters
    ----------
    model : SqueakModel
        The model at the nominal parameters.
    speed, load : float
        A valid operating point [rad/s], [N].
    geometry : bool
        Also the geometry parameters (two geometries each).

    Returns
    -------
    lam : numpy.ndarray
        Oscillatory eigenvalues [1/s], shape (M,).
    derivatives : dict of str to numpy.ndarray
        Parameter -> d lambda / d ln p [1/s], complex, shape (M,).
    """
    pairs, p = EigenPairs.solve(model.geometry, speed, load), model.params
    out = {}
    for name, dc in _scale_derivatives(model, speed, load).items():
        dl = pairs.coefficient_rate(dc)
        if name == "speed_rad_s":
            dl = dl + pairs.speed_rate_of_stiffness()
        value = speed if name == "speed_rad_s" else load if name == "load_n" else getattr(p, name)
        out[name] = value * dl
    out["modal_damping"] = p.modal_damping * pairs.damping_rate()
    if geometry:
        for name in GEOMETRY:
            out[name] = getattr(p, name) * pairs.matrix_rate(
                geometry_derivative(p, name, speed, load)
            )
    return pairs.lam, out


def sensitivities(
    model: SqueakModel, speed_rad_s: float, load_n: float, geometry: bool = True
) -> Sensitivity | None:
    """d(growth rate)/d(ln p) of the least-stable oscillatory mode.

    Parameters
    ----------
    model : SqueakModel
        The model at the nominal parameters.
    speed_rad_s, load_n : float
        Operating point [rad/s], [N].
    geometry : bool
        Also the geometry parameters (radius, helix angle, nut position and length), which
        rebuild the geometry twice each.

    Returns
    -------
    Sensitivity or None
        None outside the model's validity.
    """
    speed, load = check_operating_point(speed_rad_s, load_n)
    if model.validity(speed, load)[0] is not Validity.OK:
        return None
    lam, derivatives = mode_derivatives(model, speed, load, geometry)
    k = int(np.argmax(lam.real))
    return Sensitivity(complex(lam[k]), {name: float(d[k].real) for name, d in derivatives.items()})
