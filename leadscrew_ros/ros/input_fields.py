# SPDX-License-Identifier: Apache-2.0
"""The node's speed, load and nut inputs in any installed message type (`inputs.<input>.*`):
the message class imported by its type name, the field path checked against the type's
installed definition (`bag.fieldpath`, the same check and the same one-line errors as the
offline replay) and precompiled into a getter, so that the callback stays short.

The wheels have no `rosidl_runtime_py` (its `get_message`): a type 'pkg/msg/Type' is the class
`Type` of the Python module `pkg.msg`, which every generated message package provides.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any, NamedTuple

from ..bag.fieldpath import FieldPathError, compile_path, installed, stamp_path
from ..live.settings import INPUTS_PREFIX, InputField
from ..model import ParameterError


class InputReader(NamedTuple):
    """How the node takes one input from its messages.

    Attributes
    ----------
    msg_type : type
        The message class it subscribes with.
    value : callable
        Message -> the input in SI units (scale times the number at the field path);
        IndexError when an index is beyond a sequence of that message.
    stamp : callable or None
        Message -> its header stamp [ns] (0: not stamped); None when the type has no header.
    """

    msg_type: type
    value: Callable[[Any], float]
    stamp: Callable[[Any], int] | None


def message_class(type_name: str) -> type:
    """The generated Python class of message type 'pkg/msg/Type' (or 'pkg/Type').

    Raises
    ------
    ParameterError
        Not a type name, or no such installed message type (one line).
    """
    parts = type_name.split("/")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != "msg") or not all(parts):
        raise ParameterError(f"{type_name!r} is not a message type name like nav_msgs/msg/Odometry")
    package, name = parts[0], parts[-1]
    try:
        module = importlib.import_module(f"{package}.msg")
    except ImportError:
        raise ParameterError(f"{type_name}: no installed message package {package}") from None
    cls = getattr(module, name, None)
    if not isinstance(cls, type) or not hasattr(cls, "get_fields_and_field_types"):
        raise ParameterError(f"{type_name}: {package} has no message type {name}")
    return cls


def input_reader(name: str, settings: InputField) -> InputReader:
    """The reader of input `name` ('speed', 'load', 'nut') with `settings`.

    Raises
    ------
    ParameterError
        The type is not installed, or the path does not lead to a number in it: one line
        naming the parameter, the type, its fields and the path, e.g. 'inputs.speed.field
        twist.twist.angular.w: nav_msgs/msg/Odometry has no field 'w' in twist.twist.angular
        (fields: x, y, z)'.
    """
    prefix = f"{INPUTS_PREFIX}{name}."
    try:
        msg_type = message_class(settings.type)
    except ParameterError as exc:
        raise ParameterError(f"{prefix}type {exc}") from None
    try:
        schema = installed(settings.type)
        get = compile_path(schema, settings.field).getter()
        stamped = stamp_path(schema) is not None
    except FieldPathError as exc:
        raise ParameterError(f"{prefix}field {settings.field}: {exc}") from None
    scale = settings.scale
    value = get if scale == 1.0 else (lambda msg: scale * get(msg))
    return InputReader(msg_type, value, stamp_ns if stamped else None)


def stamp_ns(msg: Any) -> int:
    """The header stamp [ns] of a message with a std_msgs/Header `header` (0: not stamped)."""
    stamp = msg.header.stamp
    return stamp.sec * 1_000_000_000 + stamp.nanosec
