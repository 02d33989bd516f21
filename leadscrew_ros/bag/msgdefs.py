# SPDX-License-Identifier: Apache-2.0
"""Complete ROS 2 message definitions (`ros2msg` schema text) from the installed packages.

rosbag2 stores, per topic, the type's .msg text followed by every type it uses, each after a
line of 80 '=' and `MSG: pkg/msg/Type` (rosbag2 docs/message_definition_encoding.md). The texts
are read from `<prefix>/share/<pkg>/msg/<Type>.msg`, never typed by hand.

The prefixes are $AMENT_PREFIX_PATH, the environment (where the ROS 2 wheels put them), and last
`jazzy_msgs/` beside this module: a copy of the Jazzy definitions of the types the package itself
writes (`BUNDLED_TYPES` and what they use), made by tools/bundle_msgdefs.py. With it the core
install, which has no ROS 2 message package, writes and replays logs whose schemas are complete;
an installed definition wins.
"""

from __future__ import annotations

import functools
import os
import re
import sys
from pathlib import Path

from . import cdr

DELIMITER = "=" * 80
_PRIMITIVES = {
    "bool",
    "byte",
    "char",
    "float32",
    "float64",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
    "string",
    "wstring",
}


class MessageDefinitionError(LookupError):
    """A message type without an installed definition, or not a message type name."""


BUNDLED = Path(__file__).resolve().parent / "jazzy_msgs"
BUNDLED_TYPES = (
    cdr.FLOAT64,
    cdr.BOOL,
    cdr.FLOAT64_MULTI_ARRAY,
    cdr.JOINT_STATE,
    cdr.DIAGNOSTIC_ARRAY,
)


def type_name(msg_type: object) -> str:
    """'pkg/msg/Type' of a generated rclpy message class (or instance)."""
    cls = msg_type if isinstance(msg_type, type) else type(msg_type)
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


def _prefixes() -> list[Path]:
    roots = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [Path(p) for p in roots] + [Path(sys.prefix), BUNDLED]


@functools.cache
def msg_text(name: str) -> str:
    """The .msg file of 'pkg/msg/Type' (or 'pkg/Type') as installed."""
    pkg, _, typ = _split(name)
    for prefix in _prefixes():
        path = prefix / "share" / pkg / "msg" / f"{typ}.msg"
        if path.is_file():
            return path.read_text()
    raise MessageDefinitionError(f"no installed definition of {pkg}/msg/{typ}")


def _split(name: str) -> tuple[str, str, str]:
    parts = name.split("/")
    if len(parts) == 2:
        return parts[0], "msg", parts[1]
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], "msg", parts[2]
    raise MessageDefinitionError(f"not a message type name: {name!r}")


def _field_types(text: str, package: str) -> list[str]:
    """Nested (non-primitive) field types of a .msg text, in field order, as 'pkg/msg/Type'."""
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        base = re.sub(r"\[.*\]$", "", line.split()[0])  # drop [], [N], [<=N]
        base = re.sub(r"<=\d+$", "", base)  # bounded strings
        if base in _PRIMITIVES or "=" in line.split()[0]:
            continue
        pkg, _, typ = _split(base) if "/" in base else (package, "msg", base)
        out.append(f"{pkg}/msg/{typ}")
    return out


@functools.cache
def definition(name: str) -> str:
    """`ros2msg` schema text of 'pkg/msg/Type': root definition, then each dependency once,
    depth first in field order (as rosbag2 writes it)."""
    pkg, _, typ = _split(name)
    root = f"{pkg}/msg/{typ}"
    seen, parts = {root}, [msg_text(root).rstrip("\n")]

    def visit(type_: str) -> None:
        for dep in _field_types(msg_text(type_), _split(type_)[0]):
            if dep not in seen:
                seen.add(dep)
                parts.append(f"{DELIMITER}\nMSG: {dep}\n{msg_text(dep).rstrip(chr(10))}")
                visit(dep)

    visit(root)
    return "\n".join(parts) + "\n"
