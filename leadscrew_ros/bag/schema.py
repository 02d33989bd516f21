# SPDX-License-Identifier: Apache-2.0
"""Schema-driven CDR: any ROS 2 message type from the `ros2msg` schema text a log stores.

rosbag2 (and our recorder, `msgdefs`) store per topic the type's .msg text followed by every
type it uses, each after a line of 80 '=' and `MSG: pkg/Type`. `parse` turns that text into
message definitions: primitive fields (bool, byte, char, int8..uint64, float32, float64,
string, bounded strings), fixed-size (`T[N]`), bounded (`T[<=N]`) and unbounded (`T[]`)
arrays, and nested types (`pkg/Type`, `Type` of the same package, `Header` as
std_msgs/Header). Constants are skipped and default values ignored. `wstring` is refused at
parse time (rosbag2 logs of it are rare and its CDR width differs between middlewares).

`MessageSchema.decode` reads an XCDR1 payload (the 4-byte encapsulation header CDR_BE or
CDR_LE, alignment counted from the end of the header, as Fast DDS and rosbags write it) into
nested dicts: primitive arrays become numpy arrays read with `np.frombuffer` (read-only views
of the payload, no per-element Python), strings `str`, other scalars Python numbers.
`MessageSchema.encode` writes such dicts back as XCDR1 little endian, byte for byte what Fast
CDR writes with its padding zeroed (an empty sequence is not aligned for its elements; no tail
padding). A type without fields holds one uint8, as rosidl generates it.

Log data is untrusted: every length is checked against the payload before use, and anything
malformed raises `CdrError` (a ValueError) in one line naming the field, never an IndexError.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

DELIMITER_RE = re.compile(r"^={10,}\s*$")
_HEADER = 4
_ENCAPSULATION = {b"\x00\x00": ">", b"\x00\x01": "<"}  # CDR_BE, CDR_LE
_LE_HEADER = b"\x00\x01\x00\x00"
# primitive -> (struct code, size); byte and char are octets (ROS 2: char is uint8)
PRIMITIVES: dict[str, tuple[str, int]] = {
    "bool": ("?", 1),
    "byte": ("B", 1),
    "char": ("B", 1),
    "int8": ("b", 1),
    "uint8": ("B", 1),
    "int16": ("h", 2),
    "uint16": ("H", 2),
    "int32": ("i", 4),
    "uint32": ("I", 4),
    "int64": ("q", 8),
    "uint64": ("Q", 8),
    "float32": ("f", 4),
    "float64": ("d", 8),
}
_NUMPY = {
    "bool": "u1",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "int64": "i8",
    "uint64": "u8",
    "float32": "f4",
    "float64": "f8",
}
_STRUCTS = {(e, code): struct.Struct(e + code) for e in "<>" for code, _ in PRIMITIVES.values()}
_U32 = {e: struct.Struct(e + "I") for e in "<>"}
_FIELD_RE = re.compile(
    r"^(?P<type>[A-Za-z][\w/]*)(?:<=(?P<strbound>\d+))?"
    r"(?:\[(?P<array>(?:<=)?\d*)\])?$"
)
_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


class SchemaError(ValueError):
    """Schema text that is not a usable ros2msg definition (one line)."""


class CdrError(ValueError):
    """A payload that does not decode with its schema, or a value that does not encode (one
    line naming the field)."""


@dataclass(frozen=True)
class Field:
    """One field of a message definition.

    Attributes
    ----------
    name : str
        Field name.
    type : str
        A primitive name (`PRIMITIVES`, or 'string'), or a nested type 'pkg/msg/Type'.
    array : str
        '' (a single value), 'fixed' (`length` elements, no length prefix), 'bounded' (at most
        `length`, length-prefixed) or 'sequence' (length-prefixed).
    length : int
        Element count of a fixed array, the bound of a bounded one, else 0.
    """

    name: str
    type: str
    array: str = ""
    length: int = 0

    @property
    def primitive(self) -> bool:
        """A number or bool type (not a string, not a nested message)."""
        return self.type in PRIMITIVES


@dataclass(frozen=True)
class MessageSchema:
    """Parsed message definitions: the root type and every type it uses.

    Attributes
    ----------
    name : str
        The root type, 'pkg/msg/Type'.
    types : mapping of str to tuple of Field
        'pkg/msg/Type' -> its fields in order (constants skipped).
    """

    name: str
    types: Mapping[str, tuple[Field, ...]]

    def fields(self, type_name: str | None = None) -> tuple[Field, ...]:
        """The fields of `type_name` (default: the root type)."""
        return self.types[type_name or self.name]

    def decode(self, data: bytes | bytearray | memoryview) -> dict[str, Any]:
        """The message in CDR payload `data` as nested dicts.

        Parameters
        ----------
        data : bytes-like
            Serialized message: encapsulation header, then the XCDR1 body (either byte
            order). Bytes after the last field are ignored (Fast CDR may pad).

        Returns
        -------
        dict
            Field name -> value: Python int/float/bool/str for scalars, numpy arrays
            (read-only views of `data`) for primitive arrays, lists for arrays of strings and
            of messages, dicts for nested messages.

        Raises
        ------
        CdrError
            The payload is cut off, a length overruns it, a string is not NUL-terminated
            UTF-8, or the encapsulation is not XCDR1.
        """
        buf = bytes(data) if not isinstance(data, bytes) else data
        if len(buf) < _HEADER:
            raise CdrError(f"{self.name}: payload of {len(buf)} bytes has no CDR header")
        endian = _ENCAPSULATION.get(buf[:2])
        if endian is None:
            raise CdrError(f"{self.name}: unsupported CDR encapsulation 0x{buf[:2].hex()}")
        value, _ = _Reader(buf, endian, self.types).message(self.name, _HEADER, self.name)
        return value

    def encode(self, value: Mapping[str, Any]) -> bytes:
        """`value` (nested dicts as `decode` returns them) as an XCDR1 little-endian payload.

        Parameters
        ----------
        value : mapping
            Field name -> value; a missing field is written as its zero value (0, '', empty
            array, a nested message of zeros), as a default-constructed message holds.

        Returns
        -------
        bytes
            Encapsulation header CDR_LE and the body.

        Raises
        ------
        CdrError
            A value does not fit its field (range, type, fixed array length, array bound,
            string bound or a NUL in a string).
        """
        w = _Writer(self.types)
        w.message(self.name, value, self.name)
        return bytes(w.out)


# ----------------------------------------------------------------------------- parsing
def _full_name(name: str, package: str) -> str:
    """'pkg/msg/Type' of a type reference inside `package` ('Header': std_msgs/Header)."""
    parts = name.split("/")
    if len(parts) == 1:
        return "std_msgs/msg/Header" if name == "Header" else f"{package}/msg/{name}"
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and parts[1] == "msg":
        return name
    raise SchemaError(f"not a message type name: {name!r}")


def _parse_fields(text: str, type_name: str) -> tuple[Field, ...]:
    package = type_name.split("/")[0]
    out = []
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split(None, 1)
        if len(parts) < 2:
            raise SchemaError(f"{type_name} line {number}: {line!r} is not 'type name'")
        rest = parts[1].split("#", 1)[0].strip()
        if re.match(r"^[A-Za-z][A-Za-z0-9_]*\s*=", rest):
            continue  # a constant
        name = rest.split()[0] if rest.split() else ""
        m = _FIELD_RE.match(parts[0])
        if m is None or not _NAME_RE.match(name):
            raise SchemaError(f"{type_name} line {number}: cannot parse {line!r}")
        base = m.group("type")
        if m.group("strbound") is not None and base not in ("string", "wstring"):
            raise SchemaError(f"{type_name} line {number}: only strings take <=N: {line!r}")
        if base == "wstring":
            raise SchemaError(f"{type_name}.{name}: wstring fields are not supported")
        if base not in PRIMITIVES and base != "string":
            base = _full_name(base, package)
        array, length = "", 0
        spec = m.group("array")
        if spec is not None:
            if spec == "":
                array = "sequence"
            elif spec.startswith("<="):
                array, length = "bounded", int(spec[2:])
            else:
                array, length = "fixed", int(spec)
        out.append(Field(name, base, array, length))
    return tuple(out)


def parse(text: str, name: str) -> MessageSchema:
    """The message definitions of rosbag2 `ros2msg` schema text.

    Parameters
    ----------
    text : str
        Root definition, then per dependency a line of '=' (80 in rosbag2), `MSG: pkg/Type`
        (or 'pkg/msg/Type') and its definition.
    name : str
        The root type, 'pkg/msg/Type' or 'pkg/Type'.

    Returns
    -------
    MessageSchema
        The root and every type defined in the text.

    Raises
    ------
    SchemaError
        A line that is not a field or constant, an unsupported type (wstring), or a nested
        type the text does not define.
    """
    root = _full_name(name, name.split("/")[0])
    blocks: list[tuple[str, list[str]]] = [(root, [])]
    for line in text.splitlines():
        if DELIMITER_RE.match(line):
            blocks.append(("", []))
        elif not blocks[-1][0] and line.startswith("MSG:"):
            blocks[-1] = (_full_name(line[4:].strip(), ""), [])
        elif not blocks[-1][0] and not line.strip():
            continue
        elif not blocks[-1][0]:
            raise SchemaError(f"{root}: a definition after '=' lacks its 'MSG: pkg/Type' line")
        else:
            blocks[-1][1].append(line)
    types: dict[str, tuple[Field, ...]] = {}
    for type_name, lines in blocks:
        if type_name:
            types.setdefault(type_name, _parse_fields("\n".join(lines), type_name))
    for type_name, flds in types.items():
        for f in flds:
            if not f.primitive and f.type != "string" and f.type not in types:
                raise SchemaError(
                    f"{type_name}.{f.name}: type {f.type} is not defined in the "
                    f"schema text of {root}"
                )
    _check_acyclic(root, types, ())
    return MessageSchema(root, types)


def _check_acyclic(
    type_name: str, types: Mapping[str, tuple[Field, ...]], path: tuple[str, ...]
) -> None:
    if type_name in path:
        raise SchemaError(f"recursive message definition: {' -> '.join(path + (type_name,))}")
    for f in types[type_name]:
        if f.type in types:
            _check_acyclic(f.type, types, path + (type_name,))


# ----------------------------------------------------------------------------- decoding
class _Reader:
    def __init__(self, buf: bytes, endian: str, types: Mapping[str, tuple[Field, ...]]):
        self.buf, self.endian, self.types = buf, endian, types

    def _need(self, pos: int, size: int, what: str) -> None:
        if pos + size > len(self.buf):
            raise CdrError(f"{what}: payload cut off at byte {len(self.buf)} (needs {pos + size})")

    def _align(self, pos: int, size: int) -> int:
        return pos + (_HEADER - pos) % size

    def scalar(self, type_: str, pos: int, what: str) -> tuple[Any, int]:
        code, size = PRIMITIVES[type_]
        pos = self._align(pos, size)
        self._need(pos, size, what)
        value = _STRUCTS[self.endian, code].unpack_from(self.buf, pos)[0]
        return value, pos + size

    def count(self, pos: int, item_size: int, what: str) -> tuple[int, int]:
        pos = self._align(pos, 4)
        self._need(pos, 4, what)
        (n,) = _U32[self.endian].unpack_from(self.buf, pos)
        if n * item_size > len(self.buf) - pos - 4:
            raise CdrError(f"{what}: length {n} overruns the payload of {len(self.buf)} bytes")
        return n, pos + 4

    def string(self, pos: int, what: str) -> tuple[str, int]:
        n, pos = self.count(pos, 1, what)
        if n == 0:  # not what Fast CDR writes, but unambiguous
            return "", pos
        if self.buf[pos + n - 1] != 0:
            raise CdrError(f"{what}: string not terminated by NUL")
        try:
            return self.buf[pos : pos + n - 1].decode("utf-8"), pos + n
        except UnicodeDecodeError as exc:
            raise CdrError(f"{what}: string is not UTF-8 ({exc.reason})") from None

    def message(self, type_name: str, pos: int, what: str) -> tuple[dict[str, Any], int]:
        fields = self.types[type_name]
        if not fields:  # rosidl's structure_needs_at_least_one_member
            _, pos = self.scalar("uint8", pos, what)
            return {}, pos
        out: dict[str, Any] = {}
        for f in fields:
            out[f.name], pos = self.field(f, pos, f"{what}.{f.name}")
        return out, pos

    def one(self, f: Field, pos: int, what: str) -> tuple[Any, int]:
        if f.primitive:
            value, pos = self.scalar(f.type, pos, what)
            return value, pos
        if f.type == "string":
            return self.string(pos, what)
        return self.message(f.type, pos, what)

    def field(self, f: Field, pos: int, what: str) -> tuple[Any, int]:
        if not f.array:
            return self.one(f, pos, what)
        if f.array == "fixed":
            n = f.length
        else:
            n, pos = self.count(pos, PRIMITIVES[f.type][1] if f.primitive else 1, what)
            if f.array == "bounded" and n > f.length:
                raise CdrError(f"{what}: {n} elements exceed the bound {f.length}")
        if not f.primitive:
            items = []
            for k in range(n):
                item, pos = self.one(f, pos, f"{what}[{k}]")
                items.append(item)
            return items, pos
        size = PRIMITIVES[f.type][1]
        if n:
            pos = self._align(pos, size)
        self._need(pos, n * size, what)
        arr = np.frombuffer(self.buf, np.dtype(self.endian + _NUMPY[f.type]), n, pos)
        return (arr != 0 if f.type == "bool" else arr), pos + n * size


# ----------------------------------------------------------------------------- encoding
class _Writer:
    def __init__(self, types: Mapping[str, tuple[Field, ...]]):
        self.types = types
        self.out = bytearray(_LE_HEADER)

    def _align(self, size: int) -> None:
        self.out += bytes(-(len(self.out) - _HEADER) % size)

    def scalar(self, type_: str, value: Any, what: str) -> None:
        code, size = PRIMITIVES[type_]
        self._align(size)
        if type_ == "bool":
            value = bool(value)
        elif code in "fd":
            if isinstance(value, (str, bytes)):
                raise CdrError(f"{what}: {value!r} is not a number")
        elif isinstance(value, (float, np.floating)) or not isinstance(
            value, (int, np.integer, bool, np.bool_)
        ):
            raise CdrError(f"{what}: {value!r} is not an integer ({type_})")
        try:
            self.out += _STRUCTS["<", code].pack(value)
        except (struct.error, TypeError, OverflowError) as exc:
            raise CdrError(f"{what}: {value!r} does not fit {type_} ({exc})") from None

    def count(self, n: int) -> None:
        self._align(4)
        self.out += _U32["<"].pack(n)

    def string(self, value: Any, what: str) -> None:
        if not isinstance(value, str):
            raise CdrError(f"{what}: {value!r} is not a string")
        raw = value.encode("utf-8", "strict")
        if b"\x00" in raw:
            raise CdrError(f"{what}: string holds a NUL, which ends a CDR string")
        self.count(len(raw) + 1)
        self.out += raw + b"\x00"

    def message(self, type_name: str, value: Mapping[str, Any] | None, what: str) -> None:
        fields = self.types[type_name]
        if not fields:
            self.scalar("uint8", 0, what)
            return
        value = {} if value is None else value
        if not isinstance(value, Mapping):
            raise CdrError(f"{what}: {type(value).__name__} is not a message (a mapping)")
        for f in fields:
            self.field(f, value.get(f.name), f"{what}.{f.name}")

    def one(self, f: Field, value: Any, what: str) -> None:
        if f.primitive:
            self.scalar(f.type, 0 if value is None else value, what)
        elif f.type == "string":
            self.string("" if value is None else value, what)
        else:
            self.message(f.type, value, what)

    def field(self, f: Field, value: Any, what: str) -> None:
        if not f.array:
            self.one(f, value, what)
            return
        if f.primitive:
            arr = self._array(f, value, what)
            n = arr.size
        else:
            items = [] if value is None else list(value)
            n = len(items)
        if f.array == "fixed" and n != f.length:
            if value is None and f.length:
                n = f.length
                if f.primitive:
                    arr = np.zeros(n, _NUMPY[f.type])
                else:
                    items = [None] * n
            else:
                raise CdrError(f"{what}: {n} elements, the array holds exactly {f.length}")
        if f.array == "bounded" and n > f.length:
            raise CdrError(f"{what}: {n} elements exceed the bound {f.length}")
        if f.array != "fixed":
            self.count(n)
        if f.primitive:
            if n:
                self._align(PRIMITIVES[f.type][1])
                self.out += arr.astype("<" + _NUMPY[f.type], copy=False).tobytes()
            return
        for k, item in enumerate(items):
            self.one(f, item, f"{what}[{k}]")

    @staticmethod
    def _array(f: Field, value: Any, what: str) -> np.ndarray:
        target = np.dtype(_NUMPY[f.type])
        try:
            arr = np.asarray([] if value is None else value)
        except (TypeError, ValueError) as exc:
            raise CdrError(f"{what}: not an array of {f.type} ({exc})") from None
        if arr.ndim != 1:
            raise CdrError(f"{what}: a {arr.ndim}-d array, expected 1-d")
        if f.type == "bool":
            return arr.astype(bool).astype("u1")
        if arr.size == 0:
            return arr.astype(target)
        if target.kind in "iu":
            if arr.dtype.kind not in "iub":
                raise CdrError(f"{what}: {arr.dtype} values are not integers ({f.type})")
            info = np.iinfo(target)
            if arr.min() < info.min or arr.max() > info.max:
                raise CdrError(f"{what}: values out of the {f.type} range")
        elif arr.dtype.kind not in "iubf":
            raise CdrError(f"{what}: {arr.dtype} values are not numbers ({f.type})")
        return arr.astype(target, copy=False)
