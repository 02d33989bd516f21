"""Process plumbing for anything in this package that starts rclpy: environment defaults,
signals and an orderly teardown.

DDS discovery stays on loopback unless the user explicitly chooses otherwise
(`ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET` to talk to another machine). Must run before
`rclpy.init`, which is when the RMW reads the environment.
"""

from __future__ import annotations

import os
import signal
import threading

import rclpy


def confine_to_localhost(private_domain: bool = False) -> None:
    """Default discovery to localhost; with `private_domain`, also pick a ROS_DOMAIN_ID of this
    process's own (self-contained runs such as the demo) unless one is set."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if private_domain:
        os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 101))


def close(ctx, executor, nodes) -> None:
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
    same kind acts as usual. Handlers are restored on exit; outside the main thread nothing is
    installed."""

    def __enter__(self) -> "StopSignals":
        self.signum = 0
        self._old: dict[int, object] = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum: int, frame) -> None:
        if self.signum == signum:                                  # asked twice: give in
            signal.signal(signum, self._old.pop(signum))
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            os.kill(os.getpid(), signum)
        self.signum = self.signum or signum

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
