# SPDX-License-Identifier: Apache-2.0
"""A client of a running `squeak_predictor` node, for the commands that watch and steer it
without the `ros2` command line (`leadscrew-squeak watch`, `record`, `params`): finding the
node, its `~/record` service, its recording status on /diagnostics and its parameters through
the standard rcl_interfaces services (rclpy's `AsyncParameterClient`: ListParameters,
DescribeParameters, GetParameters, SetParameters).

Each command runs a short-lived node in a Context of its own on the user's ROS_DOMAIN_ID (the
running node's), with discovery confined to this machine unless
ROS_AUTOMATIC_DISCOVERY_RANGE says otherwise (`env.confine_to_localhost`).
"""

from __future__ import annotations

import difflib
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.context import Context
from rclpy.exceptions import InvalidNamespaceException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.task import Future
from rclpy.validate_namespace import validate_namespace
from std_srvs.srv import SetBool

from ..live.status import Level
from ..model.physics.display import exact, yaml_value
from . import diagnostics
from .env import close, confine_to_localhost, init_context
from .node import LATCHED, NODE_NAME, RECORD_SERVICE
from .parameters import split_unit

DISCOVERY_S = 2.0  # `watch` says after this long that it has not found the node
# A command that needs the node (record, params, watch --once) gives up after this long: on a
# busy machine (load 6 on 2 cores) discovery took up to 3 s
NODE_WAIT_S = 5.0
CALL_TIMEOUT_S = 30.0  # for an answer (a parameter set rebuilds the model: ~1 s when busy)
SPIN_STEP_S = 0.05


class NodeNotFound(RuntimeError):
    """No squeak_predictor answers in the namespace; the message says how to start one."""


class UnknownParameter(ValueError):
    """A parameter name the node does not have; the message names the closest ones."""


class Refused(RuntimeError):
    """The node refused a parameter value; the message holds its reason."""


def normalise_namespace(namespace: str) -> str:
    """The fully qualified namespace: 'seat_left' or '/seat_left/' -> '/seat_left', '' -> '/'.

    Raises
    ------
    ValueError
        Not a valid ROS namespace (one line: rcl's reason).
    """
    ns = "/" + namespace.strip().strip("/")
    try:
        validate_namespace(ns)
    except InvalidNamespaceException as exc:
        # "Invalid namespace: <reason>:" above the name with a caret: the reason
        reason = str(exc).splitlines()[0].removeprefix("Invalid namespace: ").rstrip(":")
        raise ValueError(f"namespace {namespace!r} is invalid: {reason}") from None
    return ns


def node_name(namespace: str) -> str:
    """The fully qualified name of the predictor in `namespace`: '/seat_left/squeak_predictor'."""
    return f"{namespace.rstrip('/')}/{NODE_NAME}"


def domain_id() -> int:
    """The ROS_DOMAIN_ID rcl uses (0 when unset or empty)."""
    return int(os.environ.get("ROS_DOMAIN_ID") or 0)


def not_found(namespace: str, detail: str = "") -> str:
    """One line: no node in `namespace` (`detail`: what was missing), and the commands that
    start one and drive it."""
    ros_args = "" if namespace == "/" else f" --ros-args -r __ns:={namespace}"
    return (
        f"no squeak_node found in namespace {namespace} (ROS_DOMAIN_ID {domain_id()})"
        + (f": {detail}" if detail else "")
        + f"; start one with: squeak_node{ros_args} (and drive it with: leadscrew-squeak "
        f"simulate --loop{ros_args})"
    )


@dataclass(frozen=True)
class RecordingState:
    """The node's recording as its 'recording' diagnostic status says it."""

    active: bool
    file: str  # being written ('' when not recording)
    bag: str  # the latest bag ('' before one)
    messages: int
    lost: int
    level: Level
    message: str

    @classmethod
    def from_status(cls, status: DiagnosticStatus) -> RecordingState:
        """From the node's 'recording' DiagnosticStatus."""
        values = {kv.key: kv.value for kv in status.values}
        return cls(
            active=values.get(diagnostics.KEY_ACTIVE) == "true",
            file=values.get(diagnostics.KEY_FILE, ""),
            bag=values.get(diagnostics.KEY_BAG, ""),
            messages=int(values.get(diagnostics.KEY_MESSAGES) or 0),
            lost=int(values.get(diagnostics.KEY_LOST) or 0),
            level=Level(status.level[0]),
            message=status.message,
        )

    def text(self) -> str:
        """'on: FILE (N messages[, M lost])' or 'off (last bag: BAG)'; the status's message
        when it is not OK."""
        if self.active:
            text = f"on: {self.file} ({self.messages} messages"
            text += f", {self.lost} lost)" if self.lost else ")"
        else:
            text = "off" + (f" (last bag: {self.bag})" if self.bag else "")
        return text if self.level == Level.OK else f"{text}; {self.level.name}: {self.message}"


@dataclass(frozen=True)
class RemoteParameter:
    """A parameter of the node, with what its descriptor says."""

    name: str
    value: Any  # Python value
    type: int  # rcl_interfaces/msg/ParameterType
    description: str  # without the unit
    unit: str
    range: str  # 'lo..hi', the open bounds or the choices ('' when free)
    read_only: bool

    @classmethod
    def from_descriptor(cls, d: ParameterDescriptor, value: Any) -> RemoteParameter:
        """From the node's descriptor (the unit split off its description) and `value`."""
        description, unit = split_unit(d.description)
        bounds = [(r.from_value, r.to_value) for r in (*d.floating_point_range, *d.integer_range)]
        closed = "..".join(format_value(b) for b in bounds[0]) if bounds else ""
        return cls(
            d.name,
            value,
            d.type,
            description,
            unit,
            d.additional_constraints or closed,
            d.read_only,
        )

    def line(self) -> str:
        """'NAME = VALUE [unit] (range; read-only): description'."""
        notes = "; ".join(n for n in (self.range, "read-only" if self.read_only else "") if n)
        return (
            f"{self.name} = {format_value(self.value)}"
            + (f" [{self.unit}]" if self.unit else "")
            + (f" ({notes})" if notes else "")
            + f": {self.description}"
        )


def format_value(value: Any) -> str:
    """A parameter value as it is written on the command line and in YAML (floats exactly)."""
    return exact(value) if isinstance(value, float) else yaml_value(value)


_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def parse_value(text: str, parameter_type: int) -> Any:
    """`text` as a value of the parameter type (a double takes '5' as 5.0: ROS refuses an
    integer for a double parameter).

    Raises
    ------
    ValueError
        Text that is not of the type (one line).
    """
    if parameter_type == ParameterType.PARAMETER_BOOL:
        if text.lower() in _TRUE + _FALSE:
            return text.lower() in _TRUE
        raise ValueError(f"{text!r} is not a bool (true or false)")
    if parameter_type == ParameterType.PARAMETER_INTEGER:
        try:
            return int(text)
        except ValueError:
            raise ValueError(f"{text!r} is not an integer") from None
    if parameter_type == ParameterType.PARAMETER_DOUBLE:
        try:
            return float(text)
        except ValueError:
            raise ValueError(f"{text!r} is not a number") from None
    if parameter_type == ParameterType.PARAMETER_STRING:
        return text
    raise ValueError(f"parameters of type {Parameter.Type(parameter_type).name} cannot be set here")


class Remote:
    """A client node in a Context of its own, for the squeak_predictor in `namespace`; close
    it (or use it as a context manager).

    Parameters
    ----------
    namespace : str
        The predictor's namespace ('/' for the root).
    make_node : callable, optional
        `make_node(context, namespace) -> Node`: the client node (`watch` subscribes to the
        outputs); default: a plain hidden node.

    Raises
    ------
    ValueError
        An invalid namespace.
    """

    def __init__(
        self, namespace: str, make_node: Callable[[Context, str], Node] | None = None
    ) -> None:
        self.namespace = normalise_namespace(namespace)
        self.target = node_name(self.namespace)
        confine_to_localhost()  # the user's ROS_DOMAIN_ID: the node's
        self.ctx = init_context()
        self.executor: SingleThreadedExecutor | None = None
        self.node: Node | None = None
        try:
            self.executor = SingleThreadedExecutor(context=self.ctx)
            self.node = (make_node or _plain_node)(self.ctx, self.namespace)
            self.executor.add_node(self.node)
        except BaseException:
            self.close()
            raise
        self._parameters: AsyncParameterClient | None = None

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        close(self.ctx, self.executor, [self.node] if self.node is not None else [])
        self.node = None

    def __enter__(self) -> Remote:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ discovery
    def found(self) -> bool:
        """The predictor is in the ROS graph now."""
        assert self.node is not None
        names = self.node.get_node_names_and_namespaces()
        return (NODE_NAME, self.namespace) in names

    def spin_until(self, condition: Callable[[], bool], seconds: float) -> bool:
        """Spin until `condition()` or `seconds` have passed; its last value."""
        assert self.executor is not None
        end = time.monotonic() + seconds
        while not condition():
            if time.monotonic() >= end:
                return False
            self.executor.spin_once(timeout_sec=SPIN_STEP_S)
        return True

    # ------------------------------------------------------------------ calls
    def _call(self, client: Any, request: Any) -> Any:
        """The answer of `client` (a service client) to `request`."""
        assert self.executor is not None
        if not client.wait_for_service(timeout_sec=NODE_WAIT_S):
            raise NodeNotFound(
                not_found(self.namespace, f"no service {client.srv_name} within {NODE_WAIT_S:g} s")
            )
        return self._result(client.call_async(request), client.srv_name)

    def _result(self, future: Future, what: str) -> Any:
        assert self.executor is not None
        self.executor.spin_until_future_complete(future, timeout_sec=CALL_TIMEOUT_S)
        if not future.done():
            future.cancel()
            raise RuntimeError(f"no answer from {what} within {CALL_TIMEOUT_S:g} s")
        return future.result()

    def record(self, on: bool) -> tuple[bool, str]:
        """Start (`on`) or stop recording through `~/record` (std_srvs/SetBool).

        Returns
        -------
        tuple of (bool, str)
            The service's success and message: the file being written, the reason of a start
            that failed, or 'stopped; last bag: BAG'.
        """
        assert self.node is not None
        client = self.node.create_client(SetBool, f"{self.target}/{RECORD_SERVICE}")
        try:
            response = self._call(client, SetBool.Request(data=on))
        finally:
            self.node.destroy_client(client)
        return response.success, response.message

    def recording(self) -> RecordingState:
        """The node's recording state, from its latest 'recording' status on /diagnostics
        (latched: the last one is there at once)."""
        assert self.node is not None
        name = f"{self.target}: {diagnostics.RECORDING_TASK}"
        found: list[DiagnosticStatus] = []

        def take(msg: DiagnosticArray) -> None:
            found.extend(s for s in msg.status if s.name == name)

        sub = self.node.create_subscription(DiagnosticArray, diagnostics.TOPIC, take, LATCHED)
        try:
            if not self.spin_until(lambda: bool(found), NODE_WAIT_S):
                what = f"no '{name}' status on /diagnostics within {NODE_WAIT_S:g} s"
                if not self.found():
                    raise NodeNotFound(not_found(self.namespace, what))
                raise RuntimeError(what)
        finally:
            self.node.destroy_subscription(sub)
        return RecordingState.from_status(found[-1])

    # ------------------------------------------------------------------ parameters
    def _parameter_client(self) -> AsyncParameterClient:
        assert self.node is not None
        if self._parameters is None:
            self._parameters = AsyncParameterClient(self.node, self.target)
        if not self._parameters.wait_for_services(timeout_sec=NODE_WAIT_S):
            raise NodeNotFound(
                not_found(
                    self.namespace,
                    f"no parameter services of {self.target} within {NODE_WAIT_S:g} s",
                )
            )
        return self._parameters

    def names(self) -> list[str]:
        """Every parameter name of the node, in its order (ListParameters)."""
        client = self._parameter_client()
        return list(self._result(client.list_parameters(), "list_parameters").result.names)

    def parameters(self, names: list[str] | None = None) -> list[RemoteParameter]:
        """The parameters `names` (default: all) with values and descriptors.

        Raises
        ------
        UnknownParameter
            A name the node does not have (the closest names in the message).
        """
        known = self.names()
        for name in names or ():
            if name not in known:
                close_names = difflib.get_close_matches(name, known, n=3)
                hint = f" (did you mean {', '.join(close_names)}?)" if close_names else ""
                raise UnknownParameter(f"{self.target} has no parameter {name!r}{hint}")
        wanted = list(names) if names else known
        client = self._parameter_client()
        descriptors = self._result(
            client.describe_parameters(wanted), "describe_parameters"
        ).descriptors
        values = self._result(client.get_parameters(wanted), "get_parameters").values
        if len(descriptors) != len(wanted) or len(values) != len(wanted):  # gone meanwhile
            raise RuntimeError(f"{self.target} did not describe all of {wanted}")
        return [
            RemoteParameter.from_descriptor(d, parameter_value_to_python(v))
            for d, v in zip(descriptors, values, strict=True)
        ]

    def set(self, name: str, text: str) -> tuple[RemoteParameter, RemoteParameter]:
        """Set parameter `name` to `text`, parsed to its declared type (SetParameters).

        Returns
        -------
        tuple of RemoteParameter
            Before and after.

        Raises
        ------
        UnknownParameter
            No such parameter.
        ValueError
            `text` is not of the parameter's type.
        Refused
            The node refused the value; the message holds its reason.
        """
        [before] = self.parameters([name])
        try:
            value = parse_value(text, before.type)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None
        response = self._result(
            self._parameter_client().set_parameters([Parameter(name, value=value)]),
            "set_parameters",
        )
        [result] = response.results
        if not result.successful:
            raise Refused(f"{self.target} refused {name} = {text}: {result.reason}")
        [after] = self.parameters([name])
        return before, after


def _plain_node(context: Context, namespace: str) -> Node:
    # A leading underscore hides it from `ros2 node list`, as for the ros2 CLI's own nodes
    return Node(f"_leadscrew_squeak_{os.getpid()}", context=context, namespace=namespace)
