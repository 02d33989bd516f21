# SPDX-License-Identifier: Apache-2.0
"""Run every command of the core install in one process; write a JSON report (a helper of
test_offline_install.py, run there with the ROS modules blocked and in a venv without ROS).

    python offline_cli.py WORKDIR       # -> WORKDIR/report.json

Each command's exit code, stdout and stderr; the modules whose import a blocker (if any) refused
while it ran, read back from $LEADSCREW_BLOCKED_LOG, where the blocker appends one name a line
(also from the Dask worker processes of `review`); where leadscrew_ros and the schema text of
std_msgs/msg/Float64MultiArray came from.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sys
import time
from pathlib import Path

from leadscrew_ros import __version__
from leadscrew_ros.bag import msgdefs
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.cli import main

ROS_COMMANDS = [
    ["demo"],
    ["simulate"],
    ["replay", "LOG", "--publish"],
    ["watch", "--once"],
    ["record", "status"],
    ["params"],
]


def commands(work: Path, log: Path) -> list[list[str]]:
    return [
        ["modes"],
        ["predict", "--speed", "20"],
        ["sweep", "--speed", "5:50:5"],
        ["map", "--x", "speed_rad_s:5:50:4", "--y", "axial_load_n:100:300:3", "--json"],
        ["figures", "--quick", "--out", str(work / "figures")],
        ["transient", "--speed", "20", "--duration", "0.05"],
        ["replay", str(log), "--out", str(work / "replay"), "--no-report", "--quiet"],
        ["info", str(log)],
        ["recover", str(log)],
        ["review", str(log), "--out", str(work / "review"), "--workers", "1", "--quiet"],
    ] + [[str(log) if a == "LOG" else a for a in c] for c in ROS_COMMANDS]


def blocked() -> list[str]:
    path = os.environ.get("LEADSCREW_BLOCKED_LOG")
    if not path or not Path(path).exists():
        return []
    names = Path(path).read_text().split()
    Path(path).write_text("")
    return sorted(set(names))


def run(work: Path) -> dict:
    log = write_log(DutyCycle(duration_s=20.0, rest_s=4.0), work / "logs")
    report = {
        "package": str(Path(sys.modules["leadscrew_ros"].__file__).parent),
        "version": __version__,
        "log": str(log),
        "definition": msgdefs.definition("std_msgs/msg/Float64MultiArray"),
        "definition_prefix": next(
            str(p)
            for p in msgdefs._prefixes()
            if (p / "share" / "std_msgs" / "msg" / "Float64MultiArray.msg").is_file()
        ),
        "blocked_by_the_log": blocked(),
        "commands": [],
    }
    for argv in commands(work, log):
        out, err = io.StringIO(), io.StringIO()
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
        report["commands"].append(
            {
                "argv": argv,
                "code": code,
                "stdout": out.getvalue(),
                "stderr": err.getvalue(),
                "blocked": blocked(),
                "seconds": round(time.perf_counter() - t0, 2),
            }
        )
    return report


if __name__ == "__main__":
    work = Path(sys.argv[1])
    (work / "report.json").write_text(json.dumps(run(work), indent=1))
