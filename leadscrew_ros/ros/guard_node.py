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
`--no-autostart`) the constructor configures and activates (`ros.managed.ManagedNode.start`:
a bad parameter raises). Parameters are read at configure;
a set while configured is checked as a whole and applied at once (new `guard.*` settings keep
the tracker's state; new model parameters a new model and band cache).
"""

from __future__ import annotations

import sys
import time
from functools import partial
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.parameter import Parameter
from rclpy.qos import (
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.timer import Timer
from std_msgs.msg import Bool, Float64, String

from ..bag import messages
from ..live.guard import BandWorker, GuardPolicy, GuardSettings, GuardStep
from ..live.status import Level
from ..model import ParameterError, ScrewParameters, SqueakModel
from ..model.uncertainty.scatter import ScatterSettings
from .diagnostics import DiagnosticStatusWrapper, Updater
from .managed import ManagedNode, one_line, run
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


class SqueakGuardNode(ManagedNode):
    """The `squeak_guard` node (the module's topics, parameters and lifecycle): wires the ROS
    interfaces to a `GuardPolicy` and its `BandWorker`.

    Parameters
    ----------
    autostart : bool
        Configure and activate in the constructor (`ManagedNode.start`: a bad parameter
        raises `ParameterError`).
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
        self._inputs: dict[str, tuple[float, float]] = {}  # LOAD/NUT -> (value, monotonic s)
        self._outputs: dict[str, Any] = {}
        self.diagnostics: Updater | None = None
        self._timer: Timer | None = None
        self._shown: tuple[bool, str] | None = None  # guard/active, guard/reason published
        self._verdict: tuple | None = None  # of the last forced /diagnostics
        self._logged: set[str] = set()  # fail-safe kinds said in the log
        self._unit_id = ""
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        if autostart:
            self.start()

    @property
    def error(self) -> str:
        """Why the last transition failed, in one line ('' if it did not)."""
        return one_line(self.failure) if self.failure is not None else ""

    # ---------------------------------------------------------------- lifecycle
    def configure(self) -> None:
        """Read and check the parameters, build the model, the policy and the band thread;
        create the publishers and subscriptions (a bad parameter raises)."""
        values = self._values({})
        try:
            settings = build(GuardSettings, values)
            own = build(NodeSettings, values)
            model = squeak_model(values)
        except (TypeError, ValueError) as exc:
            raise ParameterError(" ".join(str(exc).split())) from exc
        self.model = model
        self.policy = GuardPolicy(settings)
        self.worker = BandWorker(self.policy, model)
        sensor = QoSProfile(
            depth=own.input_queue_depth,
            reliability=qos_profile_sensor_data.reliability,
            durability=qos_profile_sensor_data.durability,
        )
        self.own(self.create_subscription(Float64, COMMAND, self._on_command, sensor))
        for topic in (LOAD, NUT):
            self.own(
                self.create_subscription(Float64, topic, partial(self._on_input, topic), sensor)
            )
        self._outputs = {
            GUARDED: self.own(self.create_lifecycle_publisher(Float64, GUARDED, COMMAND_QOS)),
            ACTIVE: self.own(self.create_lifecycle_publisher(Bool, ACTIVE, LATCHED)),
            REASON: self.own(self.create_lifecycle_publisher(String, REASON, LATCHED)),
        }
        self.diagnostics = Updater(
            self,
            LATCHED,
            own.diagnostics_period_s,
            own.hardware_id,
            publish=self._publish_diagnostics,
        )
        self.own(self.diagnostics.publisher)
        self.diagnostics.add(GUARD_TASK, self._guard_status)
        self._unit_id = own.unit_id
        self.get_logger().info(
            f"configured: p_max {settings.p_max:g}, "
            f"{'enabled' if settings.enabled else 'disabled (exact pass-through)'}"
        )

    def activate(self) -> None:
        """Start publishing (the guarded command, guard/active, guard/reason, /diagnostics)."""
        self._shown = self._verdict = None  # republish the state
        self._timer = self.own_timer(HOUSEKEEPING_PERIOD_S, self._housekeeping, clock=self._steady)
        self._diagnose(periodic=False)

    def deactivate(self) -> None:
        """Stop publishing: commands pass nowhere until activated again."""
        if self._timer is not None:
            self.destroy_owned(self._timer)
            self._timer = None

    def release(self) -> None:
        """Release everything configure made (the band thread ends)."""
        if self.worker is not None:
            self.worker.close()
        self.destroy_owned()
        self._outputs, self._timer = {}, None
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
    """Run the node until SIGINT/SIGTERM (`managed.run`): exit 0 on that requested shutdown
    (with the line `squeak_guard: stopped by SIGTERM` (or SIGINT) on stderr), 2 on bad
    parameters or arguments (with autostart: a configure that failed); `-h`/`--help` prints
    `usage()`."""
    return run(
        lambda autostart: SqueakGuardNode(autostart=autostart),
        PROG,
        NODE_NAME,
        usage,
        make_executor,
        args,
    )


if __name__ == "__main__":
    sys.exit(main())
