# SPDX-License-Identifier: Apache-2.0
"""Process plumbing for anything in this package that starts rclpy: environment defaults,
ROS arguments, signals and an orderly teardown.

DDS discovery stays on loopback unless the user explicitly chooses otherwise
(`ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET` to talk to another machine). Must run before
`rclpy.init`, which is when the RMW reads the environment.
"""

from __future__ import annotations

import os
import signal
import sys
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, TypeVar

import rclpy
from rclpy.context import Context
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

if TYPE_CHECKING:
    from types import FrameType

    from rclpy.executors import Executor
    from rclpy.node import Node

    # What signal.signal takes and returns.
    _SignalHandler = Callable[[int, FrameType | None], Any] | int | signal.Handlers | None


PROGRAM = "leadscrew-squeak"
T = TypeVar("T")


def confine_to_localhost(private_domain: bool = False) -> None:
    """Default discovery to localhost; with `private_domain`, also pick a ROS_DOMAIN_ID of this
    process's own (self-contained runs such as the demo) unless one is set."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if private_domain:
        os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 101))


def init_context(ros_args: Sequence[str] = ()) -> Context:
    """A new Context, initialised with exactly `ros_args` (`--ros-args -r __ns:=/seat_left
    -p name:=value ...`), never with sys.argv: rcl would read the program's own options (it
    warns about `--remap OLD:=NEW` as a deprecated remap rule). Raises ValueError with one
    line for arguments rcl rejects (`checked_ros_args`)."""
    ctx = Context()
    checked_ros_args(lambda: rclpy.init(context=ctx, args=[PROGRAM, *ros_args]))
    return ctx


def checked_ros_args(parse: Callable[[], T]) -> T:
    """Run `parse`, an rclpy call that parses ROS arguments (`rclpy.init`,
    `rclpy.utilities.remove_ros_args`), and return its result; arguments rcl rejects raise
    ValueError with one line: the problem and rcl's warnings about it (its log lines on
    stderr are dropped).

    Raises
    ------
    ValueError
        '--ros-args: Couldn't parse params file: ...', '--ros-args: unknown ROS arguments
        [...]', ...
    """
    with _stderr_captured() as captured:
        try:
            result, problem = parse(), ""
        except _rclpy.UnknownROSArgsError as exc:
            problem = f"unknown ROS arguments {exc}"  # "['--bogus', '-x']"
        except _rclpy.RCLError as exc:  # RCLInvalidROSArgsError (bad file, rule) too
            problem = (
                str(exc)
                .removeprefix("failed to initialize rcl: ")
                .removeprefix("Failed to parse ROS arguments: ")
            )
    if not problem:
        sys.stderr.write(captured[0])  # warnings of a successful parse stay
        return result
    warnings = [
        line.split("]: ", 1)[-1] for line in captured[0].splitlines() if line.startswith("[WARN]")
    ]
    # "<problem>. Error: <detail>, at <source file>...": the detail only when rcl gave no
    # warning, which says it better ("Error opening YAML file" vs "lexeme type 19")
    problem, _, detail = problem.partition(". Error: ")
    detail = detail.split(", at ")[0].strip()
    if detail and not warnings:
        warnings = [detail]
    raise ValueError(
        f"--ros-args: {' '.join(problem.split())}" + "".join(f" ({w.strip()})" for w in warnings)
    )


@contextmanager
def _stderr_captured() -> Iterator[list[str]]:
    """Redirect file descriptor 2 (where rcutils logs) into a temporary file; the yielded list
    receives what was written, on exit."""
    sys.stderr.flush()
    saved = os.dup(2)
    text: list[str] = []
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield text
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            text.append(tmp.read().decode(errors="replace"))


def close(ctx: Context | None, executor: Executor | None, nodes: Iterable[Node]) -> None:
    """Remove and destroy `nodes` (in the given order), stop the executor, shut `ctx` down."""
    for node in nodes:
        if executor is not None:
            executor.remove_node(node)
        node.destroy_node()
    if executor is not None:
        executor.shutdown(timeout_sec=1.0)
    rclpy.try_shutdown(context=ctx)


class StopSignals:
    """Context manager: SIGINT and SIGTERM set `signum` instead of interrupting, so a spin loop
    can end cleanly between two callbacks (with a non-default Context rclpy installs no signal
    handlers: SIGTERM would kill the process, SIGINT raise anywhere). A second signal of the
    same kind acts as usual (SIGINT: KeyboardInterrupt, exit 130; SIGTERM: killed by it).
    Handlers are restored on exit; outside the main thread nothing is installed.

    The one rule for how every long-running ROS command (`squeak_node`, `demo`, `simulate`,
    `replay --publish`) ends, applied by `exit_status`: a requested shutdown is a success.
    SIGINT and SIGTERM alike give exit status 0 and one line on stderr,
    `<program>: stopped by SIGINT` / `<program>: stopped by SIGTERM`; stdout keeps the
    command's own output (its summary so far)."""

    def __enter__(self) -> StopSignals:
        self.signum = 0
        self._old: dict[int, _SignalHandler] = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signum == signum:  # asked twice: give in
            signal.signal(signum, self._old.pop(signum))
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            os.kill(os.getpid(), signum)
        self.signum = self.signum or signum

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)

    def exit_status(self, program: str = PROGRAM) -> int:
        """The exit status of a command that ran until now: 0. After a stop signal, first
        write `<program>: stopped by SIGTERM` (or SIGINT) on stderr."""
        if self.signum:
            print(
                f"{program}: stopped by {signal.Signals(self.signum).name}",
                file=sys.stderr,
                flush=True,
            )
        return 0
