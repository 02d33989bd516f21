"""ROS 2 node `squeak_predictor`: live squeak prediction beside an actuator controller.

Subscribes (sensor-data QoS): motor_speed (std_msgs/Float64, rad/s), axial_load (Float64, N),
nut_position (Float64, m) and joint_states (sensor_msgs/JointState, joint `joint_name`).
Publishes (reliable, transient local, depth 1): squeak/risk, squeak/unstable_frequencies,
squeak/active, squeak/modes, squeak/safe_speed and /diagnostics.
Records inputs and outputs to MCAP (`record.*` parameters, std_srvs/SetBool `~/record`).
The physics lives in `leadscrew_ros.model`, the recompute policy in `leadscrew_ros.live`, the
recording in `leadscrew_ros.recorder`.
"""

from __future__ import annotations

import math
import signal
import sys
import time
from dataclasses import fields

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import ParameterException
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Float64MultiArray, MultiArrayDimension
from std_srvs.srv import SetBool

from .live import Level, LivePredictor, LiveSettings, Status
from .model import ParameterError, Prediction, ScrewParameters, SqueakModel
from .model.parameters import FORMULATIONS
from .recorder import COMPRESSIONS, Recorder, RecordSettings
from .ros_env import confine_to_localhost

NODE_NAME = "squeak_predictor"
MODE_COLUMNS = ("frequency_hz", "growth_rate", "damping_ratio")
HOUSEKEEPING_PERIOD_S = 0.05
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST)

# The node's own parameters: name -> (default, unit, description, (lo, hi) or None, read_only).
NODE_PARAMETERS: dict[str, tuple] = {
    "speed_deadband_rad_s": (0.1, "rad/s", "recompute when the speed moved more than this",
                             (0.0, 1000.0), False),
    "load_deadband_n": (1.0, "N", "recompute when the load moved more than this",
                        (0.0, 1e5), False),
    "nut_deadband_m": (0.0005, "m", "re-integrate the contact when the nut moved more than "
                       "this", (0.0, 1.0), False),
    "max_rate_hz": (100.0, "Hz", "maximum recompute rate (bursts are coalesced)",
                    (0.1, 10000.0), False),
    "risk_warn_threshold": (0.5, "1", "diagnostic WARN above this squeak risk", (0.0, 1.0),
                            False),
    "stale_timeout_s": (1.0, "s", "diagnostic STALE when speed or load is older than this",
                        (0.01, 3600.0), False),
    "diagnostics_period_s": (1.0, "s", "period of /diagnostics when nothing changes",
                             (0.05, 60.0), False),
    "safe_speed_margin": (0.05, "1", "relative distance kept from a squeak band edge by "
                          "squeak/safe_speed", (0.0, 0.5), False),
    "joint_name": ("", "", "screw joint in joint_states ('' ignores joint_states)", None, False),
    "nut_position_at_zero_angle_m": (0.15, "m", "nut position when the screw joint angle is 0; "
                                     "the nut travels R tan(beta) per radian", (-100.0, 100.0),
                                     False),
    "hardware_id": ("leadscrew", "", "hardware_id of the diagnostic status", None, True),
    "input_queue_depth": (5, "1", "queue depth of the input subscriptions", (1, 1000), True),
    "record.enabled": (False, "", "record inputs and outputs to MCAP (also ~/record)", None,
                       False),
    "record.directory": (".", "", "directory that receives one squeak_<UTC time> bag per "
                         "recording; must exist", None, False),
    "record.split_size_mb": (512.0, "MB", "start a new file beyond this size (0: never)",
                             (0.0, 1e6), False),
    "record.split_duration_s": (600.0, "s", "start a new file after this long (0: never)",
                                (0.0, 1e7), False),
    "record.compression": ("zstd", "", f"chunk compression: {' | '.join(COMPRESSIONS)}", None,
                           False),
    "record.flush_period_s": (0.5, "s", "hand recorded data to the OS this often: the most a "
                              "killed process loses", (0.05, 10.0), False),
}
LIVE_FIELDS = {f.name for f in fields(LiveSettings)}
RECORD_PREFIX = "record."


def _descriptor(name: str, default, unit: str, description: str, bounds, read_only: bool,
                extra: str = "") -> ParameterDescriptor:
    d = ParameterDescriptor(name=name, description=f"{description} [{unit}]" if unit else
                            description, read_only=read_only, additional_constraints=extra)
    if bounds is not None and isinstance(default, float):
        d.floating_point_range = [FloatingPointRange(from_value=float(bounds[0]),
                                                     to_value=float(bounds[1]))]
    elif bounds is not None and isinstance(default, int):
        d.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]),
                                        step=1)]
    return d


class SqueakPredictorNode(Node):
    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._declare_parameters()
        self.live = LivePredictor(SqueakModel(self._screw_parameters({})),
                                  self._live_settings({}))
        self.recorder = Recorder(self._record_settings({}))
        self.latched: dict[str, object] = {}          # topic -> last message published on it
        self._published: tuple | None = None          # verdict of the last /diagnostics
        self._last_diagnostics = -math.inf

        depth = self.get_parameter("input_queue_depth").value
        sensor = QoSProfile(depth=depth, reliability=qos_profile_sensor_data.reliability,
                            durability=qos_profile_sensor_data.durability)
        # Best-effort inputs and reliable transient-local outputs match every peer's QoS, so
        # the default QoS-event handlers could never fire; without them each executor cycle
        # waits on 20 fewer entities (measured: lower input-to-risk latency).
        sub_events = SubscriptionEventCallbacks(use_default_callbacks=False)
        pub_events = PublisherEventCallbacks(use_default_callbacks=False)

        def subscribe(msg_type, topic, callback):
            sub = self.create_subscription(msg_type, topic, lambda msg: callback(msg, sub),
                                           sensor, event_callbacks=sub_events)

        def publisher(msg_type, topic):
            return self.create_publisher(msg_type, topic, LATCHED, event_callbacks=pub_events)

        subscribe(Float64, "motor_speed", self._on_speed)
        subscribe(Float64, "axial_load", self._on_load)
        subscribe(Float64, "nut_position", self._on_nut_position)
        subscribe(JointState, "joint_states", self._on_joint_states)
        self.risk_pub = publisher(Float64, "squeak/risk")
        self.frequencies_pub = publisher(Float64MultiArray, "squeak/unstable_frequencies")
        self.active_pub = publisher(Bool, "squeak/active")
        self.modes_pub = publisher(Float64MultiArray, "squeak/modes")
        self.safe_speed_pub = publisher(Float64, "squeak/safe_speed")
        self.diagnostics_pub = publisher(DiagnosticArray, "/diagnostics")

        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        # Housekeeping (staleness, bad-input verdict, periodic diagnostics) at a fixed slow
        # rate; the rate-limit timer runs only while an input waits for the rate limit.
        self.create_timer(HOUSEKEEPING_PERIOD_S, self._housekeeping)
        self._rate_timer = self._create_rate_timer()
        self.create_service(SetBool, "~/record", self._on_record_service)
        if self.get_parameter("record.enabled").value:
            self._set_recording(True)
        self._publish_diagnostics(time.monotonic())

    def destroy_node(self) -> None:
        self.live.close()                     # the background safe-speed search ends too
        self.recorder.stop()                  # summary, index and footer: a clean file
        super().destroy_node()

    # ---------------------------------------------------------------- parameters
    def _declare_parameters(self) -> None:
        for f in fields(ScrewParameters):
            md = f.metadata
            extra = f"one of: {', '.join(FORMULATIONS)}" if f.name == "formulation" else (
                "open bound" if md.get("lo_open") or md.get("hi_open") else "")
            bounds = None if md.get("lo") is None else (md["lo"], md["hi"])
            self.declare_parameter(f.name, f.default, _descriptor(
                f.name, f.default, md["unit"], md["description"], bounds, False, extra))
        for name, (default, unit, description, bounds, read_only) in NODE_PARAMETERS.items():
            self.declare_parameter(name, default, _descriptor(name, default, unit, description,
                                                              bounds, read_only))

    def _values(self, changes: dict) -> dict:
        return {**{p.name: p.value for p in self.get_parameters(
            [f.name for f in fields(ScrewParameters)] + list(NODE_PARAMETERS))}, **changes}

    def _screw_parameters(self, changes: dict) -> ScrewParameters:
        values = self._values(changes)
        return ScrewParameters(**{f.name: values[f.name] for f in fields(ScrewParameters)})

    def _live_settings(self, changes: dict) -> LiveSettings:
        values = self._values(changes)
        return LiveSettings(**{k: values[k] for k in LIVE_FIELDS})

    def _record_settings(self, changes: dict) -> RecordSettings:
        values = self._values(changes)
        return RecordSettings(**{k[len(RECORD_PREFIX):]: v for k, v in values.items()
                                 if k.startswith(RECORD_PREFIX) and k != "record.enabled"})

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """The new set as a whole must make a valid model and recorder; else nothing changes."""
        changes = {p.name: p.value for p in params}
        try:
            self._screw_parameters(changes)
            self._record_settings(changes)
        except (ParameterError, TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        names = {p.name for p in params}
        if names & ({f.name for f in fields(ScrewParameters)} | LIVE_FIELDS):
            model_changed = bool(names & set(ScrewParameters.__dataclass_fields__))
            model = SqueakModel(self._screw_parameters({})) if model_changed else self.live.model
            self.live.set_model(model, self._live_settings({}))
            if "max_rate_hz" in names:
                self.destroy_timer(self._rate_timer)
                self._rate_timer = self._create_rate_timer()
            self._recompute(time.monotonic())
        if any(n.startswith(RECORD_PREFIX) for n in names):
            settings = self._record_settings({})
            if settings != self.recorder.settings:      # takes effect with a new bag
                self.recorder.stop()
                self.recorder = Recorder(settings)
            self._set_recording(self.get_parameter("record.enabled").value)

    def _create_rate_timer(self):
        timer = self.create_timer(1.0 / self.live.settings.max_rate_hz, self._on_rate_timer)
        timer.cancel()
        return timer

    # ---------------------------------------------------------------- recording
    def _set_recording(self, on: bool) -> None:
        if on and not self.recorder.active:
            now_ns = self.get_clock().now().nanoseconds
            if self.recorder.start(now_ns):
                self.get_logger().info(f"recording to {self.recorder.bag}")
                for topic, msg in self.latched.items():   # a bag starts with the current state,
                    self.recorder.write(topic, msg, now_ns)   # as a latched subscriber gets it
            else:
                self.get_logger().error(f"recording failed: {self.recorder.error}")
        elif not on and self.recorder.active:
            self.recorder.stop()
            self.get_logger().info(f"recording stopped: {self.recorder.bag}")
        # /diagnostics follows within a housekeeping period: the verdict includes recording

    def _on_record_service(self, request: SetBool.Request, response: SetBool.Response
                           ) -> SetBool.Response:
        """Start (data=true) or stop recording; `record.enabled` follows."""
        self.set_parameters([Parameter("record.enabled", value=bool(request.data))])
        response.success = self.recorder.active == request.data
        response.message = (str(self.recorder.path) if self.recorder.active else
                            self.recorder.error or f"stopped; last bag: {self.recorder.bag}")
        return response

    def _record(self, topic: str, msg) -> None:
        if self.recorder.active:
            self.recorder.write(topic, msg, self.get_clock().now().nanoseconds)

    def _publish(self, publisher, msg) -> None:
        publisher.publish(msg)
        self.latched[publisher.topic_name] = msg
        self._record(publisher.topic_name, msg)

    # ---------------------------------------------------------------- inputs
    def _on_speed(self, msg: Float64, sub) -> None:
        self._record(sub.topic_name, msg)
        self._input(self.live.set_speed(msg.data, time.monotonic()))

    def _on_load(self, msg: Float64, sub) -> None:
        self._record(sub.topic_name, msg)
        self._input(self.live.set_load(msg.data, time.monotonic()))

    def _on_nut_position(self, msg: Float64, sub) -> None:
        self._record(sub.topic_name, msg)
        self._input(self.live.set_nut_position(msg.data, time.monotonic()))

    def _on_joint_states(self, msg: JointState, sub) -> None:
        self._record(sub.topic_name, msg)
        joint = self.get_parameter("joint_name").value
        if not joint or joint not in msg.name:
            return
        i, now = msg.name.index(joint), time.monotonic()
        errors = []                     # both inputs first: one recompute at the new point
        if i < len(msg.velocity):
            errors.append(self.live.set_speed(msg.velocity[i], now))
        if i < len(msg.position):
            p = self.live.model.params
            lead = p.radius_m * math.tan(p.helix_angle_rad)              # m per radian
            z = self.get_parameter("nut_position_at_zero_angle_m").value + msg.position[i] * lead
            errors.append(self.live.set_nut_position(z, now))
        self._input("; ".join(e for e in errors if e), now)

    def _input(self, error: str, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        if error:                 # the next tick reports it: a flood of bad input stays bounded
            self.get_logger().warning(f"input rejected: {error}", throttle_duration_sec=2.0)
        elif self.live.due(now):
            self._recompute(now)
        elif self.live.changed() and self._rate_timer.is_canceled():
            self._rate_timer.reset()         # held back by the rate limit: recompute later

    # ---------------------------------------------------------------- outputs
    def _on_rate_timer(self) -> None:
        now = time.monotonic()
        if self.live.due(now):
            self._recompute(now)
        if not self.live.changed():
            self._rate_timer.cancel()

    def _housekeeping(self) -> None:
        self.recorder.tick(self.get_clock().now().nanoseconds)
        now = time.monotonic()
        if self.live.poll_advice():          # a background safe-speed search has finished
            self._publish_safe_speed()
        status = self.live.status(now)
        if (now - self._last_diagnostics >= self.get_parameter("diagnostics_period_s").value
                or self._verdict(status) != self._published):  # e.g. bad input, input went stale
            self._publish_diagnostics(now, status)

    def _verdict(self, status: Status) -> tuple:
        """What /diagnostics says: republished when it changes."""
        return status.level, status.message, self.recorder.active, self.recorder.error

    def _recompute(self, now: float) -> None:
        p = self.live.update(now)
        status = self.live.status(now)
        if p is None:                        # outside validity: keep the last good outputs
            self.get_logger().warning(status.message, throttle_duration_sec=2.0)
        else:
            self._publish_prediction(p)
        if self._verdict(status) != self._published:  # else the housekeeping period covers it
            self._publish_diagnostics(now, status)

    def _publish_prediction(self, p: Prediction) -> None:
        self._publish(self.risk_pub, Float64(data=float(p.risk)))
        self._publish(self.frequencies_pub, frequencies_message(p))
        self._publish(self.active_pub, Bool(data=not p.stable))
        self._publish(self.modes_pub, modes_message(p))
        if not self.live.advice_pending:     # else the last advice stays until the new one
            self._publish_safe_speed()

    def _publish_safe_speed(self) -> None:
        if self.live.safe_speed_rad_s is not None:
            self._publish(self.safe_speed_pub, Float64(data=float(self.live.safe_speed_rad_s)))

    def _publish_diagnostics(self, now: float, status: Status | None = None) -> None:
        status = self.live.status(now) if status is None else status
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        hardware_id = self.get_parameter("hardware_id").value
        msg.status = [DiagnosticStatus(
            level=bytes([int(status.level)]), name=f"{self.get_name()}: squeak prediction",
            message=status.message, hardware_id=hardware_id,
            values=[KeyValue(key=k, value=v) for k, v in status.values.items()]),
            self._recording_status(hardware_id)]
        self._publish(self.diagnostics_pub, msg)
        self._published, self._last_diagnostics = self._verdict(status), now

    def _recording_status(self, hardware_id: str) -> DiagnosticStatus:
        r = self.recorder
        if r.error:
            level, message = Level.ERROR, r.error
        elif r.active:
            level, message = Level.OK, f"recording to {r.path}"
        else:
            level, message = Level.OK, "not recording"
        values = {"bag": str(r.bag or ""), "files": str(len(r.files)),
                  "messages": str(r.messages)}
        return DiagnosticStatus(level=bytes([int(level)]), name=f"{self.get_name()}: recording",
                                message=message, hardware_id=hardware_id,
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])


def frequencies_message(p: Prediction) -> Float64MultiArray:
    """Squeak frequencies [Hz], most unstable first."""
    msg = Float64MultiArray(data=p.unstable_frequencies_hz)
    msg.layout.dim = [MultiArrayDimension(label="frequency_hz", size=len(msg.data),
                                          stride=len(msg.data))]
    return msg


def modes_message(p: Prediction) -> Float64MultiArray:
    """Rows = oscillatory modes (growth rate descending), columns = MODE_COLUMNS; the row
    dimension's label lists the mode labels."""
    msg = Float64MultiArray(data=[v for m in p.modes for v in
                                  (m.frequency_hz, m.growth_rate, m.damping_ratio)])
    rows, cols = len(p.modes), len(MODE_COLUMNS)
    msg.layout.dim = [
        MultiArrayDimension(label="modes:" + ",".join(m.label for m in p.modes), size=rows,
                            stride=rows * cols),
        MultiArrayDimension(label=",".join(MODE_COLUMNS), size=cols, stride=cols)]
    return msg


def main(args: list[str] | None = None) -> int:
    """Run the node until SIGINT/SIGTERM; exit 0 on a clean shutdown, 2 on bad parameters."""
    confine_to_localhost()
    # SIGINT/SIGTERM only set `stop`; the loop ends between callbacks. rclpy's own handlers
    # shut the context down from another thread (a publish in flight then fails with "context
    # is invalid", exit 1 with a traceback) or raise KeyboardInterrupt inside any callback.
    stop: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: stop.append(signum))
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = SqueakPredictorNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not stop:
            executor.spin_once(timeout_sec=0.1)    # stops after the current callback
    except (ParameterError, ParameterException) as exc:
        print(f"{NODE_NAME}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
