# SPDX-License-Identifier: Apache-2.0
"""One test's ROS world, launch-free: the pattern of the shared notes (Tests) in one place.

A fresh `Context` (rclpy.init on it, optionally with ROS arguments or a domain), one executor
for every node made through the world, spin loops with deadlines that fail naming what they
waited for, and a `close` that destroys the nodes and shuts the context down even after a
failure.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable

import rclpy
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from leadscrew_ros.ros.node import make_executor

# every message of a test, however fast they come: reliable, deep, and late-joining
COLLECT = QoSProfile(
    depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


def unique_ns(prefix: str = "/t", length: int = 32) -> str:
    """A topic namespace no other test (or test process) uses."""
    return f"{prefix}{uuid.uuid4().hex[:length]}"


def new_executor(kind: str, context: Context):
    """The executor of `kind`: "single", rclpy's SingleThreadedExecutor; "events": the node's
    own (`make_executor`, rclpy's EventsExecutor), for tests that must see what squeak_node
    does."""
    if kind == "events":
        return make_executor(context)
    if kind == "single":
        return SingleThreadedExecutor(context=context)
    raise ValueError(f"executor kind {kind!r}: 'single' or 'events'")


class RosWorld:
    """A private rclpy Context with one executor; nodes made or added here are spun by it and
    destroyed by `close` (also a context manager)."""

    def __init__(
        self,
        *,
        ns: str | None = None,
        args: list[str] | None = None,
        domain_id: int | None = None,
        executor: str = "single",
    ):
        self.ns = ns or unique_ns()
        self.ctx = Context()
        rclpy.init(context=self.ctx, args=args, domain_id=domain_id)
        try:
            self.executor = new_executor(executor, self.ctx)
        except BaseException:
            rclpy.shutdown(context=self.ctx)
            raise
        self.nodes: list[Node] = []

    # ------------------------------------------------------------------ nodes
    def add(self, node):
        """Spin `node` on this world's executor; destroyed by `close`."""
        self.executor.add_node(node)
        self.nodes.append(node)
        return node

    def make_node(self, name: str, namespace: str | None = None, **kwargs) -> Node:
        """A plain rclpy Node in this world (default namespace: the world's)."""
        return self.add(
            Node(
                name,
                context=self.ctx,
                namespace=self.ns if namespace is None else namespace,
                **kwargs,
            )
        )

    def remove(self, node) -> None:
        """Take `node` out of the executor, then destroy it. The EventsExecutor (rclpy 7.1.6)
        still runs events queued for a node after `remove_node`, so the queue is emptied
        first (nothing new arrives meanwhile: the test sends nothing while this runs)."""
        self.spin_for(0.2)
        self.executor.remove_node(node)
        node.destroy_node()
        if node in self.nodes:
            self.nodes.remove(node)

    # ------------------------------------------------------------------ spinning
    def describe(self) -> str:
        """What a timeout message adds about the world's state (subclasses say more)."""
        return ""

    def spin_until(
        self, condition: Callable[[], object], timeout: float = 10.0, what: str = "condition"
    ) -> None:
        """Spin until `condition()` is true; AssertionError naming `what` after `timeout` s."""
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"timeout after {timeout} s waiting for {what}" + self.describe()
                )
            self.executor.spin_once(timeout_sec=0.01)

    def spin_for(self, seconds: float) -> None:
        """Spin for `seconds` whatever arrives (the last messages of a stream)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def drain(self, rounds: int = 5) -> None:
        """Handle whatever is ready now (no waiting for anything new)."""
        for _ in range(rounds):
            self.executor.spin_once(timeout_sec=0.0)

    def wait_matched(self, publisher, timeout: float = 10.0, at_least: int = 1) -> None:
        """Until `publisher` has `at_least` subscribers (before publishing anything)."""
        self.spin_until(
            lambda: publisher.get_subscription_count() >= at_least,
            timeout,
            f"{at_least} subscriber(s) on {publisher.topic_name}",
        )

    # ------------------------------------------------------------------ teardown
    def close(self) -> None:
        try:
            for node in reversed(self.nodes):
                node.destroy_node()
            self.nodes.clear()
            self.executor.shutdown(timeout_sec=1.0)
        finally:
            rclpy.try_shutdown(context=self.ctx)

    def __enter__(self) -> RosWorld:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Spinner:
    """`executor` spun on a background thread until `stop()`, as a node process spins its own
    (a callback that blocks shows up as a join timeout, not a hung test)."""

    def __init__(self, executor):
        self.executor = executor
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def stop(self, timeout: float = 120.0) -> None:
        self._stop.set()
        self._thread.join(timeout=timeout)


class LifecycleClient:
    """A managed node's standard lifecycle services (`<node>/change_state`, `<node>/get_state`),
    called from `client_node` of `world` as a lifecycle manager calls them (no ros2 CLI)."""

    def __init__(self, world: RosWorld, client_node: Node, target: str, timeout: float = 60.0):
        """`target`: the managed node's fully qualified name."""
        self.world, self.timeout = world, timeout
        self._change = client_node.create_client(ChangeState, f"{target}/change_state")
        self._get = client_node.create_client(GetState, f"{target}/get_state")

    def _call(self, client, request):
        self.world.spin_until(
            client.service_is_ready, self.timeout, f"the service {client.srv_name}"
        )
        future = client.call_async(request)
        self.world.spin_until(future.done, self.timeout, f"the answer of {client.srv_name}")
        return future.result()

    def change(self, transition: int | str) -> bool:
        """Trigger a transition by id (`lifecycle_msgs.msg.Transition.TRANSITION_*`) or label
        ('configure', 'shutdown', ...); True if it succeeded."""
        t = (
            Transition(label=transition)
            if isinstance(transition, str)
            else Transition(id=transition)
        )
        return self._call(self._change, ChangeState.Request(transition=t)).success

    def state(self) -> str:
        """The current state's label ('unconfigured', 'inactive', 'active', 'finalized')."""
        return self._call(self._get, GetState.Request()).current_state.label
