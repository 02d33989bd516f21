# SPDX-License-Identifier: Apache-2.0
"""The prior of the calibrated parameters: the model's scatter around its nominal values.

The prior is the unit-to-unit scatter (`uncertainty.scatter`) in the standardised
coordinates u of `Scatter.values`:

    normal:     theta = theta0 (1 + s u)        log-normal: theta = theta0 exp(s u)

with u ~ N(0, widen^2) independently per name, truncated to the valid domain
(`scatter.valid_mask`: field ranges, mu_s >= mu_k). `widen` = 1 is the prior itself; the
per-unit sampling runs under an interim prior widened by `SamplerSettings.prior_widen` so a
unit's posterior is not pinned to the prior's centre (the population step divides it out).
Sampling in u keeps every name on the scale of its prior SD, and a log-normal name in ln.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..physics.parameters import ParameterError, ScrewParameters
from ..uncertainty.scatter import LOG_NORMAL, Scatter, scatterable, valid_mask

# What `calibrate` calibrates by default: the fields of the default scatter.
DEFAULT_NAMES = ("mu_static", "mu_kinetic", "friction_decay_s_m", "modal_damping")
FRICTION = ("mu_static", "mu_kinetic", "friction_decay_s_m")  # through the level and slope
DAMPING = "modal_damping"  # through the damping ratio
# Fields that are an operating point of the log (given per frame), never calibrated.
NOT_CALIBRATED = frozenset({"nut_position_m"})
# The interim prior's widening (SamplerSettings.prior_widen): a population a prior SD or two
# from the nominal values then lies within one interim SD.
INTERIM_WIDEN = 2.0
_MAX_REDRAW_ROUNDS = 50


def check_names(names: Sequence[str]) -> tuple[str, ...]:
    """`names` as a tuple if they can be calibrated (scatterable, distinct, at least one).

    Raises
    ------
    ParameterError
        Naming the first name that cannot be calibrated.
    """
    names = tuple(names)
    if not names:
        raise ParameterError("nothing to calibrate: give at least one --calibrate NAME")
    for name in names:
        if name in NOT_CALIBRATED:
            raise ParameterError(
                f"--calibrate {name}: the log gives it per frame (an operating point); "
                "it cannot be calibrated"
            )
        if name not in scatterable():
            raise ParameterError(
                f"--calibrate {name}: not a scatterable parameter; one of "
                f"{', '.join(n for n in scatterable() if n not in NOT_CALIBRATED)}"
            )
    if len(set(names)) != len(names):
        raise ParameterError(f"--calibrate names a parameter twice: {', '.join(names)}")
    return names


class Prior:
    """Independent normal / log-normal priors of `names` around `nominal` (module docstring).

    Parameters
    ----------
    nominal : ScrewParameters
        The prior's centre theta0 (and the values of every other field).
    scatter : Scatter
        The prior SDs: relative SD (normal) or SD of ln (log-normal, `scatter.LOG_NORMAL`).
    names : sequence of str
        The calibrated parameters, in the order of theta's columns.
    widen : float
        Factor on every SD (1: the prior; > 1: an interim prior).

    Raises
    ------
    ParameterError
        A name that cannot be calibrated, or one without a prior SD in `scatter` (then the
        message asks for ``--scatter NAME=SD``).

    Attributes
    ----------
    names : tuple of str
        The calibrated parameters.
    nominal : ScrewParameters
        The centre.
    theta0 : numpy.ndarray
        (D,) the centre's values of `names`, in the fields' units.
    sd : numpy.ndarray
        (D,) the scatter's SDs (before widening), dimensionless.
    log : numpy.ndarray
        (D,) bool: log-normal names.
    widen : float
        The widening factor.
    """

    def __init__(
        self, nominal: ScrewParameters, scatter: Scatter, names: Sequence[str], widen: float = 1.0
    ):
        self.names = check_names(names)
        missing = [n for n in self.names if n not in scatter.sd]
        if missing:
            raise ParameterError(
                f"no prior scatter for {', '.join(missing)}: give "
                + " ".join(f"--scatter {n}=SD" for n in missing)
                + " (relative SD, or SD of ln for "
                + ", ".join(sorted(LOG_NORMAL))
                + ")"
            )
        if not (math.isfinite(widen) and widen > 0):
            raise ParameterError(f"prior widening = {widen!r} must be a number > 0")
        self.nominal, self.scatter, self.widen = nominal, scatter, float(widen)
        self.theta0 = np.array([float(getattr(nominal, n)) for n in self.names])
        self.sd = np.array([scatter.sd[n] for n in self.names])
        self.log = np.array([n in LOG_NORMAL for n in self.names])

    def widened(self, factor: float) -> Prior:
        """The prior with every SD `factor` times wider (an interim prior).

        Parameters
        ----------
        factor : float
            Factor > 0.

        Returns
        -------
        Prior
            Same centre and names.
        """
        return Prior(self.nominal, self.scatter, self.names, self.widen * factor)

    @property
    def field_sd(self) -> np.ndarray:
        """(D,) the prior SD of each name (widened): in the field's unit for a normal name,
        of ln for a log-normal one."""
        return self.widen * np.where(self.log, self.sd, self.sd * self.theta0)

    def to_u(self, theta: np.ndarray) -> np.ndarray:
        """Standardised coordinates u of values theta (..., D) in the fields' units.

        Parameters
        ----------
        theta : numpy.ndarray
            (..., D) values.

        Returns
        -------
        numpy.ndarray
            (..., D) u (not divided by `widen`: u ~ N(0, widen^2)).
        """
        theta = np.asarray(theta, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(
                self.log,
                np.log(theta / self.theta0) / self.sd,
                (theta / self.theta0 - 1.0) / self.sd,
            )

    def from_u(self, u: np.ndarray) -> np.ndarray:
        """Values theta (..., D) in the fields' units at standardised coordinates u.

        Parameters
        ----------
        u : numpy.ndarray
            (..., D) standardised coordinates.

        Returns
        -------
        numpy.ndarray
            (..., D) theta, as `Scatter.values` gives them.
        """
        su = self.sd * np.asarray(u, float)
        return self.theta0 * np.where(self.log, np.exp(su), 1.0 + su)

    def valid(self, theta: np.ndarray) -> np.ndarray:
        """(W,) bool: the rows of theta (W, D) inside the valid domain (`scatter.valid_mask`).

        Parameters
        ----------
        theta : numpy.ndarray
            (W, D) values in the fields' units.

        Returns
        -------
        numpy.ndarray
            (W,) bool.
        """
        theta = np.asarray(theta, float)
        return valid_mask(self.nominal, dict(zip(self.names, theta.T, strict=True))) & np.all(
            np.isfinite(theta), axis=-1
        )

    def log_density_u(self, u: np.ndarray) -> np.ndarray:
        """Log density of u (W, D) up to a constant (the truncation's normaliser is constant),
        -inf outside the valid domain.

        Parameters
        ----------
        u : numpy.ndarray
            (W, D) standardised coordinates.

        Returns
        -------
        numpy.ndarray
            (W,) log density.
        """
        u = np.asarray(u, float)
        out = -0.5 * np.sum((u / self.widen) ** 2, axis=-1)
        return np.where(self.valid(self.from_u(u)), out, -np.inf)

    def draw(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """Draws of u (count, D) inside the valid domain (outside ones redrawn).

        Parameters
        ----------
        count : int
            Number of draws.
        rng : numpy.random.Generator
            The source of randomness.

        Returns
        -------
        numpy.ndarray
            (count, D) standardised coordinates.

        Raises
        ------
        ParameterError
            The valid domain is (almost) never hit.
        """
        u = self.widen * rng.standard_normal((count, len(self.names)))
        for _ in range(_MAX_REDRAW_ROUNDS):
            bad = ~self.valid(self.from_u(u))
            if not bad.any():
                return u
            u[bad] = self.widen * rng.standard_normal((int(bad.sum()), len(self.names)))
        raise ParameterError("the prior leaves the valid parameter domain too often")

    def values(self, theta_row: np.ndarray) -> ScrewParameters:
        """The nominal parameters with `names` set to one row of theta (validated).

        Parameters
        ----------
        theta_row : numpy.ndarray
            (D,) values in the fields' units.

        Returns
        -------
        ScrewParameters
            A validated parameter set.

        Raises
        ------
        ParameterError
            The values are not allowed.
        """
        return self.nominal.with_(
            **{n: float(v) for n, v in zip(self.names, theta_row, strict=True)}
        )
