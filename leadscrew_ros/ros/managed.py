# SPDX-License-Identifier: Apache-2.0
"""Managed (lifecycle) nodes of this package: what `squeak_node` and `squeak_guard` share.

A `ManagedNode` is an `rclpy.lifecycle.LifecycleNode` whose transitions are four methods of the
subclass: `configure` (read and check the parameters, build what the node runs on: model,
subscriptions, publishers, timers, services; a bad parameter raises `ParameterError`),
`activate` (start publishing and recording), `deactivate` (stop both cleanly) and `release`
(undo `configure`, from any state; cleanup, shutdown, an error and `destroy_node` all end
there). A transition that raises fails with one log line and leaves the node where it was
(configure: unconfigured, everything it built released); rclpy itself would swallow the
exception silently. Entities made by `configure` are registered with `own` and destroyed by
`destroy_owned`, so that `configure` can run again after a cleanup.

`start` is the autostart of `--autostart` (the default of the executables): configure and
activate at once, raising what made either fail, so that a process without a lifecycle manager
behaves as an unmanaged node (exit status 2 and one line for a bad parameter).
`autostart_option` takes `--autostart`/`--no-autostart` out of a program's own arguments;
`AUTOSTART_HELP` is their text for `--help`. `run` is the executables' `main`.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, TypeVar

import rclpy
from rclpy.client import Client
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor
from rclpy.lifecycle import LifecycleNode, LifecyclePublisher, LifecycleState
from rclpy.lifecycle import TransitionCallbackReturn as Result
from rclpy.publisher import Publisher
from rclpy.service import Service
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rclpy.utilities import remove_ros_args

from ..model import ParameterError
from .env import StopSignals, checked_ros_args, confine_to_localhost

AUTOSTART, NO_AUTOSTART = "--autostart", "--no-autostart"
AUTOSTART_HELP = (
    f"  {AUTOSTART}      configure and activate at start-up (the default): runs like an "
    "unmanaged node",
    f"  {NO_AUTOSTART}   start unconfigured and wait for a lifecycle manager "
    "(~/change_state: configure, activate, deactivate, cleanup, shutdown)",
)
T = TypeVar("T")


def autostart_option(args: list[str]) -> tuple[bool, list[str]]:
    """Take `--autostart` and `--no-autostart` out of a program's own arguments.

    Parameters
    ----------
    args : list of str
        The arguments without the program name and the ROS arguments.

    Returns
    -------
    autostart : bool
        The last of the two options given; True when neither is.
    rest : list of str
        The other arguments, in their order.
    """
    autostart, rest = True, []
    for arg in args:
        if arg in (AUTOSTART, NO_AUTOSTART):
            autostart = arg == AUTOSTART
        else:
            rest.append(arg)
    return autostart, rest


def one_line(exc: BaseException) -> str:
    """An exception as one line: its message with the whitespace collapsed (a `ValueError`
    subclass, such as `ParameterError`, says enough by its message; others add their type)."""
    text = " ".join(str(exc).split())
    return text if isinstance(exc, ValueError) else f"{type(exc).__name__}: {text}"


class ManagedNode(LifecycleNode):
    """A lifecycle node whose transitions are `configure`, `activate`, `deactivate` and
    `release` (module docstring).

    Parameters
    ----------
    node_name : str
        The node's name.
    **kwargs
        Passed to `rclpy.lifecycle.LifecycleNode` (context, namespace, parameter overrides...).

    Attributes
    ----------
    failure : BaseException or None
        What made the last transition fail (None after a successful one).
    """

    def __init__(self, node_name: str, **kwargs: Any):
        super().__init__(node_name, **kwargs)
        self.failure: BaseException | None = None
        self._active = False
        self._starting = False  # in `start`: failures are raised, not logged
        self._owned: list[Any] = []

    # ----------------------------------------------------------------- subclass API
    def configure(self) -> None:
        """Read and check the parameters and build everything (`own` what is made)."""

    def activate(self) -> None:
        """Start publishing (the lifecycle publishers are enabled already)."""

    def deactivate(self) -> None:
        """Stop publishing and recording (`active` is False already)."""

    def release(self) -> None:
        """Release what `configure` built (from any state; nothing when unconfigured)."""
        self.destroy_owned()

    @property
    def active(self) -> bool:
        """In the active state (from the end of activating to the start of deactivating)."""
        return self._active

    def own(self, entity: T) -> T:
        """Register a subscription, publisher, timer, service or client made by `configure`
        for `destroy_owned`; returns it."""
        self._owned.append(entity)
        return entity

    def own_timer(self, period_s: float, callback: Callable[[], None], **kwargs: Any) -> Timer:
        """A timer (`own`) whose callback does nothing once `destroy_owned` destroyed it: the
        executor may have taken an expiry in the same wait as the transition (shutdown,
        cleanup, deactivate) that destroys it, and run it after (it then published on a
        destroyed publisher). `kwargs` go to `create_timer`."""

        def tick() -> None:
            if any(e is timer for e in self._owned):
                callback()

        timer = self.own(self.create_timer(period_s, tick, **kwargs))
        return timer

    def destroy_owned(self, entity: object | None = None) -> None:
        """Destroy `entity` (one made by `own`), or all of them, newest first."""
        for e in [entity] if entity is not None else self._owned[::-1]:
            self._owned.remove(e)
            if isinstance(e, LifecyclePublisher):
                self.destroy_lifecycle_publisher(e)
            elif isinstance(e, Publisher):
                self.destroy_publisher(e)
            elif isinstance(e, Subscription):
                self.destroy_subscription(e)
            elif isinstance(e, Timer):
                self.destroy_timer(e)
            elif isinstance(e, Service):
                self.destroy_service(e)
            elif isinstance(e, Client):
                self.destroy_client(e)
            else:
                raise TypeError(f"cannot destroy {e!r}")

    def start(self) -> None:
        """Configure and activate now (autostart).

        Raises
        ------
        Exception
            What made configure or activate fail (`ParameterError` for a bad parameter); the
            node is then unconfigured (configure failed) or inactive (activate failed).
        """
        self._starting = True
        try:
            for trigger in (self.trigger_configure, self.trigger_activate):
                if trigger() != Result.SUCCESS:
                    raise self.failure or RuntimeError(f"{trigger.__name__} failed")
        finally:
            self._starting = False

    def destroy_node(self) -> None:
        """Release everything (from any state), then destroy the node and its lifecycle
        state machine."""
        self._active = False
        self.release()
        super().destroy_node()
        # rclpy 7.1.6 leaves the state machine, which holds the node's handle: the node would
        # stay in the ROS graph until the process ends, also after its context shut down
        self._state_machine.destroy_when_not_in_use()

    # ----------------------------------------------------------------- transitions
    def on_configure(self, state: LifecycleState) -> Result:
        """Configuring: `configure`; on failure everything built is released."""
        return self._transition("configure", state, self.configure, undo=self.release)

    def on_activate(self, state: LifecycleState) -> Result:
        """Activating: the lifecycle publishers first, then `activate`."""
        result = super().on_activate(state)
        if result != Result.SUCCESS:
            return result
        self._active = True
        return self._transition("activate", state, self.activate, undo=lambda: self._stop(state))

    def on_deactivate(self, state: LifecycleState) -> Result:
        """Deactivating: `deactivate`, then the lifecycle publishers."""
        self._active = False
        result = self._transition("deactivate", state, self.deactivate)
        return super().on_deactivate(state) if result == Result.SUCCESS else result

    def on_cleanup(self, state: LifecycleState) -> Result:
        """Cleaning up: `release`."""
        return self._transition("cleanup", state, self.release)

    def on_shutdown(self, state: LifecycleState) -> Result:
        """Shutting down (from unconfigured, inactive or active): `release`."""
        self._active = False
        return self._transition("shutdown", state, self.release)

    def on_error(self, state: LifecycleState) -> Result:
        """Error processing (a transition raised): `release`, then unconfigured; if that
        raises too, finalized."""
        self._active = False
        result = self._transition("error processing", state, self.release)
        return Result.SUCCESS if result == Result.SUCCESS else Result.FAILURE

    def _stop(self, state: LifecycleState) -> None:
        """Undo a failed activation: `deactivate`, the publishers off again."""
        self._active = False
        self.deactivate()
        super().on_deactivate(state)

    def _transition(
        self,
        name: str,
        state: LifecycleState,
        step: Callable[[], None],
        undo: Callable[[], None] | None = None,
    ) -> Result:
        """Run `step`; if it raises, `undo`, keep the reason in `failure`, say it in one log
        line (unless `start` raises it) and fail: back to `state` (configure, activate),
        else error processing."""
        self.failure = None
        try:
            step()
            return Result.SUCCESS
        except Exception as exc:
            self.failure = exc
            if undo is not None:
                undo()
            if not self._starting:
                self.get_logger().error(
                    f"{name} failed: {one_line(exc)}; the node stays {state.label}"
                    if undo is not None
                    else f"{name} failed: {one_line(exc)}"
                )
            return Result.FAILURE if undo is not None else Result.ERROR


def run(
    make_node: Callable[[bool], ManagedNode],
    prog: str,
    name: str,
    usage: Callable[[], str],
    make_executor: Callable[[], Executor],
    args: list[str] | None = None,
    before_spin: Callable[[], None] | None = None,
) -> int:
    """An executable's `main`: parse, start the node, spin until SIGINT/SIGTERM.

    Parameters
    ----------
    make_node : callable
        The node from the autostart flag (`--autostart`/`--no-autostart`).
    prog : str
        The program's name for its error lines.
    name : str
        The node's name for the line a stop signal gives.
    usage : callable
        Its `--help` text.
    make_executor : callable
        The executor to spin it on.
    args : list of str, optional
        The command line (default `sys.argv`).
    before_spin : callable, optional
        Called once the node is on the executor (e.g. `gc.freeze`).

    Returns
    -------
    int
        0 on a requested shutdown (SIGINT/SIGTERM, one line on stderr: `StopSignals`), 2 on a
        bad argument or parameter (one line; with autostart also a configure that failed).
    """
    argv = list(sys.argv if args is None else args)
    try:  # a bad params file or remap rule: one line
        own_args = checked_ros_args(lambda: remove_ros_args(argv))[1:]
    except ValueError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    if {"-h", "--help"} & set(own_args):
        print(usage())
        return 0
    autostart, own_args = autostart_option(own_args)
    if own_args:
        print(
            f"{prog}: error: unrecognized arguments: {' '.join(own_args)} (ROS "
            "arguments go after --ros-args; see --help)",
            file=sys.stderr,
        )
        return 2
    confine_to_localhost()
    # SIGINT/SIGTERM only set `stop.signum`; the loop ends between callbacks. rclpy's own
    # handlers shut the context down from another thread (a publish in flight then fails with
    # "context is invalid", exit 1 with a traceback) or raise KeyboardInterrupt inside any
    # callback.
    with StopSignals() as stop:
        try:  # unknown ROS arguments: remove_ros_args keeps them, init refuses them
            checked_ros_args(
                lambda: rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
            )
        except ValueError as exc:
            print(f"{prog}: error: {exc}", file=sys.stderr)
            return 2
        node = None
        try:
            node = make_node(autostart)
            if not autostart:
                node.get_logger().info(
                    "unconfigured: waiting for a lifecycle transition (~/change_state)"
                )
            executor = make_executor()
            executor.add_node(node)
            if before_spin is not None:
                before_spin()
            while not stop.signum:
                executor.spin_once(timeout_sec=0.1)  # stops after the current callback
        except (ParameterError, ParameterException) as exc:
            print(f"{prog}: error: {' '.join(str(exc).split())}", file=sys.stderr)
            return 2
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return stop.exit_status(name)
