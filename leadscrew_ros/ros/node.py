# SPDX-License-Identifier: Apache-2.0
"""ROS 2 node `squeak_predictor`: live squeak prediction beside an actuator controller.

Subscribes (sensor-data QoS): motor_speed (rad/s), axial_load (N), nut_position (m), each a
std_msgs/Float64 or any installed type with the number at a field path times a scale
(`inputs.<input>.type`, `.field`, `.scale`: `ros.input_fields`), and joint_states
(sensor_msgs/JointState, joint `joint_name`).
Publishes (reliable, transient local, depth 1): squeak/risk (P(squeak) over the parameter
scatter, `scatter.*` parameters), squeak/margin (least damping ratio at the nominal parameters),
squeak/unstable_frequencies, squeak/active, squeak/modes, squeak/safe_speed (nearest speed with
P(squeak) below `safe_probability`) and /diagnostics (levels by P: `warn_probability`,
`error_probability`).
Listens (`listen.*` parameters, off by default) to microphone (std_msgs/Float32MultiArray
chunks): the callback only queues the payload, a worker thread analyses it (`live.listen`), and
the housekeeping timer publishes squeak/heard, squeak/heard_frequency and a third diagnostic
status, the measurement (heard against predicted).
Records inputs and outputs to MCAP (`record.*` parameters, std_srvs/SetBool `~/record`):
inputs, and the guard's topics when anyone publishes them (`bag.messages.GUARD_TYPES`), from
subscriptions of their own that never wait for the model, with every lost message counted
(`ros.input_recording`); outputs as the CDR bytes it publishes (`bag.messages`); every
file begins with the `leadscrew_ros` metadata record of the parameters (`bag.logmeta`), and a
parameter change while recording starts a new file with the new record; on start, reports (or
recovers) its own bags cut off by an earlier crash (`bag.crash_recovery`).
A managed (lifecycle) node (`ros.managed`): configure builds all of the above, activate
publishes and records, deactivate stops both; `squeak_node --no-autostart` waits unconfigured
for a lifecycle manager. `squeak_node --help` lists the parameters and topics.
The physics lives in `model`, the input rules in `live.rules`, the recompute policy and the
verdict in `live.recompute`, the parameter table in `ros.parameters`, the /diagnostics updater
and the recording verdict in `ros.diagnostics`: this class wires them and keeps its callbacks
short.
"""

from __future__ import annotations

import contextlib
import gc
import sys
import time
from functools import partial
from typing import Any, NamedTuple

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.context import Context
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import Executor
from rclpy.experimental import EventsExecutor
from rclpy.lifecycle import LifecyclePublisher
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float32MultiArray, Float64, Float64MultiArray, String
from std_srvs.srv import SetBool

from ..bag import cdr, logmeta, messages, msgdefs
from ..bag.audio import LiveAudio
from ..bag.crash_recovery import CrashRecovery
from ..bag.recorder import Recorder, RecordSettings, ensure_directory
from ..live.listen import Decoder, Listener
from ..live.recompute import LivePredictor
from ..live.rules import SampleOrder
from ..live.settings import (
    INPUT_FIELDS,
    INPUTS_PREFIX,
    JointSettings,
    ListenSettings,
    LiveSettings,
)
from ..live.status import Status, inactive_status
from ..model import ParameterError, Prediction, ScrewParameters, SqueakModel
from ..model.acoustics.settings import DetectorSettings
from ..model.uncertainty.scatter import ScatterSettings
from .diagnostics import (
    MEASUREMENT_TASK,
    PREDICTION_TASK,
    RECORDING_TASK,
    RESUME_HINT,
    Updater,
    recording_status,
    status_task,
)
from .input_fields import InputReader, input_reader, stamp_ns
from .input_recording import InputRecording
from .managed import AUTOSTART_HELP, ManagedNode, run
from .parameters import (
    GROUPS,
    PARAMETER_NAMES,
    PARAMETERS,
    NodeSettings,
    RecordingControl,
    as_declared_type,
    build,
    descriptor,
    help_lines,
    log_metadata,
    names_of,
    squeak_model,
)

NODE_NAME = "squeak_predictor"
PROG = "squeak_node"  # the executable: its one-line errors name it, as argparse does
RECORD_SERVICE = "record"  # ~/record: std_srvs/SetBool, in the node's private namespace
HOUSEKEEPING_PERIOD_S = 0.05
# 'pkg/msg/Type' -> rclpy class, of the types the node publishes or records from the guard
_CLASSES = {msgdefs.type_name(c): c for c in (Float64, Float64MultiArray, Bool, String)}
# Output topic (`bag.messages`) -> rclpy class of its type (the payloads are CDR bytes).
OUTPUT_CLASSES = {topic: _CLASSES[t] for topic, t in messages.OUTPUT_TYPES.items()}
LATCHED = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)

# Input topic -> its default message class (`inputs.<input>.type` chooses another for the
# first three).
INPUTS = {
    "motor_speed": Float64,
    "axial_load": Float64,
    "nut_position": Float64,
    "joint_states": JointState,
}
FIELD_TOPICS = {"motor_speed": "speed", "axial_load": "load", "nut_position": "nut"}
SETTERS = {"speed": "set_speed", "load": "set_load", "nut": "set_nut_position"}  # LivePredictor's
LISTEN_CLASSES = {topic: _CLASSES[t] for topic, t in messages.LISTEN_TYPES.items()}
# The guard's topics (`bag.messages.GUARD_TYPES`): recorded while anyone publishes them
GUARD_CLASSES = {topic: _CLASSES[t] for topic, t in messages.GUARD_TYPES.items()}
# What ~/record answers for a start while inactive
INACTIVE_RECORDING = "node inactive: recording starts when it is activated"


class SoundInput(NamedTuple):
    """A sound input of the node (with `listen.enabled`): its message class and how a payload
    becomes samples (`live.listen.Decoder`, run on the listening thread)."""

    msg_type: type
    decode: Decoder


def float32_chunk(data: bytes) -> tuple[np.ndarray, None]:
    """Samples of a std_msgs/Float32MultiArray chunk (full scale; a layout of two dimensions
    whose second has size > 1 holds interleaved channels), at `listen.sample_rate_hz`.

    Parameters
    ----------
    data : bytes
        The CDR payload.

    Returns
    -------
    samples : numpy.ndarray
        float32, one column per channel when there are several.
    rate : None
        The message carries no sample rate.

    Raises
    ------
    ValueError
        A malformed payload.
    """
    msg = cdr.decode_float32_multi_array(data)
    x = msg.data[msg.data_offset :]
    if len(msg.dim) == 2 and msg.dim[1].size > 1:
        channels = msg.dim[1].size
        x = x[: x.size // channels * channels].reshape(-1, channels)
    return x, None


# Sound inputs (topic -> kind) subscribed with `listen.enabled` (AudioDataStamped, which needs
# an optional package, is subscribed apart: `AUDIO_COMMON_TOPICS`). Another kind is one more
# entry here with its decoder (samples and, when the payload carries it, the rate).
SOUND_INPUTS = {"microphone": SoundInput(Float32MultiArray, float32_chunk)}
# ros-drivers audio_common (released into Jazzy, not on PyPI): where its `audio_common_msgs` is
# importable, the node also hears the AudioDataStamped chunks of its audio_capture node, with
# their AudioInfo (topic -> type; decoded by `bag.audio.LiveAudio`).
AUDIO_COMMON_TOPICS = {
    "audio_stamped": "audio_common_msgs/msg/AudioDataStamped",
    "audio_info": "audio_common_msgs/msg/AudioInfo",
}


def audio_common_classes() -> tuple[type, type] | None:
    """The message classes of ros-drivers audio_common where that package is installed.

    Returns
    -------
    tuple of type or None
        (AudioDataStamped, AudioInfo); None without the package, or with the incompatible
        audio_common_msgs of the same name that has no AudioDataStamped.
    """
    try:
        from audio_common_msgs.msg import AudioDataStamped, AudioInfo  # type: ignore[import-not-found]
    except ImportError:
        return None
    return AudioDataStamped, AudioInfo


def make_executor(context: Context | None = None) -> Executor:
    """The executor the node runs on (`main`, the demo, the benchmarks and the tests).

    rclpy's `EventsExecutor` (C++): a ready input costs no wait-set rebuild in Python (the
    `SingleThreadedExecutor` rebuilds it every cycle, ~200 us here, two cycles per
    motor_speed -> squeak/risk round trip). What differs for a caller (rclpy 7.1.6): one event
    per `spin_once`, first in first out, timers without priority; events already queued for a
    node still run after `remove_node` (stop spinning, or drain, before destroying it);
    callbacks taking message info are not supported (`ros.input_recording` keeps its own
    `SingleThreadedExecutor` for that reason); it enables `faulthandler` on the process's
    stderr.

    Parameters
    ----------
    context : rclpy.context.Context, optional
        The context to spin; default: rclpy's default context.

    Returns
    -------
    rclpy.executors.Executor
        A new EventsExecutor (a C++ object with the Executor interface used here).
    """
    # EventsExecutor() calls faulthandler.enable(), which needs a sys.stderr with a file
    # descriptor (not so under pytest's capsys, in a notebook, ...): give it the process's own
    with contextlib.redirect_stderr(sys.__stderr__ or sys.stderr):
        return EventsExecutor(context=context)


def bag_prefix(namespace: str) -> str:
    """Bag name prefix of a node in `namespace`: '/seat_left' -> 'seat_left_squeak'."""
    return "_".join([p for p in namespace.split("/") if p] + ["squeak"])


class SqueakPredictorNode(ManagedNode):
    """The `squeak_predictor` node (the module's topics, parameters and recording): wires the
    ROS interfaces to a `LivePredictor`, a `Recorder` and the /diagnostics updater.

    A managed (lifecycle) node (`ros.managed`): the constructor declares the parameters;
    configure checks them and builds the model, subscriptions, publishers, timers, the
    ~/record service and /diagnostics; activate starts publishing (and recording with
    `record.enabled`); deactivate stops both (the bag is finished); cleanup and shutdown
    release what configure built. While inactive the inputs are not taken, nothing is
    predicted, published or recorded, and /diagnostics says so (STALE).

    Parameters
    ----------
    autostart : bool
        Configure and activate at once (an unmanaged node's behaviour); a bad parameter then
        raises `ParameterError`. False: the node stays unconfigured until a lifecycle
        transition.
    **kwargs
        Passed to `rclpy.lifecycle.LifecycleNode` (context, namespace, parameter overrides...).
    """

    # Made by `configure`, released by `release`
    live: LivePredictor
    joint: JointSettings
    readers: dict[str, InputReader]
    order: SampleOrder
    recorder: Recorder
    listener: Listener | None
    diagnostics: Updater
    output_pubs: dict[str, Publisher]
    listen_pubs: dict[str, Publisher]

    def __init__(self, autostart: bool = True, **kwargs: Any):
        super().__init__(NODE_NAME, **kwargs)
        self._declare_parameters()
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        # Housekeeping, rate limit and recording run on a steady clock: with use_sim_time a
        # paused /clock must not stop flushing, splitting, staleness and diagnostics (they
        # measure wall time, time.monotonic).
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._configured = False
        if autostart:
            self.start()

    # ---------------------------------------------------------------- lifecycle
    def configure(self) -> None:
        """Check the parameters and build everything the node runs on (nothing published
        yet); a bad parameter raises `ParameterError` (`ManagedNode` releases what was
        built)."""
        # Every check first (a bad parameter raises here, before anything is built)
        model, live_settings = self._model({}), self._live_settings({})
        self.joint = self._settings(JointSettings, {})
        # speed, load, nut: message class, precompiled field getter, header stamp
        self.readers = {name: self._reader(name, {}) for name in INPUT_FIELDS}
        own = self._settings(NodeSettings, {})
        listen = self._settings(ListenSettings, {})
        detector = self._settings(DetectorSettings, {})
        auto_recover = self._settings(RecordingControl, {}).auto_recover
        recorder = self._new_recorder(bag_prefix(self.get_namespace()), self._metadata())
        # this node's bags an earlier crash cut off (found now, recovered with auto_recover)
        self._crash_recovery = CrashRecovery(recorder.settings.directory, recorder.name)

        # What runs threads (`release` ends them)
        self.live = LivePredictor(model, live_settings)
        self.recorder = recorder
        self.listener = Listener(listen, detector) if listen.enabled else None
        self._input_recording: InputRecording | None = None
        self._configured = True
        self.order = SampleOrder()  # header stamps of the stamped inputs
        self.latched: dict[str, Latched] = {}  # topic -> last message published on it
        # Input topic -> its last accepted message, oldest first: the state a bag starts with
        self.accepted: dict[str, object] = {}
        self._incident_logged = ""
        self._diagnosed: tuple | None = None  # verdict of the last forced /diagnostics
        self._measurement: Status | None = None  # what the measurement task says

        sensor = QoSProfile(
            depth=own.input_queue_depth,
            reliability=qos_profile_sensor_data.reliability,
            durability=qos_profile_sensor_data.durability,
        )
        # Best-effort inputs and reliable transient-local outputs match every peer's QoS, so
        # the default QoS-event handlers could never fire; without them each executor cycle
        # waits on 20 fewer entities (measured: lower input-to-risk latency).
        sub_events = SubscriptionEventCallbacks(use_default_callbacks=False)
        pub_events = PublisherEventCallbacks(use_default_callbacks=False)
        self._inputs: dict[str, type] = {}  # fully qualified input topic -> message class

        def subscribe(msg_type, topic, callback, qos=sensor, raw=False, always=False):
            """An input's subscription; its messages are taken only while active (`always`:
            in every state)."""
            name = self.resolve_topic_name(topic)  # fully qualified
            self.own(
                self.create_subscription(
                    msg_type,
                    topic,
                    lambda msg: callback(name, msg) if always or self.active else None,
                    qos,
                    raw=raw,
                    event_callbacks=sub_events,
                )
            )
            self._inputs[name] = msg_type

        def publisher(msg_type, topic):
            """An output: a lifecycle publisher, silent while inactive."""
            return self.own(
                self.create_lifecycle_publisher(
                    msg_type, topic, LATCHED, event_callbacks=pub_events
                )
            )

        for topic, name in FIELD_TOPICS.items():
            subscribe(self.readers[name].msg_type, topic, partial(self._on_field, kind=name))
        subscribe(INPUTS["joint_states"], "joint_states", self._on_joint_states)
        self.output_pubs = {topic: publisher(cls, topic) for topic, cls in OUTPUT_CLASSES.items()}
        self.listen_pubs = {}
        if self.listener is not None:
            # Serialized payloads, queued as they are: the analysis thread decodes them
            sound = QoSProfile(
                depth=listen.queue_chunks,
                reliability=qos_profile_sensor_data.reliability,
                durability=qos_profile_sensor_data.durability,
            )
            for topic, kind in SOUND_INPUTS.items():
                on_sound = partial(self._on_sound, decode=kind.decode)
                subscribe(kind.msg_type, topic, on_sound, qos=sound, raw=True)
            classes = audio_common_classes()
            if classes is not None:
                audio = LiveAudio()
                stamped, info = classes

                def on_info(_topic: str, data: bytes, audio: LiveAudio = audio) -> None:
                    audio.info(data)

                # the format, kept in every state: the chunks after an activation need it
                subscribe(info, "audio_info", on_info, qos=sound, raw=True, always=True)
                on_sound = partial(self._on_sound, decode=audio)
                subscribe(stamped, "audio_stamped", on_sound, qos=sound, raw=True)
            self.listen_pubs = {
                topic: publisher(cls, topic) for topic, cls in LISTEN_CLASSES.items()
            }
        # Recorded beside the inputs, never taken by the model: the guard's topics
        self._recorded = {
            **self._inputs,
            **{self.resolve_topic_name(t): cls for t, cls in GUARD_CLASSES.items()},
        }
        # /diagnostics is no lifecycle publisher: it says what the node does in every state
        self.diagnostics = Updater(
            self,
            LATCHED,
            own.diagnostics_period_s,
            own.hardware_id,
            publish=lambda pub, data, stamp_ns: self._publish(pub, data, stamp_ns),
            event_callbacks=pub_events,
        )
        self.own(self.diagnostics.publisher)
        self._status = self._verdict(time.monotonic())  # what the prediction task says
        self.diagnostics.add(PREDICTION_TASK, status_task(lambda: self._status))
        self.diagnostics.add(
            RECORDING_TASK, lambda stat: recording_status(stat, self.recorder, self._crash_recovery)
        )
        if self.listener is not None:
            self._measurement = self.listener.status(time.monotonic())
            self.diagnostics.add(MEASUREMENT_TASK, status_task(self._measurement_status))

        # Housekeeping (staleness, bad-input verdict, periodic diagnostics) at a fixed slow
        # rate; the rate-limit timer runs only while an input waits for the rate limit.
        self.own_timer(HOUSEKEEPING_PERIOD_S, self._housekeeping, clock=self._steady)
        self._rate_timer = self._create_rate_timer()
        self.own(self.create_service(SetBool, f"~/{RECORD_SERVICE}", self._on_record_service))
        if self._crash_recovery.bags and auto_recover:
            self._crash_recovery.start()
        # /diagnostics from the first housekeeping tick: an autostart is active by then

    def activate(self) -> None:
        """Publish again (the last prediction at the current inputs, what was heard), record
        with `record.enabled`."""
        now = time.monotonic()
        if self.listener is not None:
            self._publish_heard()  # latched: nothing heard yet, or what was heard last
        if self.live.prediction is not None:  # parameters may have changed while inactive
            self._recompute(now)
        if self.get_parameter("record.enabled").value:
            self._set_recording(True)
            self._check_recording()
        self._diagnose(now, periodic=False)

    def deactivate(self) -> None:
        """Stop recording (the file finished: summary, index, footer); /diagnostics says
        inactive."""
        if self.recorder.active:
            self._stop_recording()
            self.get_logger().info(f"recording stopped: {self.recorder.bag}")
        self._diagnose(time.monotonic(), periodic=False)

    def release(self) -> None:
        """Stop the predictor, the listening and the recording (a clean file), wait for the
        crash recovery, destroy the subscriptions, publishers, timers and the service."""
        if not self._configured:
            return
        self._configured = False
        self.live.close()  # the background safe-speed search ends too
        if self.listener is not None:
            self.listener.close()  # the listening thread ends
        self._stop_recording()  # summary, index and footer: a clean file
        self._crash_recovery.join()
        super().release()

    # ---------------------------------------------------------------- parameters
    def _declare_parameters(self) -> None:
        # rclpy offers no hook between the overrides (--params-file, parameter_overrides)
        # and their type check at declaration: whole numbers for doubles are converted here,
        # later sets in the pre-set callback.
        overrides = self._parameter_overrides
        for name, parameter in overrides.items():
            overrides[name] = as_declared_type(parameter)
        for spec in PARAMETERS:
            self.declare_parameter(spec.name, spec.default, descriptor(spec))
        self.add_pre_set_parameters_callback(lambda ps: [as_declared_type(p) for p in ps])

    def _values(self, changes: dict) -> dict:
        return {**{p.name: p.value for p in self.get_parameters(PARAMETER_NAMES)}, **changes}

    def _settings(self, cls: type, changes: dict) -> Any:
        """Settings dataclass `cls` from the current parameters with `changes` applied."""
        return build(cls, self._values(changes))

    def _model(self, changes: dict) -> SqueakModel:
        """The model of the parameters with `changes` applied (`parameters.squeak_model`: one
        prediction draws the scatter's samples, so a scatter they cannot take is rejected
        here with the reason, never later in a callback)."""
        return squeak_model(self._values(changes))

    def _reader(self, name: str, changes: dict) -> InputReader:
        """The reader of input `name` from the parameters with `changes` applied."""
        return input_reader(name, self._settings(INPUT_FIELDS[name], changes))

    def _field(self, name: str) -> str:
        return self.get_parameter(f"{INPUTS_PREFIX}{name}.field").value

    def _live_settings(self, changes: dict) -> LiveSettings:
        return self._settings(LiveSettings, changes)

    def _record_settings(self, changes: dict) -> RecordSettings:
        return self._settings(RecordSettings, changes)

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """The new set as a whole must make valid settings (model, recorder, ...), and a
        recording it asks for must be able to start; else nothing changes."""
        changes = {p.name: p.value for p in params}
        try:
            values = self._values(changes)
            for group in GROUPS:
                build(group.cls, values)
            if set(changes) & (names_of(ScrewParameters) | names_of(ScatterSettings)):
                self._model(changes)
            for name, cls in INPUT_FIELDS.items():  # a field path must fit its type
                if set(changes) & names_of(cls):
                    self._reader(name, changes)
            recording = names_of(RecordSettings) | names_of(RecordingControl)
            if values["record.enabled"] and recording & set(changes):
                ensure_directory(values["record.directory"])  # mkdir -p, writable
        except (ParameterError, TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        except OSError as exc:
            return SetParametersResult(successful=False, reason=exc.strerror or str(exc))
        return SetParametersResult(successful=True)

    def _metadata(self) -> dict[str, dict[str, str]]:
        """The recording's metadata records of the current parameters (`bag.logmeta`)."""
        return {logmeta.RECORD_NAME: log_metadata(self._values({})).record()}

    def _apply_parameters(self, params: list[Parameter]) -> None:
        if not self._configured:  # configure reads them
            return
        names = {p.name for p in params}
        recording = names_of(RecordSettings) | names_of(RecordingControl)
        new_bag = bool(names & recording) and self._record_settings({}) != self.recorder.settings
        metadata = self._metadata()
        if metadata != self.recorder.metadata:
            self.recorder.metadata = metadata
            # A recording that goes on continues in a new file with the new record, before
            # the outputs of the new parameters (a new bag or a stop needs no split)
            if not new_bag and self.get_parameter("record.enabled").value:
                self.recorder.split()
        model_names = names_of(ScrewParameters) | names_of(ScatterSettings)
        if names & (model_names | names_of(LiveSettings)):
            model = self._model({}) if names & model_names else self.live.model
            self.live.set_model(model, self._live_settings({}))
            if "max_rate_hz" in names:
                self.destroy_owned(self._rate_timer)
                self._rate_timer = self._create_rate_timer()
            if self.active:  # else at activation
                self._recompute(time.monotonic())
        if names & names_of(JointSettings):
            self.joint = self._settings(JointSettings, {})
        for name, cls in INPUT_FIELDS.items():  # the type is read-only: same subscription
            if names & names_of(cls):
                self.readers[name] = self._reader(name, {})
        if names & names_of(NodeSettings):
            self.diagnostics.period_s = self._settings(NodeSettings, {}).diagnostics_period_s
        if self.listener is not None and names & (
            names_of(ListenSettings) | names_of(DetectorSettings)
        ):
            self._restart_listening()
        if names & recording:
            if new_bag:  # new record settings: a new bag
                self._stop_recording()
                self.recorder = self._new_recorder(self.recorder.name, metadata)
            self._set_recording(self.get_parameter("record.enabled").value)

    def _create_rate_timer(self):
        timer = self.own_timer(
            1.0 / self.live.settings.max_rate_hz, self._on_rate_timer, clock=self._steady
        )
        timer.cancel()
        return timer

    # ---------------------------------------------------------------- recording
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _new_recorder(self, name: str, metadata: dict) -> Recorder:
        return Recorder(
            self._record_settings({}),
            name,
            clock=self._now_ns,
            metadata=metadata,
            state=self._state_messages,
        )

    def _state_messages(self) -> list:
        """What every file starts with, as rosbag2 records transient-local topics: the last
        accepted message of each input in the order accepted (so that a replay of the file
        starts from the node's operating point), then the last message of each output."""
        return [
            *(
                (topic, msgdefs.type_name(type(msg)), serialize_message(msg), None)
                for topic, msg in list(self.accepted.items())
            ),
            *(
                (topic, m.type_name, m.data, m.publish_time_ns)
                for topic, m in list(self.latched.items())
            ),
        ]

    def _set_recording(self, on: bool) -> None:
        """Start (only while active: else at activation) or stop recording."""
        if on and self.active and not self.recorder.active:
            # Bags are named and split by the wall clock; log times are the node's clock.
            # A start that fails is reported by `_check_recording`.
            if self.recorder.start(topics=tuple(self._recorded)):
                self.get_logger().info(f"recording to {self.recorder.bag}")
                self._input_recording = InputRecording(self, self._recorded, self.recorder)
        elif not on and self.recorder.active:
            self._stop_recording()
            self.get_logger().info(f"recording stopped: {self.recorder.bag}")
        # /diagnostics follows within a housekeeping period: the verdict includes recording

    def _stop_recording(self) -> None:
        """Inputs first (their thread ends), then the file is finished."""
        if self._input_recording is not None:
            self._input_recording.stop()
            self._input_recording = None
        self.recorder.stop()

    def _check_recording(self) -> None:
        """Say once what the recorder reports. A recording that stopped on its own (disk full,
        ...) is logged once and `record.enabled` turns false, so that the parameter never
        reads true while nothing records; a file lost under the recorder is logged once."""
        r = self.recorder
        if r.incident and r.incident != self._incident_logged:
            self._incident_logged = r.incident
            self.get_logger().error(r.incident)
        if r.error and not r.active and self.get_parameter("record.enabled").value:
            self._stop_recording()  # the input thread too; the file stays as is
            self.get_logger().error(f"{r.error}; {RESUME_HINT}")
            self.set_parameters([Parameter("record.enabled", value=False)])

    def _on_record_service(
        self, request: SetBool.Request, response: SetBool.Response
    ) -> SetBool.Response:
        """Start (data=true) or stop recording; `record.enabled` follows."""
        [result] = self.set_parameters([Parameter("record.enabled", value=bool(request.data))])
        self._check_recording()  # a start that failed: the parameter false
        response.success = result.successful and self.recorder.active == request.data
        response.message = (
            str(self.recorder.path)
            if self.recorder.active
            else (result.reason if not result.successful else "")
            or self.recorder.error
            or (INACTIVE_RECORDING if request.data and not self.active else "")
            or f"stopped; last bag: {self.recorder.bag}"
        )
        return response

    def _publish(
        self, publisher: Publisher, data: bytes, publish_time_ns: int | None = None
    ) -> None:
        """Publish a CDR payload, latch it and record the same bytes (publish time: the
        message's header stamp if it has one, else the log time); an output's lifecycle
        publisher while inactive: nothing."""
        if isinstance(publisher, LifecyclePublisher) and not publisher.is_activated:
            return
        publisher.publish(data)  # bytes: published as serialized
        latched = Latched(msgdefs.type_name(publisher.msg_type), data, publish_time_ns)
        self.latched[publisher.topic_name] = latched
        if self.recorder.active:  # inputs are recorded by InputRecording
            self.recorder.write_serialized(
                publisher.topic_name, latched.type_name, data, publish_time_ns=publish_time_ns
            )

    # ---------------------------------------------------------------- inputs
    def _on_field(self, topic: str, msg: Any, kind: str) -> None:
        """Speed, load or nut: the number at the input's field path times its scale
        (`inputs.<kind>.*`); a stamped message older than the last one taken is stale."""
        reader, now = self.readers[kind], time.monotonic()
        if reader.stamp is not None and self._stale(topic, reader.stamp(msg)):
            return
        try:
            value = reader.value(msg)
        except IndexError as exc:  # an array of this message is shorter than the path's index
            outcome = self.live.rules.missing(kind, self._field(kind), str(exc))
            self._input(topic, msg, outcome.error, now)
            return
        self._input(topic, msg, getattr(self.live, SETTERS[kind])(value, now), now)

    def _on_joint_states(self, topic: str, msg: JointState) -> None:
        """The screw joint's speed and nut position (`live.rules`: ignored while joint_name is
        '' or without that joint), then one recompute decision."""
        if self._stale(topic, stamp_ns(msg)):
            return
        now = time.monotonic()
        outcome = self.live.set_joint_state(msg.name, msg.position, msg.velocity, now, self.joint)
        if not outcome.ignored:
            self._input(topic, msg, outcome.error, now)

    def _stale(self, topic: str, stamp: int) -> bool:
        """A message stamped `stamp` [ns] earlier than the last one taken on `topic` (0: not
        stamped, never stale), as the replay orders samples (`live.rules.SampleOrder`)."""
        back = self.order.step_back_ns(topic, stamp) if stamp else None
        if back:
            self.get_logger().warning(
                f"input not taken: {topic} header stamp {back / 1e9:.6g} s older than the last "
                f"one taken",
                throttle_duration_sec=2.0,
            )
        return bool(back)

    def _input(self, topic: str, msg: object, error: str, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        if error:  # the next tick reports it: a flood of bad input stays bounded
            self.get_logger().warning(f"input rejected: {error}", throttle_duration_sec=2.0)
            return
        self.accepted.pop(topic, None)  # re-inserted last: the order the state arose in
        self.accepted[topic] = msg
        if self.listener is not None:  # the detector rejects tones on the motor orders
            self.listener.note_speed(now, self.live.inputs.speed_rad_s)
        if self.live.due(now):
            self._recompute(now)
        elif self.live.changed() and self._rate_timer.is_canceled():
            self._rate_timer.reset()  # held back by the rate limit: recompute later

    def _on_sound(self, topic: str, data: bytes, decode: Decoder) -> None:
        """A sound chunk: queued for the listening thread as it is (or dropped and counted)."""
        assert self.listener is not None  # subscribed only while listening
        self.listener.offer(data, time.monotonic(), decode)

    # ---------------------------------------------------------------- listening
    def _restart_listening(self) -> None:
        """New `listen.*` settings: a new listener (and detector); the sound so far is
        forgotten, the last predictions are kept for the comparison."""
        old = self.listener
        assert old is not None  # listen.* are declared only while listening
        old.close()
        self.listener = Listener(
            self._settings(ListenSettings, {}), self._settings(DetectorSettings, {})
        )
        self.listener.take_over(old)
        self._publish_heard()

    def _measurement_status(self) -> Status:
        assert self._measurement is not None  # set when listening starts
        return self._measurement

    def _publish_heard(self) -> None:
        assert self.listener is not None
        for topic, data in messages.heard_payloads(self.listener.heard, self.listener.frequency_hz):
            self._publish(self.listen_pubs[topic], data)

    # ---------------------------------------------------------------- outputs
    def _on_rate_timer(self) -> None:
        now = time.monotonic()
        if self.live.due(now):
            self._recompute(now)
        if not self.live.changed():
            self._rate_timer.cancel()

    def _housekeeping(self) -> None:
        self.recorder.tick()  # flush, split by the wall clock, file still there
        self._check_recording()
        now = time.monotonic()
        if self.live.poll_advice():  # a background safe-speed search has finished
            self._publish_safe_speed()
        if self.listener is not None:
            if self.listener.collect():  # what the listening thread heard since
                self._publish_heard()
            self._measurement = self.listener.status(now)
        self._diagnose(now, periodic=True)  # e.g. bad input, input went stale

    def _diagnose(self, now: float, periodic: bool) -> None:
        """/diagnostics at once when the verdict changed, else (`periodic`) on its period."""
        self._status = self._verdict(now)
        m = self._measurement
        verdict = (
            self._status.level,
            self._status.message,
            self.recorder.active,
            self.recorder.error,
            self.recorder.incident,
            self.recorder.lost > 0,
            self._crash_recovery.state,
            m and (m.level, m.message),
        )
        if verdict != self._diagnosed:
            self.diagnostics.force_update()
            self._diagnosed = verdict
        elif periodic:
            self.diagnostics.update()

    def _verdict(self, now: float) -> Status:
        """The squeak-prediction status: the predictor's verdict; while inactive, STALE."""
        status = self.live.status(now)
        return status if self.active else inactive_status(status)

    def _recompute(self, now: float) -> None:
        p = self.live.update(now)
        if self.listener is not None:  # what the measurement compares the sound with
            self.listener.predicted(now, p)
        if p is not None:  # else outside validity: keep the last outputs
            self._publish_prediction(p)
        self._diagnose(now, periodic=False)  # else the housekeeping period covers it
        if p is None:
            self.get_logger().warning(self._status.message, throttle_duration_sec=2.0)

    def _publish_prediction(self, p: Prediction) -> None:
        for topic, data in messages.prediction_payloads(p):
            self._publish(self.output_pubs[topic], data)
        if not self.live.advice_pending:  # else the last advice stays until the new one
            self._publish_safe_speed()

    def _publish_safe_speed(self) -> None:
        if self.live.safe_speed_rad_s is not None:
            self._publish(
                self.output_pubs[messages.SAFE_SPEED],
                messages.safe_speed_payload(self.live.safe_speed_rad_s),
            )


class Latched(NamedTuple):
    """The last message published on an output topic, as a new bag starts with it."""

    type_name: str  # 'pkg/msg/Type'
    data: bytes  # CDR payload
    publish_time_ns: int | None  # header stamp, None: the log time


def usage() -> str:
    """`squeak_node --help`: how to run it, its topics and every parameter with unit, default
    and range."""
    lines = [
        "usage: squeak_node [-h] [--autostart | --no-autostart] [--ros-args "
        "[-r __ns:=/NAMESPACE] [-p NAME:=VALUE] [--params-file FILE] ...]",
        "",
        __doc__.splitlines()[0].replace("`", ""),
        "",
        "A managed (lifecycle) node: unconfigured -> configure -> inactive -> activate -> "
        "active (deactivate, cleanup, shutdown back).",
        *AUTOSTART_HELP,
        "",
        "Subscribes (sensor-data QoS, relative to the namespace):",
        "  motor_speed (std_msgs/Float64) [rad/s], axial_load (std_msgs/Float64) [N],",
        "  nut_position (std_msgs/Float64) [m] (or any installed type: inputs.<input>.type, "
        "a number at inputs.<input>.field times inputs.<input>.scale),",
        "  joint_states (sensor_msgs/JointState, joint `joint_name`),",
        "  with listen.enabled: microphone (std_msgs/Float32MultiArray chunks, full scale -1..1, "
        "at listen.sample_rate_hz)",
        "Publishes (reliable, transient local, depth 1):",
        "  squeak/risk (Float64) [1]: P(squeak) over the scatter (scatter.*),",
        "  squeak/margin (Float64) [1]: least damping ratio, < 0 when a nominal mode squeaks,",
        "  squeak/unstable_frequencies (Float64MultiArray) [Hz], squeak/active (Bool),",
        "  squeak/modes (Float64MultiArray),",
        "  squeak/safe_speed (Float64) [rad/s]: nearest speed with P(squeak) < safe_probability,",
        "  with listen.enabled: squeak/heard (Bool), squeak/heard_frequency (Float64) [Hz, 0 "
        "while nothing is heard],",
        "  /diagnostics (diagnostic_msgs/DiagnosticArray: '<node>: squeak prediction', "
        "'<node>: recording';",
        "  with listen.enabled also '<node>: measurement', heard against predicted;",
        "  STALE 'inactive' while inactive)",
        "Records (with record.enabled, while active) the inputs, the outputs and, when published "
        "in the namespace, the guard's",
        "  " + ", ".join(f"{t} ({c.__name__})" for t, c in GUARD_CLASSES.items()),
        "Services: ~/record (std_srvs/SetBool) starts or stops recording; the lifecycle's "
        "~/change_state, ~/get_state (lifecycle_msgs/srv/ChangeState, GetState) ...",
        "",
        "Parameters (name [unit] = default, range: description):",
        *help_lines(),
    ]
    lines += [
        "",
        "Example: squeak_node --ros-args -r __ns:=/seat_left --params-file "
        "config/leadscrew.yaml -p record.enabled:=true",
        "(config/leadscrew.yaml is keyed `/**:`, so it applies in any namespace)",
    ]
    return "\n".join(lines)


def main(args: list[str] | None = None) -> int:
    """Run the node until SIGINT/SIGTERM (`managed.run`): exit 0 on that requested shutdown
    (with the line `squeak_predictor: stopped by SIGTERM` (or SIGINT) on stderr, as every
    long-running command: `ros_env.StopSignals.exit_status`), 2 on bad parameters or
    arguments; `-h`/`--help` prints `usage()` and exits 0. `--no-autostart`: the node starts
    unconfigured and waits for lifecycle transitions (a configure that fails is logged, the
    node stays unconfigured and running)."""
    # Startup's objects (rclpy, numpy, scipy, the model) out of the collector's generations:
    # a full collection of them stalled a callback by ~60 ms (bench_node).
    return run(
        lambda autostart: SqueakPredictorNode(autostart=autostart),
        PROG,
        NODE_NAME,
        usage,
        make_executor,
        args,
        before_spin=gc.freeze,
    )


if __name__ == "__main__":
    sys.exit(main())
