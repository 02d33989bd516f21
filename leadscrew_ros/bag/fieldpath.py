# SPDX-License-Identifier: Apache-2.0
"""A number inside any message type: a field path checked against the type's definition, read
from a CDR payload (the offline replay) or from a deserialized message object (the node).

A path is field names joined by '.', each optionally indexed once: `data`,
`twist.twist.angular.z` (nav_msgs/Odometry), `velocity[2]` (sensor_msgs/JointState),
`feedback.velocities[0]` (control_msgs/JointTrajectoryControllerState), `points[1].positions[0]`.
`compile_path` checks it against a `schema.MessageSchema` (from the log's schema text, or from
the installed definition: `installed`): every name must be a field, an index must be on an array
(and within a fixed array's length), and the path must end at an integer or floating-point
field (not bool, byte, char, string or a message). A path that does not fit is a
`FieldPathError` of one line naming the type, the fields where it went wrong and the path, e.g.
"nav_msgs/msg/Odometry has no field 'w' in twist.twist.angular (fields: x, y, z)".

`FieldPath.read` takes the number out of an XCDR1 payload reading only the fields before it on
the path (`schema._Reader`: every length checked, a malformed payload or an index beyond a
sequence's length is a `CdrError`); `FieldPath.getter` is the same path precompiled into
attribute and item lookups for a message object (rclpy's or rosbags' classes).

A message whose root type has a `header` (std_msgs/Header) carries its sample time:
`stamp_path` gives the paths of its `header.stamp` seconds and nanoseconds.
"""

from __future__ import annotations

import operator
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from . import msgdefs
from .schema import (
    _ENCAPSULATION,
    _HEADER,
    PRIMITIVES,
    CdrError,
    Field,
    MessageSchema,
    SchemaError,
    _Reader,
    parse,
)

# Field types a path may end at: integers and floating point (bool, byte and char are not
# quantities).
NUMBERS = frozenset(t for t in PRIMITIVES if t not in ("bool", "byte", "char"))
HEADER_TYPE = "std_msgs/msg/Header"
_SEGMENT = re.compile(r"^(?P<name>[A-Za-z][A-Za-z0-9_]*)(?:\[(?P<index>\d+)\])?$")


class FieldPathError(ValueError):
    """A path that is not a field path, or does not lead to a number of its type (one line)."""


class BeyondArray(CdrError):
    """A message whose array is shorter than the path's index: it holds no such number."""


@dataclass(frozen=True)
class Step:
    """One segment of a path: the field (its position among its type's fields) and the
    element index, if any."""

    position: int
    field: Field
    index: int | None


def split_path(text: str) -> tuple[tuple[str, int | None], ...]:
    """(name, index or None) of each segment of `text`; FieldPathError if it is no path."""
    segments = []
    for part in text.split("."):
        m = _SEGMENT.match(part)
        if m is None:
            raise FieldPathError(
                f"{text!r} is not a field path (field names joined by '.', each optionally "
                f"indexed: twist.twist.angular.z, velocity[2])"
            )
        segments.append((m["name"], None if m["index"] is None else int(m["index"])))
    return tuple(segments)


def _a(type_name: str) -> str:
    """'a float64', 'an int32', 'a geometry_msgs/msg/Vector3'."""
    return f"{'an' if type_name[0] in 'aeiou' else 'a'} {type_name}"


def _kind(f: Field) -> str:
    """What an array field holds, for the error line: 'float64[36]', 'string[]'."""
    sizes = {"fixed": f"[{f.length}]", "bounded": f"[<={f.length}]", "sequence": "[]"}
    return f"{f.type}{sizes.get(f.array, '')}"


def compile_path(schema: MessageSchema, text: str) -> FieldPath:
    """The path `text` into messages of `schema`, checked.

    Parameters
    ----------
    schema : MessageSchema
        The message type's definitions.
    text : str
        The field path.

    Returns
    -------
    FieldPath

    Raises
    ------
    FieldPathError
        One line: the type, where the path went wrong (with the fields there) and why.
    """
    steps = []
    type_name, done = schema.name, ""
    segments = split_path(text)
    for k, (name, index) in enumerate(segments):
        fields = schema.fields(type_name)
        where = f" in {done}" if done else ""
        names = [f.name for f in fields]
        if name not in names:
            raise FieldPathError(
                f"{schema.name} has no field {name!r}{where} (fields: {', '.join(names)})"
            )
        f = fields[names.index(name)]
        here = f"{done}.{name}" if done else name
        if index is not None and not f.array:
            raise FieldPathError(f"{schema.name}: {here} is {_a(f.type)}, not an array")
        if index is not None and f.array == "fixed" and index >= f.length:
            raise FieldPathError(
                f"{schema.name}: {here} has {f.length} elements, index {index} is beyond them"
            )
        if index is None and f.array:
            raise FieldPathError(
                f"{schema.name}: {here} is an array ({_kind(f)}): index it, e.g. {here}[0]"
            )
        steps.append(Step(names.index(name), f, index))
        done = f"{here}[{index}]" if index is not None else here
        last = k == len(segments) - 1
        if f.type in schema.types and last:
            inner = ", ".join(g.name for g in schema.fields(f.type))
            raise FieldPathError(
                f"{schema.name}: {done} is {_a(f.type)}, not a number (fields: {inner})"
            )
        if f.type not in schema.types and not last:
            raise FieldPathError(f"{schema.name}: {done} is {_a(f.type)}, it has no fields")
        if last and f.type not in NUMBERS:
            raise FieldPathError(f"{schema.name}: {done} is {_a(f.type)}, not a number")
        type_name = f.type
    return FieldPath(schema, text, tuple(steps))


def installed(type_name: str) -> MessageSchema:
    """The schema of an installed message type 'pkg/msg/Type' (`msgdefs`: the ROS 2 packages
    of the environment, else the package's bundled definitions).

    Raises
    ------
    FieldPathError
        Not a type name, no installed definition, or one that does not parse.
    """
    try:
        return parse(msgdefs.definition(type_name), type_name)
    except (msgdefs.MessageDefinitionError, SchemaError) as exc:
        raise FieldPathError(str(exc)) from None


def topic_schema(type_name: str, text: str) -> MessageSchema:
    """The schema of a log's topic: its stored schema text, or where the log stored none
    (e.g. a .db3 bag of an older rosbag2), the installed definition of its type.

    Raises
    ------
    FieldPathError
        The text does not parse, or there is none and no installed definition.
    """
    if not text.strip():
        return installed(type_name)
    try:
        return parse(text, type_name)
    except SchemaError as exc:
        raise FieldPathError(str(exc)) from None


def stamp_path(schema: MessageSchema) -> tuple[FieldPath, FieldPath] | None:
    """The paths of header.stamp.sec and header.stamp.nanosec, if the root type has a
    std_msgs/Header `header`, else None."""
    if not any(f.name == "header" and f.type == HEADER_TYPE for f in schema.fields()):
        return None
    return (
        compile_path(schema, "header.stamp.sec"),
        compile_path(schema, "header.stamp.nanosec"),
    )


@dataclass(frozen=True)
class FieldPath:
    """A checked path to a number in messages of one type (`compile_path`).

    Attributes
    ----------
    schema : MessageSchema
        The message type's definitions.
    text : str
        The path as given.
    steps : tuple of Step
        Per segment: the field and its index.
    """

    schema: MessageSchema
    text: str
    steps: tuple[Step, ...]

    def read(self, data: bytes | bytearray | memoryview) -> float:
        """The number at the path in CDR payload `data` (a float, whatever its field type).

        Raises
        ------
        CdrError
            The payload is malformed or cut off before the number; `BeyondArray` when an
            index is beyond a sequence's length in this message.
        """
        buf = data if isinstance(data, bytes) else bytes(data)
        endian = _ENCAPSULATION.get(buf[:2]) if len(buf) >= _HEADER else None
        if endian is None:
            raise CdrError(f"{self.schema.name}: not an XCDR1 payload")
        r = _Reader(buf, endian, self.schema.types)
        type_name, pos, what = self.schema.name, _HEADER, self.schema.name
        for step in self.steps:
            for g in self.schema.fields(type_name)[: step.position]:
                _, pos = r.field(g, pos, f"{what}.{g.name}")
            f = step.field
            what = f"{what}.{f.name}"
            if step.index is not None:
                pos = self._element(r, f, step.index, pos, what)
                what = f"{what}[{step.index}]"
            if f.type in NUMBERS:
                value, _ = r.scalar(f.type, pos, what)
                return float(value)
            type_name = f.type
        raise AssertionError("compile_path ends every path at a number")

    @staticmethod
    def _element(r: _Reader, f: Field, index: int, pos: int, what: str) -> int:
        """Where element `index` of array field `f` starting at `pos` begins."""
        primitive = f.type in PRIMITIVES
        if f.array == "fixed":
            n = f.length
        else:
            n, pos = r.count(pos, PRIMITIVES[f.type][1] if primitive else 1, what)
        if index >= n:
            raise BeyondArray(f"{what}: index {index} is beyond its {n} elements")
        if primitive:
            size = PRIMITIVES[f.type][1]
            return r._align(pos, size) + index * size
        for k in range(index):
            _, pos = r.one(f, pos, f"{what}[{k}]")
        return pos

    def getter(self) -> Callable[[Any], float]:
        """The path precompiled for message objects: `getter(msg)` is the number (attribute
        lookups, one `operator.attrgetter` per run of names, an item lookup per index).
        IndexError when an index is beyond a sequence's length in that message."""
        parts: list[Callable[[Any], Any]] = []
        names: list[str] = []
        for step in self.steps:
            names.append(step.field.name)
            if step.index is not None:
                parts += [operator.attrgetter(".".join(names)), operator.itemgetter(step.index)]
                names = []
        if names:
            parts.append(operator.attrgetter(".".join(names)))
        if len(parts) == 1:
            only = parts[0]
            return lambda msg: float(only(msg))

        def get(msg: Any) -> float:
            for part in parts:
                msg = part(msg)
            return float(msg)

        return get
