# SPDX-License-Identifier: Apache-2.0
"""Velocity-dependent friction law (12) and its values at steady sliding (A.10, A.11)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .parameters import ParamsLike


def friction_coefficient(p: ParamsLike, sliding_speed_m_s: ArrayLike) -> np.ndarray:
    """mu(|Vc|) = mu_k + (mu_s - mu_k) exp(-d |Vc|)  (12)."""
    v = np.abs(sliding_speed_m_s)
    return p.mu_kinetic + (p.mu_static - p.mu_kinetic) * np.exp(-p.friction_decay_s_m * v)


def friction_slope(p: ParamsLike, sliding_speed_m_s: ArrayLike) -> np.ndarray:
    """Slope of (12), s/m: dmu/d|Vc| = -d (mu_s - mu_k) exp(-d |Vc|), steepest at rest."""
    v = np.abs(sliding_speed_m_s)
    return -p.friction_decay_s_m * (p.mu_static - p.mu_kinetic) * np.exp(-p.friction_decay_s_m * v)


def sliding_speed(p: ParamsLike, speed_rad_s: ArrayLike) -> np.ndarray:
    """Steady contact sliding speed |Vc| = R |Omega| / cos(beta), m/s (from (4), (11))."""
    return p.radius_m * np.abs(speed_rad_s) / np.cos(p.helix_angle_rad)


def steady_friction(p: ParamsLike, speed_rad_s: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(mu_o, gamma) at the steady sliding speed |Vc| = R |Omega| / cos(beta) (A.10, A.11;
    README "Physics"): the friction coefficient (12) there and the slope term
    gamma = cos(beta) dmu/d|Vc| [s/m], from one exponential (`SteadyFriction`)."""
    return SteadyFriction(p)(speed_rad_s)


class SteadyFriction:
    """`steady_friction` of fixed parameters (scalars, or arrays of scatter samples) as a
    function of the screw speed: the factors of (12) that do not depend on the speed are
    computed once (the live P(squeak) evaluates the law for its 1024 samples at every
    operating point: three array operations and one exponential there).

    Parameters
    ----------
    p : ScrewParameters or SimpleNamespace
        The friction fields, the radius and the helix angle (arrays broadcast).
    """

    __slots__ = ("mu_kinetic", "drop", "exponent", "slope")

    def __init__(self, p: ParamsLike):
        cos_beta = np.cos(p.helix_angle_rad)
        self.mu_kinetic = p.mu_kinetic
        self.drop = p.mu_static - p.mu_kinetic
        # e = exp(-d |Vc|) = exp(exponent |Omega|), |Vc| = R |Omega| / cos(beta)
        self.exponent = -p.friction_decay_s_m * p.radius_m / cos_beta  # [s/rad]
        self.slope = -self.drop * p.friction_decay_s_m * cos_beta  # gamma / e [s/m]

    def __call__(self, speed_rad_s: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(mu_o, gamma) at the screw speed(s) [rad/s] (broadcast against the parameters)."""
        w = abs(speed_rad_s) if type(speed_rad_s) is float else np.abs(speed_rad_s)
        e = np.exp(self.exponent * w)
        return self.mu_kinetic + self.drop * e, self.slope * e


def mu_o(p: ParamsLike, speed_rad_s: ArrayLike) -> np.ndarray:
    """Friction coefficient at the steady sliding speed (A.10)."""
    return steady_friction(p, speed_rad_s)[0]


def gamma(p: ParamsLike, speed_rad_s: ArrayLike) -> np.ndarray:
    """Friction slope term gamma = cos(beta) dmu/d|Vc| at steady sliding, s/m  (A.11)."""
    return steady_friction(p, speed_rad_s)[1]
