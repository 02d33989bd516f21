# SPDX-License-Identifier: Apache-2.0
"""Model parameters in SI units; defaults are Table 1 of the paper plus the friction law of Fig. 4.

Every field carries metadata (unit, allowed range, description, whether it changes the geometry)
so the CLI, the ROS parameter descriptors and the YAML config are all generated from this one
table.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import Field, dataclass, fields, replace
from types import SimpleNamespace
from typing import Any, TypeAlias

from .display import exact
from .metadata import check_value, documented, setting

FORMULATIONS = ("paper", "consistent")
MAX_CONTACT_TURNS = 5000  # longest nut accepted, in thread turns


class ParameterError(ValueError):
    """A model parameter or operating point is invalid; the message names field, value and range."""


def _p(
    default: Any,
    unit: str,
    description: str,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    geometry: bool = True,
) -> Any:
    choices = FORMULATIONS if isinstance(default, str) else ()
    return setting(
        default,
        unit,
        description,
        lo,
        hi,
        lo_open=lo_open,
        hi_open=hi_open,
        choices=choices,
        geometry=geometry,
    )


@dataclass(frozen=True)
class ScrewParameters:
    """Lead screw, nut contact and friction parameters (Table 1, SI units).

    Fields marked ``geometry=True`` in their metadata change the modal basis or the contact
    integrals; the others only rescale precomputed matrices. Construction validates every field
    and the cross-field constraints (`validate`) and raises `ParameterError` on a bad value.

    The Attributes section below is generated from the field metadata (unit, description,
    allowed range, default), so it cannot drift from the fields.
    """

    radius_m: float = _p(0.005, "m", "effective screw radius R", 1e-4, 0.5)
    length_m: float = _p(0.300, "m", "screw length L", 1e-3, 20.0)
    thread_height_m: float = _p(0.001, "m", "thread height h", 0.0, 1.0, lo_open=True)
    helix_angle_rad: float = _p(
        math.radians(5.0),
        "rad",
        "screw helix angle beta",
        0.0,
        math.pi / 2,
        lo_open=True,
        hi_open=True,
    )
    nut_position_m: float = _p(0.150, "m", "contact (nut) start location z_o", 0.0, 20.0)
    nut_length_m: float = _p(0.060, "m", "contact (nut) length b", 0.0, 20.0, lo_open=True)
    youngs_modulus_pa: float = _p(207e9, "Pa", "Young's modulus E", 0.0, 1e13, lo_open=True)
    shear_modulus_pa: float = _p(79.3e9, "Pa", "shear modulus G", 0.0, 1e13, lo_open=True)
    density_kg_m3: float = _p(7820.0, "kg/m^3", "density rho", 0.0, 1e5, lo_open=True)
    axial_load_n: float = _p(
        200.0, "N", "nominal axial load F_z (default operating load)", -1e7, 1e7, geometry=False
    )
    modal_damping: float = _p(
        3.0e-3,
        "1",
        "modal damping ratio xi_n of every mode",
        0.0,
        1.0,
        hi_open=True,
        geometry=False,
    )
    mu_static: float = _p(0.25, "1", "static friction coefficient mu_s", 0.0, 2.0, geometry=False)
    mu_kinetic: float = _p(0.20, "1", "kinetic friction coefficient mu_k", 0.0, 2.0, geometry=False)
    friction_decay_s_m: float = _p(
        10.0, "s/m", "friction decay constant d", 0.0, 1e4, geometry=False
    )
    n_bending: int = _p(6, "1", "bending orders per direction (x and y)", 1, 40)
    n_torsion: int = _p(6, "1", "torsion orders", 1, 40)
    formulation: str = _p(
        "paper",
        "",
        "Appendix A as printed ('paper') or first-principles linearisation ('consistent')",
    )
    min_speed_rad_s: float = _p(
        0.5,
        "rad/s",
        "lowest |speed| at which the sliding linearisation is trusted",
        0.0,
        1e4,
        lo_open=True,
        geometry=False,
    )

    def __post_init__(self) -> None:
        validate(self)

    @property
    def n_modes(self) -> int:
        """Number of modal coordinates N = 2 n_bending + n_torsion (the state has 2N)."""
        return 2 * self.n_bending + self.n_torsion

    @property
    def lead_per_rad_m(self) -> float:
        """Axial advance of the contact helix per radian of screw angle, R tan(beta) [m/rad]
        (z = R tan(beta) theta, (A.9))."""
        return self.radius_m * math.tan(self.helix_angle_rad)

    @property
    def nut_travel_m(self) -> float:
        """Largest nut position z_o with the nut on the screw, L - b [m]."""
        return self.length_m - self.nut_length_m

    def with_(self, **changes: Any) -> ScrewParameters:
        """Copy with some fields changed (validated).

        Parameters
        ----------
        **changes
            Field names and new values, each in the field's unit (see Attributes); strings
            such as CLI arguments are converted to the field's type.

        Returns
        -------
        ScrewParameters
            A new, validated parameter set.

        Raises
        ------
        ParameterError
            A name is not a field, or a value is of the wrong type or out of range.
        """
        unknown = changes.keys() - _FIELD_BY_NAME.keys()
        if unknown:
            raise ParameterError(
                f"unknown parameter(s): {', '.join(sorted(unknown))}; "
                f"known: {', '.join(field_names())}"
            )
        values = {k: coerce(k, v) for k, v in changes.items()}
        new = object.__new__(ScrewParameters)  # `replace`, checking only the changed
        new.__dict__.update(self.__dict__, **values)  # fields: the others were valid in self
        validate(new, values)
        return new

    def geometry_only(self) -> ScrewParameters:
        """These parameters with every non-geometry field at its default (a cache key).

        Returns
        -------
        ScrewParameters
            A copy whose non-geometry fields hold their defaults.
        """
        defaults: dict[str, Any] = {
            f.name: f.default for f in fields(self) if not f.metadata["geometry"]
        }
        return replace(self, **defaults)

    def as_dict(self) -> dict[str, Any]:
        """The fields as a plain dict.

        Returns
        -------
        dict[str, Any]
            Field name to value, in the field's unit.
        """
        return {name: getattr(self, name) for name in _FIELD_BY_NAME}


_FIELDS = fields(ScrewParameters)

# The parameters, or a namespace of their fields where some hold arrays of scattered values
# (`uncertainty`'s samples): what the friction law and the kernels broadcast over.
ParamsLike: TypeAlias = "ScrewParameters | SimpleNamespace"
_FIELD_BY_NAME = {f.name: f for f in _FIELDS}
# The fields the modes and the contact depend on (metadata "geometry"); the others only
# rescale the precomputed matrices at an operating point
GEOMETRY_FIELDS = frozenset(f.name for f in _FIELDS if f.metadata["geometry"])


def field_names() -> list[str]:
    """The names of the `ScrewParameters` fields, in declaration order.

    Returns
    -------
    list of str
        The field names.
    """
    return list(_FIELD_BY_NAME)


def _field(name: str) -> Field[Any]:
    try:
        return _FIELD_BY_NAME[name]
    except (KeyError, TypeError):
        raise ParameterError(
            f"unknown parameter {name!r}; known: {', '.join(field_names())}"
        ) from None


def field_info(name: str) -> dict[str, Any]:
    """Metadata of field `name`: unit, range, help, with its default and type."""
    f = _field(name)
    return dict(f.metadata, default=f.default, type=f.type)


def coerce(name: str, value: Any) -> Any:
    """Convert a value (e.g. a CLI string) to the field's type, with a clear error."""
    typ = _field(name).type
    try:
        if typ == "int":  # a whole number only: never truncate '2.5' to 2
            number = float(value) if isinstance(value, str) else value
            if isinstance(number, float) and not number.is_integer():
                raise ParameterError(f"{name} = {value!r} is not a whole number")
            return int(number)
        if typ == "float":
            if isinstance(value, bool):
                raise ValueError
            return float(value)
        return str(value)
    except ParameterError:
        raise
    except (TypeError, ValueError, OverflowError):
        raise ParameterError(f"{name} = {value!r} is not a valid {typ}") from None


documented(ScrewParameters, {"formulation": f"one of {', '.join(FORMULATIONS)}"})


def validate(p: ScrewParameters, changed: Iterable[str] | None = None) -> None:
    """Check every field (only those named in `changed` when given: the others are known to be
    valid) and the cross-field constraints; raise ParameterError naming the field."""
    for f in _FIELDS if changed is None else map(_FIELD_BY_NAME.__getitem__, changed):
        reason = check_value(f.name, getattr(p, f.name), f)
        if reason:
            raise ParameterError(reason)
    if p.nut_position_m + p.nut_length_m > p.length_m:
        raise ParameterError(
            f"nut_position_m + nut_length_m = {exact(p.nut_position_m + p.nut_length_m)} m "
            f"exceeds "
            f"length_m = {exact(p.length_m)} m: the nut must lie on the screw (z_o + b <= L)"
        )
    if p.mu_kinetic > p.mu_static:
        raise ParameterError(
            f"mu_kinetic = {exact(p.mu_kinetic)} exceeds mu_static = "
            f"{exact(p.mu_static)}: need mu_static >= mu_kinetic >= 0"
        )
    turns = p.nut_length_m / (2 * math.pi * p.lead_per_rad_m)
    if turns > MAX_CONTACT_TURNS:
        raise ParameterError(
            f"the nut spans {turns:.3g} thread turns (nut_length_m / lead); at most "
            f"{MAX_CONTACT_TURNS} are supported: increase helix_angle_rad or radius_m"
        )
    if p.thread_height_m >= p.radius_m:
        raise ParameterError(
            f"thread_height_m = {p.thread_height_m:g} m must be smaller than "
            f"radius_m = {p.radius_m:g} m"
        )
