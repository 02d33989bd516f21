# SPDX-License-Identifier: Apache-2.0
"""Unit-to-unit scatter of the model parameters and samples of it.

A scattered parameter p is drawn from its nominal value p0 (the `ScrewParameters` field) as

    normal:     p = p0 (1 + s u)          s = relative standard deviation
    log-normal: p = p0 exp(s u)           s = standard deviation of ln p

with u standard normal, independent per parameter. Default scatter (assumptions, README
"Squeak probability"): mu_static and mu_kinetic normal, s = 0.05; friction_decay_s_m normal,
s = 0.10; modal_damping log-normal, s = 0.35; every other parameter fixed. A sample outside the
valid domain (mu_s >= mu_k >= 0, positive values, any field range) is redrawn.

Samples are scrambled Sobol points (`scipy.stats.qmc`) in independent replicates, so an
estimate over them has a standard error from the spread of the replicates.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, make_dataclass
from functools import lru_cache
from types import MappingProxyType, SimpleNamespace
from typing import Any

import numpy as np
from scipy.special import ndtri

from ..physics.metadata import check, setting
from ..physics.parameters import ParameterError, ParamsLike, ScrewParameters

LOG_NORMAL = frozenset({"modal_damping"})  # positive, with a spread of a factor
DEFAULT_SCATTER = MappingProxyType(
    {"mu_static": 0.05, "mu_kinetic": 0.05, "friction_decay_s_m": 0.10, "modal_damping": 0.35}
)
# Fields that are operating conditions or switches, not properties of a drive.
NOT_SCATTERED = frozenset(
    {"axial_load_n", "n_bending", "n_torsion", "formulation", "min_speed_rad_s"}
)
MAX_SCATTER = 1.0  # relative SD (or SD of ln) at most
REPLICATES = 8  # independent scramblings per estimate
LIVE_SAMPLES = 1024  # samples of the live estimate (default)
_MAX_REDRAW_ROUNDS = 20
# The cross-field rules of ScrewParameters that a sample must keep (`valid_mask`).
_RULES = (
    (("mu_static", "mu_kinetic"), lambda get: get("mu_static") >= get("mu_kinetic")),
    (
        ("nut_position_m", "nut_length_m", "length_m"),
        lambda get: get("nut_position_m") + get("nut_length_m") <= get("length_m"),
    ),
    (("thread_height_m", "radius_m"), lambda get: get("thread_height_m") < get("radius_m")),
)


def scatterable() -> tuple[str, ...]:
    """Names of the parameters that can carry a scatter (numeric properties of a drive)."""
    return tuple(f.name for f in fields(ScrewParameters) if f.name not in NOT_SCATTERED)


@dataclass(frozen=True)
class Scatter:
    """Relative standard deviations of the scattered parameters (0 or absent: fixed).

    Parameters
    ----------
    sd : mapping of str to float
        Parameter field name -> relative SD (normal) or SD of ln p (log-normal, see
        `LOG_NORMAL`), dimensionless, in [0, MAX_SCATTER].
    """

    sd: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_SCATTER))

    def __post_init__(self) -> None:
        known = scatterable()
        for name, s in self.sd.items():
            if name not in known:
                raise ParameterError(
                    f"scatter.{name}: not a scatterable parameter; one of {', '.join(known)}"
                )
            if (
                isinstance(s, bool)
                or not isinstance(s, (int, float))
                or not (math.isfinite(s) and 0.0 <= s <= MAX_SCATTER)
            ):
                raise ParameterError(
                    f"scatter.{name} = {s!r} must be a number in [0, {MAX_SCATTER:g}]"
                )
        object.__setattr__(
            self, "sd", MappingProxyType({k: float(v) for k, v in sorted(self.sd.items()) if v > 0})
        )

    @property
    def names(self) -> tuple[str, ...]:
        """The scattered parameters (SD > 0), sorted."""
        return tuple(self.sd)

    def __hash__(self) -> int:
        return hash(tuple(self.sd.items()))

    def __reduce__(self):  # a mappingproxy does not pickle; a dict does
        return (Scatter, (dict(self.sd),))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Scatter) and dict(self.sd) == dict(other.sd)

    def values(self, nominal: ParamsLike, u: np.ndarray) -> dict[str, np.ndarray]:
        """Parameter values at standard-normal points.

        Parameters
        ----------
        nominal : ScrewParameters
            The nominal values p0.
        u : numpy.ndarray
            Shape (..., len(names)): standard-normal coordinates, one column per name.

        Returns
        -------
        dict of str to numpy.ndarray
            Name -> values of shape u.shape[:-1], in the field's unit.
        """
        out = {}
        for k, name in enumerate(self.names):
            p0, s = getattr(nominal, name), self.sd[name]
            out[name] = p0 * (np.exp(s * u[..., k]) if name in LOG_NORMAL else 1.0 + s * u[..., k])
        return out


def valid_mask(nominal: ParamsLike, values: Mapping[str, np.ndarray]) -> np.ndarray:
    """Samples inside the valid domain: each field within its range, mu_s >= mu_k, the nut on
    the screw (the cross-field rules of `ScrewParameters` for the scattered fields)."""
    shape = np.broadcast_shapes(*(np.shape(v) for v in values.values()))
    ok = np.ones(shape, bool)
    for f in fields(ScrewParameters):
        if f.name not in values:
            continue
        md, v = f.metadata, values[f.name]
        ok &= (v > md["lo"]) if md["lo_open"] else (v >= md["lo"])
        ok &= (v < md["hi"]) if md["hi_open"] else (v <= md["hi"])

    def get(name):
        return values.get(name, getattr(nominal, name))

    for names, rule in _RULES:
        if set(names) & set(values):
            ok &= rule(get)
    return ok


@dataclass(frozen=True)
class Samples:
    """Standard-normal points of a scatter in `replicates` independent scrambled Sobol sets.

    Attributes
    ----------
    scatter : Scatter
        The scatter drawn from.
    u : numpy.ndarray
        Shape (replicates, per_replicate, len(names)), every point inside the valid domain.
    values : dict of str to numpy.ndarray
        The parameter values at `u`, shape (replicates, per_replicate).
    redrawn : int
        Points replaced because they fell outside the valid domain.
    """

    scatter: Scatter
    u: np.ndarray
    values: dict[str, np.ndarray]
    redrawn: int

    @property
    def count(self) -> int:
        """Number of samples."""
        return self.u.shape[0] * self.u.shape[1]


def draw(
    nominal: ParamsLike,
    scatter: Scatter,
    count: int = 4096,
    replicates: int = REPLICATES,
    seed: int = 0,
) -> Samples:
    """Samples of the scatter around `nominal`.

    Parameters
    ----------
    nominal : ScrewParameters
        Nominal values.
    scatter : Scatter
        Which parameters scatter, and how much.
    count : int
        Total samples, a multiple of `replicates` whose quotient is a power of 2 (Sobol balance).
    replicates : int
        Independent scramblings (for the standard error), >= 2.
    seed : int
        Seed of the scramblings: the same seed gives the same samples.

    Returns
    -------
    Samples

    Raises
    ------
    ParameterError
        A bad count or replicates, or the valid domain is (almost) never hit.
    """
    # imported here: scipy.stats costs ~0.4 s, and a process given its samples (a replay's
    # prediction worker) never draws
    from scipy.stats import qmc

    per = check_count(count, replicates) // replicates
    dim = max(len(scatter.names), 1)
    rng = np.random.default_rng(seed)
    u = np.stack(
        [ndtri(qmc.Sobol(dim, scramble=True, seed=rng).random(per)) for _ in range(replicates)]
    )[..., : len(scatter.names)]
    values = scatter.values(nominal, u)
    bad = ~valid_mask(nominal, values)
    redrawn = int(bad.sum())
    for _ in range(_MAX_REDRAW_ROUNDS):  # redraw outside the domain (truncation)
        if not bad.any():
            break
        u[bad] = rng.standard_normal((int(bad.sum()), u.shape[-1]))
        values = scatter.values(nominal, u)
        bad = ~valid_mask(nominal, values)
    else:
        raise ParameterError(
            f"the scatter leaves the valid parameter domain too often "
            f"({int(bad.sum())} of {count} samples after "
            f"{_MAX_REDRAW_ROUNDS} redraws)"
        )
    return Samples(scatter, u, values, redrawn)


def check_count(count: object, replicates: int = REPLICATES) -> int:
    """`count` if it is a valid number of samples (replicates times a power of 2), else
    ParameterError with the reason."""
    if (
        isinstance(count, bool)
        or not isinstance(count, int)
        or isinstance(replicates, bool)
        or not isinstance(replicates, int)
        or replicates < 2
    ):
        raise ParameterError("count and replicates must be integers, replicates >= 2")
    per = count // replicates
    if per < 1 or per * replicates != count or per & (per - 1):
        raise ParameterError(
            f"count = {count} must be replicates ({replicates}) times a power of 2"
        )
    return count


def samples_for(
    nominal: ScrewParameters, scatter: Scatter, count: int = LIVE_SAMPLES, seed: int = 0
) -> Samples:
    """`draw(nominal, scatter, count, REPLICATES, seed)`, with the standard-normal points
    cached: they depend on the nominal values only through the valid domain, so a model
    rebuilt for a new nut position or load reuses them (values are recomputed around it)."""
    key = tuple((n, getattr(nominal, n)) for n in sorted(involved(scatter)))
    u, redrawn = _points(scatter, count, seed, key)
    return Samples(scatter, u, scatter.values(nominal, u), redrawn)


def involved(scatter: Scatter) -> set[str]:
    """The fields the samples of `scatter` depend on: the scattered ones and those sharing a
    validity rule with them (the domain); a model changed in other fields keeps its samples."""
    names = set(scatter.names)
    for rule, _ in _RULES:
        if names & set(rule):
            names |= set(rule)
    return names


@lru_cache(maxsize=64)
def _points(scatter: Scatter, count: int, seed: int, key: tuple) -> tuple[np.ndarray, int]:
    """Points of `draw` whose domain is given by the nominal values in `key`."""
    s = draw(SimpleNamespace(**dict(key)), scatter, count, REPLICATES, seed)
    s.u.setflags(write=False)
    return s.u, s.redrawn


def _settings_class() -> type:
    """ScatterSettings: one field per scatterable parameter (default: DEFAULT_SCATTER, else 0)
    and the live sample count, each with its metadata (ROS parameters `scatter.<name>`)."""
    spec: list[tuple[str, type, Any]] = [
        (
            name,
            float,
            setting(
                DEFAULT_SCATTER.get(name, 0.0),
                "1",
                f"{'SD of ln' if name in LOG_NORMAL else 'relative SD of'} {name} from unit "
                "to unit (0: fixed)",
                0.0,
                MAX_SCATTER,
            ),
        )
        for name in scatterable()
    ]
    spec.append(
        (
            "samples",
            int,
            setting(
                LIVE_SAMPLES,
                "1",
                f"scatter samples of the live P(squeak) ({REPLICATES} replicates of a power of 2)",
                16,
                65536,
            ),
        )
    )

    def post_init(self: Any) -> None:
        check(self, ParameterError, "scatter.")
        try:
            check_count(self.samples)
        except ParameterError as exc:
            raise ParameterError(f"scatter.samples = {self.samples}: {exc}") from None

    def scatter(self: Any) -> Scatter:
        """The scatter these settings give (the SDs > 0)."""
        return Scatter({n: getattr(self, n) for n in scatterable()})

    return make_dataclass(
        "ScatterSettings",
        spec,
        frozen=True,
        namespace={
            "__post_init__": post_init,
            "scatter": property(scatter),
            "__module__": __name__,
            "__doc__": "Unit-to-unit scatter of the parameters (`Scatter`) and the live sample "
            "count,\n    declared with field metadata (ROS parameters "
            "`scatter.<name>`).",
        },
    )


ScatterSettings = _settings_class()
