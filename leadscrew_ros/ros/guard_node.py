# SPDX-License-Identifier: Apache-2.0
"""ROS 2 managed node `squeak_guard`: a speed-command filter that steers around squeak bands.

Runs between the command source and the motor controller. Subscribes (sensor-data QoS,
relative to the namespace): speed_command (std_msgs/Float64, rad/s), axial_load (Float64, N),
nut_position (Float64, m). Publishes speed_command_guarded (Float64, rad/s; reliable, depth 10,
one per command), guard/active (Bool) and guard/reason (String, `GuardStep.reason`; both
reliable, transient local, depth 1, published when either changes) and /diagnostics (one status
'<node>: squeak guard': WARN with the reason while the fail-safe passes the command through,
OK while guarding or disabled).

The policy is `live.guard.GuardPolicy` (O(1) per command, no prediction in a callback); the
squeak bands come from the model in-process (`live.guard.BandWorker`: a background thread
computes the bins the steps ask for). The parameters are the model's and the scatter's, as the
predictor's (`ros.parameters.GUARD_GROUPS`: the same params file serves both), the node's own
and `guard.*` (`GuardSettings`).

A managed (lifecycle) node: configure reads and checks the parameters (a bad one: FAILURE and
one log line), builds the model, the policy and the band thread, and creates the publishers and
subscriptions; activate starts publishing; deactivate stops it (commands then pass nowhere:
the motor controller is to fall back on the raw command); cleanup and shutdown release
everything (the band thread ends). With `autostart` (the default, as `squeak_guard` runs without
`--no-autostart`) the constructor configures and activates. Parameters are read at configure;
a set while configured is checked as a whole and applied at once (new `guard.*` settings keep
the tracker's state; new model parameters a new model and band cache).
"""

from __future__ import annotations

import sys
import time
from typing import Any

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.logging import LoggingSeverity
from rclpy.parameter import Parameter
from rclpy.qos import (
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.signals import SignalHandlerOptions
from rclpy.timer import Timer
from rclpy.utilities import remove_ros_args
from std_msgs.msg import Bool, Float64, String

from ..bag import messages
from ..live.guard import BandWorker, GuardPolicy, GuardSettings, GuardStep
from ..live.status import Level
from ..model import ParameterError, ScrewParameters, SqueakModel
from ..model.uncertainty.scatter import ScatterSettings
from .diagnostics import DiagnosticStatusWrapper, Updater
from .env import StopSignals, checked_ros_args, confine_to_localhost
from .node import LATCHED, make_executor
from .parameters import (
    GUARD_GROUPS,
    GUARD_PARAMETER_NAMES,
    GUARD_PARAMETERS,
    NodeSettings,
    build,
    declare,
    help_lines,
    names_of,
    squeak_model,
)

NODE_NAME = "squeak_guard"
PROG = "squeak_guard"
COMMAND, GUARDED = messages.SPEED_COMMAND, messages.SPEED_COMMAND_GUARDED
ACTIVE, REASON = messages.GUARD_ACTIVE, messages.GUARD_REASON
LOAD, NUT = "axial_load", "nut_position"  # the predictor's input names
GUARD_TASK = "squeak guard"
HOUSEKEEPING_PERIOD_S = 0.05
# The guarded command: every one delivered, not latched (a late motor controller must not
# start from an old command).
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
# Key names of the guard's diagnostic status.
KEY_ENABLED = "enabled"
KEY_ACTIVE = "active"
KEY_REASON = "reason"
KEY_FAULT = "fault"
KEY_COMMAND = "command_rad_s"
KEY_GUARDED = "guarded_rad_s"
KEY_BINS = "band_bins"
KEY_WANTED = "band_bins_wanted"
KEY_UNIT = "unit_id"
MODEL_NAMES = names_of(ScrewParameters) | names_of(ScatterSettings)


class SqueakGuardNode(LifecycleNode):
    """The `squeak_guard` node (the module's topics, parameters and lifecycle): wires the ROS
    interfaces to a `GuardPolicy` and its `BandWorker`.

    Parameters
    ----------
    autostart : bool
        Configure and activate in the constructor (a failed configure leaves the node
        unconfigured with `error` set).
    **kwargs
        Passed to `rclpy.lifecycle.LifecycleNode` (context, namespace, parameter overrides).

    Attributes
    ----------
    policy : GuardPolicy or None
        While configured.
    worker : BandWorker or None
        The band thread, while configured.
    last : GuardStep or None
        The latest step.
    command : float or None
        The latest speed command taken [rad/s].
    error : str
        Why the last configure failed ('' if it did not).
    """

    def __init__(self, autostart: bool = True, **kwargs: Any):
        super().__init__(NODE_NAME, **kwargs)
        declare(self, GUARD_PARAMETERS)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.policy: GuardPolicy | None = None
        self.worker: BandWorker | None = None
        self.model: SqueakModel | None = None
        self.last: GuardStep | None = None
        self.command: float | None = None
        self.error = ""
        self.active = False
        self._inputs: dict[str, tuple[float, float]] = {}  # LOAD/NUT -> (value, monotonic s)
        self._subscriptions_own: list = []
        self._outputs: dict[str, Any] = {}
        self.diagnostics: Updater | None = None
        self._timer: Timer | None = None
        self._shown: tuple[bool, str] | None = None  # guard/active, guard/reason published
        self._verdict: tuple | None = None  # of the last forced /diagnostics
        self._logged: set[str] = set()  # fail-safe kinds said in the log
        self._unit_id = ""
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        if autostart and self.trigger_configure() == TransitionCallbackReturn.SUCCESS:
            self.trigger_activate()

    # ---------------------------------------------------------------- lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Read and check the parameters, build the model, the policy and the band thread;
        create the publishers and subscriptions. A bad parameter: FAILURE, one log line."""
        values = self._values({})
        try:
            settings = build(GuardSettings, values)
            own = build(NodeSettings, values)
            model = squeak_model(values)
        except (ParameterError, TypeError, ValueError) as exc:
            self.error = " ".join(str(exc).split())
            self.get_logger().error(f"configure failed: {self.error}")
            return TransitionCallbackReturn.FAILURE
        self.error = ""
        self.model = model
        self.policy = GuardPolicy(settings)
        self.worker = BandWorker(self.policy, model)
        sensor = QoSProfile(
            depth=own.input_queue_depth,
            reliability=qos_profile_sensor_data.reliability,
            durability=qos_profile_sensor_data.durability,
        )
        self._subscriptions_own = [
            self.create_subscription(Float64, COMMAND, self._on_command, sensor),
            self.create_subscription(Float64, LOAD, lambda m: self._on_input(LOAD, m), sensor),
            self.create_subscription(Float64, NUT, lambda m: self._on_input(NUT, m), sensor),
        ]
        self._outputs = {
            GUARDED: self.create_lifecycle_publisher(Float64, GUARDED, COMMAND_QOS),
            ACTIVE: self.create_lifecycle_publisher(Bool, ACTIVE, LATCHED),
            REASON: self.create_lifecycle_publisher(String, REASON, LATCHED),
        }
        self.diagnostics = Updater(
            self,
            LATCHED,
            own.diagnostics_period_s,
            own.hardware_id,
            publish=self._publish_diagnostics,
        )
        self.diagnostics.add(GUARD_TASK, self._guard_status)
        self._unit_id = own.unit_id
        self.get_logger().info(
            f"configured: p_max {settings.p_max:g}, "
            f"{'enabled' if settings.enabled else 'disabled (exact pass-through)'}"
        )
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start publishing (the guarded command, guard/active, guard/reason, /diagnostics)."""
        self.active = True
        self._shown = self._verdict = None  # republish the state
        self._timer = self.create_timer(
            HOUSEKEEPING_PERIOD_S, self._housekeeping, clock=self._steady
        )
        result = super().on_activate(state)  # enables the lifecycle publishers
        self._diagnose(periodic=False)
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop publishing: commands pass nowhere until activated again."""
        self._stop_publishing()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything configure made (the band thread ends)."""
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state: stop publishing and release everything."""
        self._stop_publishing()
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """A transition raised: release everything, back to unconfigured."""
        self._stop_publishing()
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def destroy_node(self) -> None:
        """Release everything (the band thread ends), then destroy the node."""
        self._stop_publishing()
        self._release()
        super().destroy_node()

    def _stop_publishing(self) -> None:
        self.active = False
        for pub in self._outputs.values():
            pub.on_deactivate(None)
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None

    def _release(self) -> None:
        if self.worker is not None:
            self.worker.close()
        for sub in self._subscriptions_own:
            self.destroy_subscription(sub)
        for pub in self._outputs.values():
            self.destroy_lifecycle_publisher(pub)
        if self.diagnostics is not None:
            self.destroy_publisher(self.diagnostics.publisher)
        self._subscriptions_own, self._outputs = [], {}
        self.diagnostics = self.worker = self.policy = self.model = None
        self.last = self.command = None
        self._inputs.clear()
        self._logged.clear()

    # ---------------------------------------------------------------- parameters
    def _values(self, changes: dict) -> dict:
        return {
            **{p.name: p.value for p in self.get_parameters(GUARD_PARAMETER_NAMES)},
            **changes,
        }

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """The new set as a whole must make valid settings (and a model); else nothing
        changes."""
        changes = {p.name: p.value for p in params}
        try:
            values = self._values(changes)
            for group in GUARD_GROUPS:
                build(group.cls, values)
            if set(changes) & MODEL_NAMES:
                squeak_model(values)
        except (ParameterError, TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """While configured: new guard settings at once (the tracker keeps its state; new
        p_max: the bands are searched again), new model parameters a new model and band
        cache; the node's own settings at the next configure."""
        if self.policy is None:
            return  # read at configure
        names = {p.name for p in params}
        values = self._values({})
        settings = build(GuardSettings, values)
        if names & MODEL_NAMES or settings.p_max != self.policy.settings.p_max:
            assert self.worker is not None  # configured
            self.worker.close()
            if names & MODEL_NAMES:
                self.model = squeak_model(values)
            self.policy.bands.clear()
            self.policy.wanted.clear()
            assert self.model is not None
            self.worker = BandWorker(self.policy, self.model)
        self.policy.settings = settings

    # ---------------------------------------------------------------- inputs
    def _on_input(self, topic: str, msg: Float64) -> None:
        self._inputs[topic] = (msg.data, time.monotonic())

    def _on_command(self, msg: Float64) -> None:
        """One command: one step of the policy (O(1)), the guarded command published."""
        arrived = time.monotonic()
        policy = self.policy
        if not self.active or policy is None:
            return  # inactive: commands pass nowhere
        load, nut = self._inputs.get(LOAD), self._inputs.get(NUT)
        age = arrived - min(load[1], nut[1]) if load and nut else 0.0
        step = policy.step(
            arrived,
            msg.data,
            load[0] if load else None,
            nut[0] if nut else None,
            age,
            arrived_s=arrived,
        )
        self._outputs[GUARDED].publish(Float64(data=step.speed_rad_s))
        assert self.worker is not None  # configured with the policy
        self.worker.poke()  # a bin wanted: the band thread computes it
        self.last, self.command = step, msg.data
        shown = (step.active, step.reason)
        if shown != self._shown:
            self._outputs[ACTIVE].publish(Bool(data=step.active))
            self._outputs[REASON].publish(String(data=step.reason))
            self._shown = shown
        if step.fault and step.fault not in self._logged:
            self._logged.add(step.fault)
            self.get_logger().warning(f"fail-safe ({step.fault}): {step.reason}")
        self._diagnose(periodic=False)

    # ---------------------------------------------------------------- diagnostics
    def _publish_diagnostics(self, publisher: Any, data: bytes, stamp_ns: int) -> None:
        if self.active:  # inactive: nothing published
            publisher.publish(data)

    def _housekeeping(self) -> None:
        if self.worker is not None:
            self.worker.poke()
        self._diagnose(periodic=True)

    def _diagnose(self, periodic: bool) -> None:
        """/diagnostics at once when the verdict changed, else (`periodic`) on its period."""
        if self.diagnostics is None or self.policy is None:
            return
        step = self.last
        verdict = (self.policy.settings.enabled, step and step.fault, step and step.active)
        if verdict != self._verdict:
            self.diagnostics.force_update()
            self._verdict = verdict
        elif periodic:
            self.diagnostics.update()

    def _guard_status(self, stat: DiagnosticStatusWrapper) -> DiagnosticStatusWrapper:
        """WARN with the reason in fail-safe, else OK (guarding, or disabled)."""
        policy, step = self.policy, self.last
        assert policy is not None  # a status only while configured
        enabled = policy.settings.enabled
        if not enabled:
            stat.summary(Level.OK, "disabled: the command passes through exactly")
        elif step is None:
            stat.summary(Level.OK, "guarding: no speed command yet")
        elif step.fault:
            stat.summary(Level.WARN, f"fail-safe: {step.reason}")
        else:
            stat.summary(Level.OK, f"guarding: {step.reason or 'command passed through'}")
        stat.add(KEY_ENABLED, str(enabled).lower())
        stat.add(KEY_ACTIVE, str(bool(step and step.active)).lower())
        stat.add(KEY_REASON, step.reason if step else "")
        stat.add(KEY_FAULT, step.fault if step else "")
        stat.add(KEY_COMMAND, "" if self.command is None else f"{self.command:.6g}")
        stat.add(KEY_GUARDED, f"{step.speed_rad_s:.6g}" if step else "")
        stat.add(KEY_BINS, len(policy.bands))
        stat.add(KEY_WANTED, len(policy.wanted))
        stat.add(KEY_UNIT, self._unit_id)
        return stat


def usage() -> str:
    """`squeak_guard --help`: how to run it, its topics, lifecycle and every parameter with
    unit, default and range."""
    return "\n".join(
        [
            "usage: squeak_guard [-h] [--no-autostart] [--ros-args [-r __ns:=/NAMESPACE] "
            "[-p NAME:=VALUE] [--params-file FILE] ...]",
            "",
            __doc__.splitlines()[0].replace("`", ""),
            "",
            "Subscribes (sensor-data QoS, relative to the namespace):",
            f"  {COMMAND} (std_msgs/Float64) [rad/s], {LOAD} (std_msgs/Float64) [N],",
            f"  {NUT} (std_msgs/Float64) [m]",
            "Publishes:",
            f"  {GUARDED} (std_msgs/Float64) [rad/s]: the guarded command, one per command "
            "(reliable, depth 10),",
            f"  {ACTIVE} (std_msgs/Bool): the command is being changed, {REASON} "
            "(std_msgs/String): why it was changed or passed through (reliable, transient "
            "local, depth 1; on change),",
            f"  /diagnostics (diagnostic_msgs/DiagnosticArray: '<node>: {GUARD_TASK}', WARN "
            "with the reason in fail-safe)",
            "Managed (lifecycle) node: configure (parameters, model), activate (publishing), "
            "deactivate, cleanup, shutdown via ~/change_state; --no-autostart waits in "
            "unconfigured for a lifecycle manager (default: configure and activate at start)",
            "",
            "Parameters (name [unit] = default, range: description):",
            *help_lines(GUARD_PARAMETERS),
            "",
            "Example: squeak_guard --ros-args -r __ns:=/seat_left --params-file "
            "config/leadscrew.yaml -p guard.p_max:=0.05",
            "(the predictor's params file: config/leadscrew.yaml is keyed `/**:`)",
        ]
    )


def main(args: list[str] | None = None) -> int:
    """Run the node until SIGINT/SIGTERM; exit 0 on that requested shutdown (with the line
    `squeak_guard: stopped by SIGTERM` (or SIGINT) on stderr), 2 on bad parameters or
    arguments (with autostart: a configure that failed); `-h`/`--help` prints `usage()`."""
    argv = list(sys.argv if args is None else args)
    try:
        own_args = checked_ros_args(lambda: remove_ros_args(argv))[1:]
    except ValueError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    if {"-h", "--help"} & set(own_args):
        print(usage())
        return 0
    autostart = "--no-autostart" not in own_args
    unknown = [a for a in own_args if a != "--no-autostart"]
    if unknown:
        print(
            f"{PROG}: error: unrecognized arguments: {' '.join(unknown)} (ROS "
            "arguments go after --ros-args; see --help)",
            file=sys.stderr,
        )
        return 2
    ros_argv = [a for a in argv if a != "--no-autostart"]
    confine_to_localhost()
    with StopSignals() as stop:
        try:
            checked_ros_args(
                lambda: rclpy.init(args=ros_argv, signal_handler_options=SignalHandlerOptions.NO)
            )
        except ValueError as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return 2
        node = None
        try:
            node = SqueakGuardNode(autostart=False)
            if autostart:  # a failed configure: the one line below, not the log's too
                logger = node.get_logger()
                level = logger.get_effective_level()
                logger.set_level(LoggingSeverity.FATAL)
                configured = node.trigger_configure() == TransitionCallbackReturn.SUCCESS
                logger.set_level(level)
                if not configured:
                    print(f"{PROG}: error: {node.error}", file=sys.stderr)
                    return 2
                node.trigger_activate()
            executor = make_executor()
            executor.add_node(node)
            while not stop.signum:
                executor.spin_once(timeout_sec=0.1)
        except (ParameterError, ParameterException) as exc:
            print(f"{PROG}: error: {' '.join(str(exc).split())}", file=sys.stderr)
            return 2
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return stop.exit_status(NODE_NAME)


if __name__ == "__main__":
    sys.exit(main())
