# SPDX-License-Identifier: Apache-2.0
"""Copy the installed ROS 2 definitions of the types the package writes into the package.

    .venv/bin/python tools/bundle_msgdefs.py           # rewrites leadscrew_ros/bag/jazzy_msgs/
    .venv/bin/python tools/bundle_msgdefs.py --check   # exit 1 if the copy is not current

`leadscrew_ros.bag.msgdefs` reads `<prefix>/share/<pkg>/msg/<Type>.msg`; the copy is its last
prefix, so the core install (no ROS 2 message packages) still writes complete `ros2msg` schemas.
Run with the ROS 2 wheels installed (`pip install -e '.[ros]'`): the texts come from them.
test/test_offline_install.py asserts the copy equals them.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from leadscrew_ros.bag import msgdefs


def installed(name: str) -> Path:
    """The installed .msg file of 'pkg/msg/Type' (never the bundled copy)."""
    pkg, _, typ = name.split("/")
    for prefix in msgdefs._prefixes():
        path = prefix / "share" / pkg / "msg" / f"{typ}.msg"
        if prefix != msgdefs.BUNDLED and path.is_file():
            return path
    raise SystemExit(f"bundle_msgdefs: {name} is not installed: pip install -e '.[ros]'")


def wanted() -> dict[Path, Path]:
    """{bundled file: installed file} of `BUNDLED_TYPES` and every type they use."""
    names: set[str] = set()
    for root in msgdefs.BUNDLED_TYPES:
        installed(root)
        names.add(root)
        names |= {
            line[5:] for line in msgdefs.definition(root).splitlines() if line.startswith("MSG: ")
        }
    out = {}
    for name in sorted(names):
        pkg, _, typ = name.split("/")
        out[msgdefs.BUNDLED / "share" / pkg / "msg" / f"{typ}.msg"] = installed(name)
    return out


def stale() -> list[str]:
    """What differs between the bundled copy and the installed definitions (empty: current)."""
    files = wanted()
    present = set(msgdefs.BUNDLED.rglob("*.msg")) if msgdefs.BUNDLED.is_dir() else set()
    out = [f"extra: {p}" for p in sorted(present - set(files))]
    out += [
        f"missing or different: {dst}"
        for dst, src in files.items()
        if not dst.is_file() or dst.read_bytes() != src.read_bytes()
    ]
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--check",
        action="store_true",
        help="only compare: exit 1 when the copy differs from the installed files",
    )
    args = p.parse_args(argv)
    if args.check:
        problems = stale()
        print("\n".join(problems) or "bundled message definitions are current")
        return 1 if problems else 0
    files = wanted()
    shutil.rmtree(msgdefs.BUNDLED / "share", ignore_errors=True)
    for dst, src in files.items():
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst)
        print(f"{dst.relative_to(msgdefs.BUNDLED)} <- {src}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
