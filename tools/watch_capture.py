#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""The screen captures of doc/user/watch.md, from a real run.

    .venv/bin/python tools/watch_capture.py           # rewrites the page's captured block
    .venv/bin/python tools/watch_capture.py --print   # prints it instead

Starts `squeak_node --ros-args -r __ns:=/seat_left -p record.directory:=records` and
`leadscrew-squeak simulate --loop` in the same namespace (child processes, in a temporary
directory, on a ROS_DOMAIN_ID of this process's own, discovery on localhost), then runs the
commands of the page as a user would type them, once the node answers: `record on`,
`watch --once` (repeated until the stroke is in squeak with a safe speed, at most `TRIES`
times), `record status`, `params get`, `params set` (one value taken, one refused) and
`record off`. Writes each command and its output (paths relative to the node's directory: the
temporary one left out) between the page's `watch_capture` markers (test_remote checks that
the page holds such a capture of the current view's rows).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "doc" / "user" / "watch.md"
BEGIN, END = "% watch_capture: begin\n", "% watch_capture: end\n"
NAMESPACE = "/seat_left"
TRIES = 20  # `watch --once` until the stroke squeaks

# One private domain on loopback for the children and the in-process commands
os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 101))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

from leadscrew_ros.cli import main as cli  # noqa: E402


def leadscrew_squeak(*argv: str) -> tuple[int, str]:
    """Run `leadscrew-squeak ARGV` in this process: exit status and what it printed (stdout
    and stderr, as on a terminal)."""
    text = io.StringIO()
    with contextlib.redirect_stdout(text), contextlib.redirect_stderr(text):
        code = cli(list(argv))
    return code, text.getvalue()


def console(argv: tuple[str, ...], output: str) -> list[str]:
    return [f"$ leadscrew-squeak {' '.join(argv)}", *output.rstrip("\n").splitlines()]


def capture(work: Path) -> str:
    """The page's Markdown: each command and its output, from a node running in `work`."""
    env = {**os.environ, "ROS_LOG_DIR": str(work / "log"), "PYTHONUNBUFFERED": "1"}
    script = Path(sys.executable).with_name("squeak_node")
    node = [str(script)] if script.exists() else [sys.executable, "-m", "leadscrew_ros.ros.node"]
    ros_args = ["--ros-args", "-r", f"__ns:={NAMESPACE}"]
    children = [
        subprocess.Popen(
            [*node, *ros_args, "-p", "record.directory:=records"],
            cwd=work,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        ),
        subprocess.Popen(
            [sys.executable, "-m", "leadscrew_ros.cli", "simulate", "--loop", *ros_args],
            cwd=work,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        ),
    ]
    os.chdir(work)  # the recording's path as the node prints it: relative to its directory
    ns = ("--namespace", NAMESPACE)
    try:
        lines: list[str] = []

        def run(*argv: str, expect: int = 0) -> str:
            code, output = leadscrew_squeak(*argv)
            if code != expect:
                raise SystemExit(f"leadscrew-squeak {' '.join(argv)}: exit {code}\n{output}")
            lines.extend(console(argv, output))
            lines.append("")
            return output

        watch = ("watch", *ns, "--once", "--timeout", "60")
        leadscrew_squeak(*watch)  # the node is up (its start-up took 5 s on a busy machine)
        run("record", "on", *ns)
        for _ in range(TRIES):
            code, output = leadscrew_squeak(*watch)
            if code != 0:
                raise SystemExit(f"watch: exit {code}\n{output}")
            # in squeak with a safe speed, the node found without a wait (no 'still looking')
            if "active: yes" in output and "none yet" not in output and "still" not in output:
                break
        lines += [*console(watch, output), ""]
        run("record", "status", *ns)
        run("params", "get", "max_rate_hz", *ns)
        run("params", "set", "max_rate_hz", "50", *ns)
        run("params", "set", "modal_damping", "1.5", *ns, expect=2)
        run("record", "off", *ns)
    finally:
        os.chdir(ROOT)
        for child in children:
            child.terminate()
        for child in children:
            child.wait(timeout=60)
    # paths as the node's own directory sees them, not this run's temporary one
    text = "\n".join(lines).rstrip("\n").replace(f"{work}/", "")
    return f"```console\n{text}\n```\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--print", action="store_true", help="print the block, leave the page")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="watch_capture_") as tmp:
        block = capture(Path(tmp))
    if args.print:
        print(block, end="")
        return 0
    page = PAGE.read_text(encoding="utf-8")
    head, rest = page.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    PAGE.write_text(head + BEGIN + block + END + tail, encoding="utf-8")
    print(f"{PAGE.relative_to(ROOT)}: capture written", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
