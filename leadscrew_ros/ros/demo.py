# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak demo`: the squeak predictor node driven by the actuator simulator.

One process, one rclpy Context, one single-threaded executor with three nodes: the predictor
(`SqueakPredictorNode`), the simulator (`ActuatorSimulator`, a power-seat stroke) and a monitor
that listens to the predictor's outputs like any other client would (over DDS, with the
predictor's latched QoS). The predictor records its inputs and outputs to an MCAP bag. With
`microphone` the simulator also publishes a simulated microphone (`simulator.stroke_microphone`)
and the predictor listens to it (`listen.enabled`); the summary then says what was heard against
what was predicted. Prints a live one-line status and a summary (with the recording), then exits
by itself.
DDS stays on loopback, on a ROS_DOMAIN_ID of this process's own unless one is set.
"""

from __future__ import annotations

import math
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.logging import LoggingSeverity, get_logger
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64

from ..bag import cdr, messages
from ..bag.logfile import LogError, inspect, log_files
from ..bag.recorder import Recorder
from ..live.guard import GuardSettings
from ..live.listen import KEY_AGREEMENT, KEY_DROPPED, KEY_HEARD_MODES, KEY_HEARD_S, KEY_PREDICTED_S
from ..live.profile import ActuatorState, StrokeProfile, expected_squeak
from ..live.status import (
    KEY_RECOMPUTES,
    KEY_SPEED,
    KEY_SQUEAK_FREQUENCIES,
    KEY_VALID,
    KEY_VALIDITY,
    Level,
)
from ..model import Validity
from .env import StopSignals, close, confine_to_localhost, init_context
from .node import LATCHED, OUTPUT_CLASSES, SqueakPredictorNode, make_executor
from .simulator import ActuatorSimulator

START_TIMEOUT_S = 10.0  # the simulator waits this long for the predictor's subscription
TAIL_S = 0.3  # keep spinning after the stroke so the last outputs arrive
DRAIN_TIMEOUT_S = 10.0  # longest wait for the recording to hold every stroke sample
SPIN_STEP_S = 0.01
STATUS_MODES = 3  # squeak modes named in the status line


@dataclass
class SqueakRecord:
    """What the monitor has seen on the predictor's outputs."""

    predictions: int = 0  # squeak/risk messages (one per prediction)
    max_probability: float | None = None  # largest P(squeak) on squeak/risk
    probability: float | None = None  # latest P(squeak) on squeak/risk
    margin: float | None = None  # latest squeak/margin (inf: no mode)
    min_margin: float | None = None  # least squeak/margin seen
    active: bool = False
    frequencies: list[float] = field(default_factory=list)
    squeak_modes: list[tuple[str, float]] = field(default_factory=list)  # latest, (label, Hz)
    safe_speed: float | None = None
    valid: bool = False  # latest diagnostics: a prediction holds
    level: Level = Level.STALE  # latest diagnostics: the verdict
    validity: Validity | None = None  # latest diagnostics: at the latest point
    recomputes: str = ""
    squeak_time_s: float = 0.0
    squeak_since: float | None = None  # monotonic time squeak started
    speed_range: list[float] = field(default_factory=list)  # [min, max] |rad/s|
    frequency_range: dict[str, list[float]] = field(default_factory=dict)  # label -> [lo, hi]
    malformed: int = 0  # output messages that did not decode


class SqueakMonitor(Node):
    """Subscribes to squeak/risk (P(squeak)), squeak/margin, squeak/unstable_frequencies,
    squeak/active, squeak/modes, squeak/safe_speed and /diagnostics; keeps a `SqueakRecord`.

    Time in squeak and the squeak speeds come from /diagnostics, which the predictor publishes
    after every recompute with the inputs used, the validity and the squeak frequencies: squeak
    counts while the latest diagnostics say the prediction is valid and lists frequencies.
    The squeak/* outputs arrive serialized and are decoded by `bag.messages`' codec, the one
    the predictor encodes them with; a payload that does not decode is counted (`malformed`)
    and otherwise ignored. `name`: the node's name (`watch` runs one of its own)."""

    def __init__(self, name: str = "squeak_monitor", **kwargs: Any):
        super().__init__(name, **kwargs)
        # The predictor's latched QoS (reliable, transient local), with room for bursts.
        qos = QoSProfile(
            depth=100,
            reliability=LATCHED.reliability,
            durability=LATCHED.durability,
            history=LATCHED.history,
        )
        self.record = SqueakRecord()
        for topic, callback in (
            (messages.RISK, self._on_risk),
            (messages.MARGIN, self._on_margin),
            (messages.FREQUENCIES, self._on_frequencies),
            (messages.ACTIVE, self._on_active),
            (messages.MODES, self._on_modes),
            (messages.SAFE_SPEED, self._on_safe_speed),
        ):
            self.create_subscription(
                OUTPUT_CLASSES[topic], topic, self._decoding(callback), qos, raw=True
            )
        self.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, qos)

    def _decoding(self, callback):
        """`callback(data)`, with a payload it cannot decode counted and dropped."""

        def run(data: bytes) -> None:
            try:
                callback(data)
            except ValueError:
                self.record.malformed += 1

        return run

    def _on_risk(self, data: bytes) -> None:
        r, probability = self.record, cdr.decode_float64(data)
        r.predictions += 1
        r.probability = probability
        r.max_probability = (
            probability if r.max_probability is None else max(r.max_probability, probability)
        )

    def _on_margin(self, data: bytes) -> None:
        r, margin = self.record, cdr.decode_float64(data)
        r.margin = margin
        r.min_margin = margin if r.min_margin is None else min(r.min_margin, margin)

    def _on_frequencies(self, data: bytes) -> None:
        self.record.frequencies = list(cdr.decode_float64_multi_array(data).data)

    def _on_active(self, data: bytes) -> None:
        self.record.active = cdr.decode_bool(data)

    def _on_safe_speed(self, data: bytes) -> None:
        self.record.safe_speed = cdr.decode_float64(data)

    def _on_modes(self, data: bytes) -> None:
        """The squeaking modes (growth rate > 0): labels and frequencies."""
        squeak = [
            (m.label, m.frequency_hz) for m in messages.decode_modes(data) if m.growth_rate > 0
        ]
        self.record.squeak_modes = squeak
        for label, f in squeak:
            lo_hi = self.record.frequency_range.setdefault(label, [f, f])
            lo_hi[0], lo_hi[1] = min(lo_hi[0], f), max(lo_hi[1], f)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        if not msg.status:
            return
        status, r = msg.status[0], self.record
        values = {kv.key: kv.value for kv in status.values}
        r.valid, r.level = values.get(KEY_VALID) == "true", Level(status.level[0])
        r.validity = Validity.__members__.get(values.get(KEY_VALIDITY, ""))
        r.recomputes = values.get(KEY_RECOMPUTES, r.recomputes)
        squeak = r.valid and bool(values.get(KEY_SQUEAK_FREQUENCIES))
        self.set_squeak(squeak, time.monotonic())
        if squeak:
            try:
                w = abs(float(values[KEY_SPEED]))
            except (KeyError, ValueError):
                return
            r.speed_range = (
                [min(r.speed_range[0], w), max(r.speed_range[1], w)] if r.speed_range else [w, w]
            )

    def set_squeak(self, squeak: bool, now: float) -> None:
        """Squeak on/off at `now`; accumulates the time in squeak."""
        r = self.record
        if squeak and r.squeak_since is None:
            r.squeak_since = now
        elif not squeak and r.squeak_since is not None:
            r.squeak_time_s += now - r.squeak_since
            r.squeak_since = None


# ----------------------------------------------------------------------------- text
def status_line(t: float, s: ActuatorState | None, r: SqueakRecord) -> str:
    """One line: time, inputs | nominal verdict, P(squeak) and its diagnostics level, margin,
    safe speed | squeak modes (most
    unstable first). The least important part comes last, where a narrow terminal cuts it
    off."""
    head = (
        f"t {t:5.1f} s {s.speed_rad_s:6.1f} rad/s {s.load_n:4.0f} N nut {s.nut_position_m:.3f} m"
        if s
        else f"t {t:5.1f} s  waiting for the predictor"
    )
    if not r.valid or r.probability is None:
        why = _why_not(r) if not r.valid else ""
        return f"{head} | no prediction" + (f" ({why})" if why else " yet")
    safe = "" if r.safe_speed is None else f" safe {r.safe_speed:5.1f} rad/s"
    margin = "" if r.margin is None else f" margin {_margin_text(r.margin)}"
    # the verdict at the nominal parameters (squeak/active) and, apart from it, P(squeak) over
    # the scatter with the diagnostics level it gives (WARN/ERROR from their thresholds)
    nominal = "SQUEAK at nominal" if r.active else "quiet at nominal"
    line = (
        f"{head} | {nominal + ',':<18} P(squeak) {r.probability:.2f} {r.level.name:<5}"
        f"{margin}{safe}"
    )
    if r.active:
        modes = [f"{label} {f:.0f} Hz" for label, f in r.squeak_modes] or [
            f"{f:.0f} Hz" for f in r.frequencies
        ]
        more = f" +{len(modes) - STATUS_MODES}" if len(modes) > STATUS_MODES else ""
        line += f" | {', '.join(modes[:STATUS_MODES])}{more}"
    return line


def _margin_text(margin: float) -> str:
    """squeak/margin in a status line: signed, 4 decimals; 'none' without an oscillatory mode
    (the topic carries +inf then)."""
    return "none" if math.isinf(margin) else f"{margin:+.4f}"


def _why_not(r: SqueakRecord) -> str:
    """Why the latest diagnostics give no prediction, in a few words ('' before the first)."""
    if r.validity not in (None, Validity.OK):
        return r.validity.label
    if r.level == Level.ERROR:
        return "invalid input"
    if r.level == Level.STALE and r.probability is not None:
        return "waiting for inputs"
    return ""


def _recorded(recorder: Recorder, sim: ActuatorSimulator) -> bool:
    """Every sample the simulator published is in the recording or counted lost (the
    recording thread may still be writing the last ones); True when not recording."""
    if not recorder.active:
        return True
    for pub in (sim.speed_pub, sim.load_pub, sim.nut_pub):
        loss = recorder.losses.get(pub.topic_name)
        if recorder.count(pub.topic_name) + (loss.lost if loss else 0) < sim.published:
            return False
    return True


def _heard(predictor: SqueakPredictorNode, sim: ActuatorSimulator) -> bool:
    """Every microphone chunk the simulator published has reached the predictor and has been
    analysed (or dropped); True when not listening."""
    listener = predictor.listener
    return listener is None or (listener.received >= sim.mic_chunks and listener.backlog == 0)


def summary(
    profile: StrokeProfile,
    r: SqueakRecord,
    elapsed_s: float,
    finished: bool,
    expected_s: float | None,
    published: int = 0,
) -> str:
    """The demo's closing summary: the stroke, what was predicted and published."""
    d = profile.duration_s
    loads = [profile.state(t).load_n for t in [d * i / 200 for i in range(201)]]
    lines = [
        f"summary of the {d:g} s stroke (0 -> {profile.peak_speed_rad_s:g} rad/s -> 0, "
        f"load {min(loads):.0f}-{max(loads):.0f} N, nut {profile.start_nut_position_m:.3f}"
        f" -> {profile.end_nut_position_m:.3f} m):"
    ]
    if not finished:
        lines.append(f"  interrupted after {elapsed_s:.1f} s")
    share = 100 * r.squeak_time_s / d
    model = "" if expected_s is None else f"; the model along the profile: {expected_s:.2f} s"
    lines.append(
        f"  time in squeak:     {r.squeak_time_s:.2f} s ({share:.1f} % of the stroke){model}"
    )
    freqs = ", ".join(
        f"{label} {lo:.1f} Hz" if round(lo, 1) == round(hi, 1) else f"{label} {lo:.1f}-{hi:.1f} Hz"
        for label, (lo, hi) in sorted(r.frequency_range.items(), key=lambda kv: kv[1][0])
    )
    lines.append(f"  squeak frequencies: {freqs or 'none'}")
    lines.append(
        "  squeak speeds:      "
        + (f"{r.speed_range[0]:.2f} - {r.speed_range[1]:.1f} rad/s" if r.speed_range else "none")
    )
    lines.append(
        "  max P(squeak):      "
        + ("none" if r.max_probability is None else f"{r.max_probability:.3f}")
    )
    lines.append(
        "  min margin:         "
        + ("none" if r.min_margin is None else _margin_text(r.min_margin))
        + " (least damping ratio at the nominal parameters; < 0: a mode squeaks)"
    )
    lines.append(
        f"  predictions:        {r.predictions}"
        + (f" (node recomputes: {r.recomputes})" if r.recomputes else "")
    )
    lines.append(
        f"  simulator:          {published} samples published (motor_speed, "
        f"axial_load, nut_position each)"
    )
    return "\n".join(lines)


def listening_summary(values: dict[str, str]) -> str:
    """One line on what the predictor heard against what it predicted, from the key-values of
    its measurement status (`live.listen`), e.g. 'heard squeak 4.50 s (T1 2653 Hz); predicted
    4.60 s; agreement 96 % of frames'."""
    modes = ", ".join(
        part.rsplit(" ", 2)[0] for part in values[KEY_HEARD_MODES].split(", ") if part
    )
    heard = float(values[KEY_HEARD_S])
    agreement = values[KEY_AGREEMENT]
    line = (
        "  heard vs predicted: "
        + (f"heard squeak {heard:.2f} s ({modes})" if heard else "heard no squeak")
        + f"; predicted {float(values[KEY_PREDICTED_S]):.2f} s; agreement "
        + (f"{100 * float(agreement):.0f} % of frames" if agreement else "none")
    )
    dropped = int(values[KEY_DROPPED])
    return line + (f"; {dropped} chunks dropped" if dropped else "")


def recording_summary(recorder: Recorder) -> str:
    """One line on the bag the predictor wrote, read back from disk."""
    if recorder.bag is None:
        return f"  recording:          none ({recorder.error or 'not enabled'})"
    try:
        files = log_files(recorder.bag)
        infos = [inspect(f) for f in files]
    except LogError as exc:
        return f"  recording:          unreadable: {exc}"
    size = sum(f.stat().st_size for f in files)
    starts = [i.start_ns for i in infos if i.start_ns is not None]
    ends = [i.end_ns for i in infos if i.end_ns is not None]
    span = (max(ends) - min(starts)) / 1e9 if starts else 0.0
    state = "complete" if all(i.complete for i in infos) else "NOT complete"
    line = (
        f"  recording:          {recorder.bag} ({len(files)} file"
        f"{'s' * (len(files) != 1)}, {size / 1e3:.0f} kB, {sum(i.messages for i in infos)} "
        f"messages over {span:.1f} s, {len(infos[0].topics) if infos else 0} topics, {state})"
    )
    line += f"; error: {recorder.error}" if recorder.error else ""
    return (
        f"{line}\n  review it offline:  leadscrew-squeak replay {recorder.bag} --out "
        f"{recorder.bag}_review"
    )


# ----------------------------------------------------------------------------- run
def run_demo(
    duration_s: float = 12.0,
    rate_hz: float = 100.0,
    status_hz: float = 4.0,
    out: TextIO | None = None,
    record_dir: Path | None = None,
    microphone: bool = False,
) -> int:
    """Run predictor + simulator + monitor for one stroke.

    Parameters
    ----------
    duration_s : float
        Length of the stroke [s].
    rate_hz : float
        Publication rate of the simulator [Hz].
    status_hz : float
        Rate of the status lines [Hz].
    out : text file, optional
        Where the status lines and the summary go; default: stdout.
    record_dir : Path, optional
        The predictor records into a bag there (created); None: no recording.
    microphone : bool
        The simulator publishes a simulated microphone and the predictor listens to it.

    Returns
    -------
    int
        0 when done, and 0 after SIGINT or SIGTERM too, with the summary so far and
        `StopSignals.exit_status`'s line on stderr.

    Raises
    ------
    ProfileError
        A bad duration, before anything starts.
    RuntimeError
        rclpy or the discovery fails.
    """
    out = out or sys.stdout
    profile = StrokeProfile(duration_s=duration_s)
    recording = []
    if record_dir is not None:
        Path(record_dir).mkdir(parents=True, exist_ok=True)
        recording = [
            Parameter("record.enabled", value=True),
            Parameter("record.directory", value=str(record_dir)),
        ]
    confine_to_localhost(private_domain=True)
    tty = out.isatty()
    with StopSignals() as stop:
        ctx = init_context()  # not sys.argv: the CLI's options are not rcl's
        nodes: list[Node] = []
        executor = monitor = sim = predictor = None
        width, stopped = 0, time.monotonic()
        listening: dict[str, str] = {}
        try:
            predictor = SqueakPredictorNode(
                context=ctx, parameter_overrides=[Parameter("listen.enabled", value=microphone)]
            )
            # Its warnings (e.g. "no prediction" while the motor rests) repeat what the status
            # line shows; keep the terminal to the status line and the summary.
            predictor.get_logger().set_level(LoggingSeverity.ERROR)
            if recording:
                predictor.set_parameters_atomically(recording)
            nodes.append(predictor)
            monitor = SqueakMonitor(context=ctx)
            nodes.append(monitor)
            sim = ActuatorSimulator(
                profile,
                rate_hz=rate_hz,
                wait_for_subscriber=True,
                microphone=microphone,
                context=ctx,
            )
            nodes.append(sim)
            executor = make_executor(ctx)
            for node in nodes:
                executor.add_node(node)
            print(
                f"leadscrew_ros demo: squeak predictor + simulated power-seat stroke "
                f"({duration_s:g} s, 0 -> {profile.peak_speed_rad_s:g} rad/s -> 0), "
                f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}, discovery "
                f"{os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')}",
                file=out,
                flush=True,
            )
            begin = time.monotonic()
            next_status, done_at = begin, None
            while not stop.signum:
                executor.spin_once(timeout_sec=SPIN_STEP_S)
                now = time.monotonic()
                if sim.started_at is None and now - begin > START_TIMEOUT_S:
                    raise RuntimeError(
                        "the predictor node did not subscribe to motor_speed "
                        f"within {START_TIMEOUT_S:g} s"
                    )
                if now >= next_status:
                    line = status_line(sim.elapsed_s, sim.last_state, monitor.record)
                    if tty:  # overwrite, within the terminal
                        line = line[: shutil.get_terminal_size().columns - 1]
                        print("\r" + line.ljust(width), end="", file=out, flush=True)
                        width = len(line)
                    else:
                        print(line, file=out, flush=True)
                    next_status += 1.0 / status_hz
                if sim.done and done_at is None:
                    done_at = now
                if (
                    done_at is not None
                    and now - done_at >= TAIL_S
                    and (
                        (_recorded(predictor.recorder, sim) and _heard(predictor, sim))
                        or now - done_at >= DRAIN_TIMEOUT_S
                    )
                ):
                    break
            if predictor.listener is not None:  # everything analysed: the totals
                predictor.listener.collect()
                listening = predictor.listener.status(time.monotonic()).values
        finally:
            stopped = time.monotonic()
            if tty and width:
                print(file=out)
            close(ctx, executor, list(reversed(nodes)))
    finished = sim is not None and sim.done
    if monitor is not None:
        monitor.set_squeak(False, stopped)  # close an open squeak interval
        expected = None
        if finished:
            times, flags = expected_squeak(profile)
            expected = float(flags.mean() * profile.duration_s)
        print(
            summary(
                profile,
                monitor.record,
                sim.elapsed_s if sim else 0.0,
                finished,
                expected,
                sim.published if sim else 0,
            ),
            file=out,
            flush=True,
        )
    if listening:
        print(listening_summary(listening), file=out, flush=True)
    if predictor is not None and record_dir is not None:
        print(recording_summary(predictor.recorder), file=out, flush=True)
    return 0 if finished else stop.exit_status()


# ----------------------------------------------------------------------------- --guard
GUARD_PNG = "guard_demo.png"
GUARD_CSV = "guard_demo.csv"
BANDS_TIMEOUT_S = 300.0  # longest wait for the guard's band thread between the strokes
TRACE_RATE_HZ = 100.0  # the runs are compared on this time grid


class StrokeTrace(Node):
    """Records what one stroke did, with times from the stroke's start: the command
    (speed_command), the motor's speed (motor_speed) and P(squeak) (squeak/risk)."""

    def __init__(self, **kwargs: Any):
        super().__init__("stroke_trace", **kwargs)
        self.t0: float | None = None  # time.monotonic() of the stroke's start
        self.series: dict[str, list[tuple[float, float]]] = {
            messages.SPEED_COMMAND: [],
            "motor_speed": [],
            messages.RISK: [],
        }
        qos = QoSProfile(depth=1000, reliability=LATCHED.reliability)
        for topic in (messages.SPEED_COMMAND, "motor_speed"):
            self.create_subscription(Float64, topic, partial(self._on_speed, topic), qos)
        self.create_subscription(
            OUTPUT_CLASSES[messages.RISK],
            messages.RISK,
            self._on_risk,
            QoSProfile(
                depth=100,
                reliability=LATCHED.reliability,
                durability=LATCHED.durability,
                history=LATCHED.history,
            ),
            raw=True,
        )

    def _on_speed(self, topic: str, msg: Float64) -> None:
        self._add(topic, msg.data)

    def _on_risk(self, data: bytes) -> None:
        self._add(messages.RISK, cdr.decode_float64(data))

    def _add(self, topic: str, value: float) -> None:
        if self.t0 is not None:
            self.series[topic].append((time.monotonic() - self.t0, value))

    def held(self, topic: str, times: np.ndarray) -> np.ndarray:
        """The topic's latest value at each time (0 before the first)."""
        points = self.series[topic]
        if not points:
            return np.zeros(len(times))
        t, v = (np.array(a) for a in zip(*points, strict=True))
        k = np.searchsorted(t, times, side="right") - 1
        return np.where(k >= 0, v[np.maximum(k, 0)], 0.0)


@dataclass
class StrokeRun:
    """One stroke of `run_guard_demo`: what the monitor saw and what the trace recorded."""

    record: SqueakRecord
    trace: StrokeTrace
    elapsed_s: float
    finished: bool


def _one_stroke(
    ctx: Any,
    executor: Any,
    profile: StrokeProfile,
    rate_hz: float,
    command: str,
    stop: StopSignals,
    out: TextIO,
) -> StrokeRun:
    """One simulated stroke with a predictor, monitor, trace and simulator of its own (the
    guard node, if any, lives on); its nodes are destroyed afterwards."""
    predictor = SqueakPredictorNode(context=ctx)
    predictor.get_logger().set_level(LoggingSeverity.ERROR)
    monitor, trace = SqueakMonitor(context=ctx), StrokeTrace(context=ctx)
    sim = ActuatorSimulator(
        profile, rate_hz=rate_hz, wait_for_subscriber=True, command=command, context=ctx
    )
    nodes: list[Node] = [predictor, monitor, trace, sim]
    for node in nodes:
        executor.add_node(node)
    try:
        begin = time.monotonic()
        done_at = None
        while not stop.signum:
            executor.spin_once(timeout_sec=SPIN_STEP_S)
            now = time.monotonic()
            if sim.started_at is None and now - begin > START_TIMEOUT_S:
                raise RuntimeError(
                    f"the predictor or the guard did not subscribe within {START_TIMEOUT_S:g} s"
                )
            trace.t0 = sim.started_at
            if sim.done and done_at is None:
                done_at = now
            if done_at is not None and now - done_at >= TAIL_S:
                break
        monitor.set_squeak(False, time.monotonic())
        return StrokeRun(monitor.record, trace, sim.elapsed_s, sim.done)
    finally:
        for node in reversed(nodes):
            executor.remove_node(node)
        for _ in range(20):  # events queued for the removed nodes (EventsExecutor)
            executor.spin_once(timeout_sec=0.0)
        for node in reversed(nodes):
            node.destroy_node()


def guard_comparison(
    profile: StrokeProfile, raw: StrokeRun, guarded: StrokeRun, p_max: float
) -> tuple[Any, tuple]:
    """Both strokes on one time grid as a `review.guard.GuardRun` (the raw run's command and P,
    the guarded run's motor speed and P) and its `review.guard.summary`."""
    from ..review.guard import Command, GuardRun, summary

    times, _, load, nut = profile.sampled(TRACE_RATE_HZ)
    run = GuardRun(
        Command(times, raw.trace.held(messages.SPEED_COMMAND, times), load, nut),
        guarded.trace.held("motor_speed", times),
        raw.trace.held(messages.RISK, times),
        guarded.trace.held(messages.RISK, times),
        [],
        GuardSettings(p_max=p_max),
    )
    return run, summary(run)


def guard_summary(raw: StrokeRun, guarded: StrokeRun, numbers: tuple, bands: str) -> str:
    """The side-by-side summary of `run_guard_demo`."""
    m_raw, m_guarded, stroke = numbers
    rows = [
        ("time in squeak [s]", raw.record.squeak_time_s, guarded.record.squeak_time_s, ".2f"),
        ("time P >= p_max [s]", m_raw.time_in_squeak_s, m_guarded.time_in_squeak_s, ".2f"),
        ("peak P(squeak)", raw.record.max_probability or 0.0, m_guarded.peak_p, ".3f"),
        ("travel [rad]", m_raw.travel_rad, m_guarded.travel_rad, ".1f"),
        ("stroke time [s]", m_raw.motion_time_s, stroke, ".2f"),
    ]
    lines = [
        "summary, raw against guarded (the motor following speed_command_guarded):",
        f"  {'':24}{'raw':>10}{'guarded':>10}",
    ]
    lines += [f"  {label:24}{a:>10{fmt}}{b:>10{fmt}}" for label, a, b, fmt in rows]
    longer = stroke / m_raw.motion_time_s - 1 if m_raw.motion_time_s > 0 else math.nan
    lines.append(
        f"  stroke time {100 * longer:+.1f} % (the guarded stroke's motion time for the raw "
        "travel); time in squeak: the predictor's nominal verdict, as the demo counts it"
    )
    lines.append(f"  {bands}")
    return "\n".join(lines)


def run_guard_demo(
    duration_s: float = 12.0,
    rate_hz: float = 100.0,
    out: TextIO | None = None,
    out_dir: Path | None = None,
) -> int:
    """`demo --guard`: the simulated stroke twice, without and with the guard node
    (`SqueakGuardNode`), each with a predictor of its own; the summary side by side and
    `guard_demo.png` / `guard_demo.csv` in `out_dir`.

    In the raw stroke the motor follows the command (speed_command) and the guard runs beside
    it unheeded, its band thread learning the stroke's squeak bands (a drive repeats its
    strokes); the guarded stroke starts once the bands are computed, the motor following
    speed_command_guarded.

    Returns
    -------
    int
        0 when both strokes are done; after SIGINT or SIGTERM `StopSignals.exit_status`.
    """
    from ..review.guard import write_run
    from ..review.plots import plot_guard
    from .guard_node import NODE_NAME as GUARD_NODE_NAME
    from .guard_node import SqueakGuardNode

    out = out or sys.stdout
    profile = StrokeProfile(duration_s=duration_s)
    confine_to_localhost(private_domain=True)
    with StopSignals() as stop:
        ctx = init_context()
        executor = guard = None
        try:
            # the status and the summary say it all: its info lines stay off the terminal
            get_logger(GUARD_NODE_NAME).set_level(LoggingSeverity.ERROR)
            try:
                guard = SqueakGuardNode(context=ctx)
            except ValueError as exc:  # a bad parameter (ParameterError)
                raise RuntimeError(f"the guard did not start: {exc}") from exc
            executor = make_executor(ctx)
            executor.add_node(guard)
            print(
                f"leadscrew_ros demo --guard: the {duration_s:g} s stroke without, then with "
                f"the squeak guard, ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}, "
                f"discovery {os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')}",
                file=out,
                flush=True,
            )
            print("stroke 1: raw (the guard learns the bands beside it)", file=out, flush=True)
            raw = _one_stroke(ctx, executor, profile, rate_hz, "raw", stop, out)
            assert guard.worker is not None and guard.policy is not None  # active
            waited = time.monotonic()
            while guard.worker.busy and not stop.signum:
                executor.spin_once(timeout_sec=SPIN_STEP_S)
                if time.monotonic() - waited > BANDS_TIMEOUT_S:
                    raise RuntimeError(f"the guard's bands took over {BANDS_TIMEOUT_S:g} s")
            waited = time.monotonic() - waited
            bins = len(guard.policy.bands)
            print(
                f"stroke 2: guarded ({bins} squeak band bins, {waited:.1f} s waited for them)",
                file=out,
                flush=True,
            )
            p_max = guard.policy.settings.p_max
            guarded = None
            if not stop.signum:
                guarded = _one_stroke(ctx, executor, profile, rate_hz, "guarded", stop, out)
        finally:
            close(ctx, executor, [guard] if guard is not None else [])
    if guarded is None or not (raw.finished and guarded.finished):
        print("interrupted", file=out, flush=True)
        return stop.exit_status()
    run, numbers = guard_comparison(profile, raw, guarded, p_max)
    print(
        guard_summary(raw, guarded, numbers, f"guard: {bins} band bins, p_max {p_max:g}"),
        file=out,
        flush=True,
    )
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        write_run(out_dir / GUARD_CSV, run)
        plot_guard(run, title="demo stroke: raw and guarded (live)").savefig(
            out_dir / GUARD_PNG, dpi=110
        )
        print(f"  wrote {out_dir / GUARD_CSV} and {out_dir / GUARD_PNG}", file=out, flush=True)
    return 0
