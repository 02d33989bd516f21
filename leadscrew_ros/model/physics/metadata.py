# SPDX-License-Identifier: Apache-2.0
"""Settings declared once: a dataclass field carries its default, unit, allowed range and
description in its metadata, and everything else (validation, ROS parameter descriptors, YAML,
CLI help, README tables) is derived from there.

`setting` declares such a field; `check` validates an instance against it; `documented` writes
the numpydoc Attributes entries of a settings class from it. Ranges are closed unless
`lo_open` / `hi_open`; `choices` lists the allowed strings of a text setting.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, Field, field, fields
from typing import Any, TypeVar

from .display import exact

T = TypeVar("T")


def setting(
    default: Any,
    unit: str,
    description: str,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    choices: tuple[str, ...] = (),
    read_only: bool = False,
    **extra: Any,
) -> Any:
    """A dataclass field with its metadata.

    Parameters
    ----------
    default : bool, int, float or str
        Default value; its type is the setting's type.
    unit : str
        SI unit ('1' dimensionless, '' for text and flags).
    description : str
        One line, lower case, no final full stop.
    lo, hi : float, optional
        Allowed range (both or neither).
    lo_open, hi_open : bool
        Exclude the bound.
    choices : tuple of str
        Allowed values of a text setting (empty: any non-empty text is checked by the owner).
    read_only : bool
        Takes effect only at start-up (a ROS parameter that cannot be set later).
    **extra
        More metadata for the owner (e.g. ``geometry`` of a model parameter).

    Returns
    -------
    dataclasses.Field
    """
    return field(
        default=default,
        metadata=dict(
            unit=unit,
            description=description,
            lo=lo,
            hi=hi,
            lo_open=lo_open,
            hi_open=hi_open,
            choices=tuple(choices),
            read_only=read_only,
            **extra,
        ),
    )


def info(f: Field) -> dict[str, Any]:
    """A field's metadata with its default and type name."""
    return dict(
        f.metadata,
        default=None if f.default is MISSING else f.default,
        type=type(f.default).__name__,
    )


def _bound(value: float) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"  # 1000000, not 1e+06


def range_text(md: Mapping[str, Any]) -> str:
    """'[lo, hi] unit' with open bounds as parentheses (no unit for dimensionless '1')."""
    lo = "(" if md["lo_open"] else "["
    hi = ")" if md["hi_open"] else "]"
    unit = "" if md["unit"] == "1" else md["unit"]
    return f"{lo}{_bound(md['lo'])}, {_bound(md['hi'])}{hi} {unit}".rstrip()


def check_value(name: str, value: Any, f: Field) -> str:
    """'' when `value` is allowed for field `f`, else a one-line reason naming `name`."""
    md, default = f.metadata, f.default
    if isinstance(default, str):
        if not isinstance(value, str):
            return f"{name} = {value!r} must be text"
        if md["choices"] and value not in md["choices"]:
            return f"{name} = {value!r} is not allowed; choose one of {', '.join(md['choices'])}"
        return ""
    if isinstance(default, bool):
        return "" if isinstance(value, bool) else f"{name} = {value!r} must be true or false"
    kind = "int" if isinstance(default, int) else "float"
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or (kind == "int" and not isinstance(value, int))
    ):
        return f"{name} = {value!r} must be a{'n' if kind == 'int' else ''} {kind}"
    if md["lo"] is None:
        return ""
    if not math.isfinite(value):
        return f"{name} = {value} must be finite, allowed {range_text(md)}"
    too_low = value <= md["lo"] if md["lo_open"] else value < md["lo"]
    too_high = value >= md["hi"] if md["hi_open"] else value > md["hi"]
    if too_low or too_high:
        shown = value if isinstance(value, int) else exact(value)
        return f"{name} = {shown} is out of range, allowed {range_text(md)}"
    return ""


def check(obj: Any, error: type[Exception] = ValueError, prefix: str = "") -> None:
    """Raise `error` with the first field of dataclass `obj` whose value is not allowed (the
    fields declared with `setting`; the owner checks any other)."""
    for f in fields(obj):
        if "unit" not in f.metadata:
            continue
        reason = check_value(prefix + f.name, getattr(obj, f.name), f)
        if reason:
            raise error(reason)


def default_text(f: Field) -> str:
    """A field's default as a user types it: 0.15, 100, paper, '' for empty text."""
    default = f.default
    if isinstance(default, bool):
        return str(default).lower()
    if isinstance(default, float):
        return exact(default)
    return str(default) if default != "" else "''"


def help_text(f: Field, description: str | None = None) -> str:
    """Command-line help of an option that sets field `f`: description, unit, default, range.

    Parameters
    ----------
    f : dataclasses.Field
        A field declared with `setting`.
    description : str, optional
        Replaces the field's description (what the option means in its command).

    Returns
    -------
    str
        E.g. 'recompute when the speed moved more than this [rad/s] (default 0.1, allowed
        [0, 1000])'.
    """
    md = f.metadata
    unit = f" [{md['unit']}]" if md["unit"] not in ("", "1") else ""
    allowed = (
        f", one of {', '.join(md['choices'])}"
        if md["choices"]
        else f", allowed {range_text({**md, 'unit': ''})}"
        if md["lo"] is not None
        else ""
    )
    return f"{description or md['description']}{unit} (default {default_text(f)}{allowed})"


def documented(cls: type[T], allowed: Mapping[str, str] | None = None) -> type[T]:
    """Append the numpydoc Attributes entries of the `setting` fields of `cls` to its docstring
    (to its Attributes section when it ends with one, for the fields documented by hand):
    description, unit, default and allowed values from the metadata. A class decorator.

    Parameters
    ----------
    cls : type
        A dataclass with `setting` fields.
    allowed : mapping of str to str, optional
        Field name -> what is allowed, where the metadata does not say (e.g. a text whose
        owner checks it).

    Returns
    -------
    type
        `cls`, its docstring extended.
    """
    doc = (cls.__doc__ or "").rstrip() + "\n"
    lines = (
        [] if "    Attributes\n    ----------" in doc else ["", "    Attributes", "    ----------"]
    )
    for f in fields(cls):  # type: ignore[arg-type]
        md = f.metadata
        if "description" not in md:
            continue
        unit = {"": "", "1": " (dimensionless)"}.get(md["unit"], f" [{md['unit']}]")
        values = (
            (allowed or {}).get(f.name)
            or (f"allowed {range_text(md)}" if md["lo"] is not None else "")
            or (f"one of {', '.join(md['choices'])}" if md["choices"] else "")
        )
        default = f"{f.default:g}" if isinstance(f.default, float) else repr(f.default)
        lines += [
            f"    {f.name} : {f.type}",
            f"        {md['description'][0].upper()}{md['description'][1:]}{unit}.",
            f"        Default {default}" + (f", {values}." if values else "."),
        ]
    cls.__doc__ = doc + "\n".join(lines) + "\n"
    return cls
