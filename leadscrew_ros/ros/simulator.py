# SPDX-License-Identifier: Apache-2.0
"""Actuator simulator: the ROS 2 node that publishes a seat stroke (`live.profile.StrokeProfile`)
on the predictor's input topics: std_msgs/Float64 `motor_speed` [rad/s], `axial_load` [N],
`nut_position` [m]; optionally sensor_msgs/JointState `joint_states` and a simulated
microphone, std_msgs/Float32MultiArray `microphone` (`stroke_microphone`). For the guard
(`squeak_guard`) it can publish the stroke's speed as the command `speed_command` and let the
simulated motor follow the guarded command `speed_command_guarded`.
"""

from __future__ import annotations

import array
import math
import os
import sys
import time
from collections.abc import Sequence
from typing import Any, TextIO

import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float32MultiArray, Float64

from ..bag.virtual_bench import squeak_frequencies
from ..live.profile import ActuatorState, ProfileError, StrokeProfile
from ..model import ScrewParameters
from .env import StopSignals, close, confine_to_localhost, init_context
from .guard_node import COMMAND as COMMAND_TOPIC
from .guard_node import GUARDED as GUARDED_TOPIC

NODE_NAME = "actuator_simulator"
MAX_RATE_HZ = 10_000.0
MIC_RATE_HZ = 48000  # the simulated microphone's sample rate
MIC_CHUNK_S = 0.1  # and its chunks
MIC_SQUEAK_LEVEL = 0.05  # squeak tone amplitude [full scale] (-26 dBFS)
_SCHEDULE_RATE_HZ = 100.0  # the model along the stroke, for the squeak tone
COMMAND_MODES = ("", "raw", "guarded")


def stroke_microphone(
    profile: StrokeProfile,
    params: ScrewParameters | None = None,
    sample_rate_hz: float = MIC_RATE_HZ,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """The simulated microphone of one stroke (computed up front, never in a callback).

    The squeak schedule is the model of `params` (`SqueakModel`, nominal verdict, no scatter;
    `bag.virtual_bench.squeak_frequencies`) at the stroke's operating points every 10 ms: where
    it squeaks, a tone at the frequency of its most unstable mode; the samples are
    `model.acoustics.synthesis.microphone` of the stroke's speed (motor orders, noise) and that
    tone.

    Parameters
    ----------
    profile : StrokeProfile
        The stroke.
    params : ScrewParameters, optional
        The screw (default: Table 1, the node's default).
    sample_rate_hz : float
        Sample rate [Hz].
    seed : int
        Seed of the noise and the order phases.

    Returns
    -------
    samples : numpy.ndarray
        float32 samples, full scale, from the start of the stroke.
    squeak_hz : numpy.ndarray
        The tone's frequency every 10 ms of the stroke, nan where the model is silent [Hz].
    """
    from ..model.acoustics.synthesis import microphone  # scipy.signal: only when used

    params = params or ScrewParameters()
    times, speed, load, nut = profile.sampled(_SCHEDULE_RATE_HZ)
    squeak_hz = squeak_frequencies(params, speed, load, nut)
    return (
        microphone(times, speed, squeak_hz, MIC_SQUEAK_LEVEL, sample_rate_hz, seed=seed),
        squeak_hz,
    )


class ActuatorSimulator(Node):
    """Publishes `profile` at `rate_hz` on motor_speed, axial_load, nut_position (Float64) and,
    with a `joint_name`, joint_states (one joint: position = screw angle, velocity = speed).

    The stroke clock starts at the first tick, or with `wait_for_subscriber` when something
    subscribes to motor_speed. Time is wall-clock time since then, so a late tick shifts no
    sample. After the stroke the end state (at rest) is published once more and `done` turns
    True; with `loop` the stroke repeats, back and forth, until the node is destroyed.

    Parameters
    ----------
    profile : StrokeProfile, optional
        The stroke; default: `StrokeProfile()`.
    rate_hz : float
        Publication rate, in (0, MAX_RATE_HZ] Hz (else ProfileError).
    loop : bool
        Repeat the stroke, back and forth.
    joint_name : str
        Also publish joint_states with this joint ('': not).
    wait_for_subscriber : bool
        Start the stroke clock when something subscribes to motor_speed.
    microphone : bool
        Also publish the stroke's simulated microphone (`stroke_microphone`, `MIC_CHUNK_S`
        chunks as their sound has passed) on `microphone`; not with `loop`.
    params : ScrewParameters, optional
        The screw whose model decides where the microphone squeaks (default: Table 1).
    command : {"", "raw", "guarded"}
        '' (default): motor_speed is the stroke's speed. 'raw': the stroke's speed is also
        published as the command `speed_command` (Float64) and motor_speed is that command.
        'guarded': the stroke's speed is published on `speed_command` only, and the motor
        follows the guarded command: every `speed_command_guarded` (Float64) received is
        published as motor_speed at once. With a command the stroke starts (with
        `wait_for_subscriber`) when `speed_command` is subscribed too.
    **kwargs
        Passed to `rclpy.node.Node` (`node_name` too).
    """

    def __init__(
        self,
        profile: StrokeProfile | None = None,
        rate_hz: float = 100.0,
        loop: bool = False,
        joint_name: str = "",
        wait_for_subscriber: bool = False,
        microphone: bool = False,
        params: ScrewParameters | None = None,
        command: str = "",
        **kwargs: Any,
    ):
        if not (math.isfinite(rate_hz) and 0 < rate_hz <= MAX_RATE_HZ):
            raise ProfileError(f"rate_hz must be in (0, {MAX_RATE_HZ:g}] Hz, got {rate_hz!r}")
        if microphone and loop:
            raise ProfileError("the simulated microphone covers one stroke: not with loop")
        if command not in COMMAND_MODES:
            raise ValueError(f"command must be one of {COMMAND_MODES}, got {command!r}")
        super().__init__(kwargs.pop("node_name", NODE_NAME), **kwargs)
        self.profile = profile or StrokeProfile()
        self.loop, self.joint_name = loop, joint_name
        self.wait_for_subscriber = wait_for_subscriber
        self.started_at: float | None = None  # time.monotonic() of t = 0
        self.done = False
        self.published = 0
        self.last_state: ActuatorState | None = None
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.speed_pub = self.create_publisher(Float64, "motor_speed", qos)
        self.load_pub = self.create_publisher(Float64, "axial_load", qos)
        self.nut_pub = self.create_publisher(Float64, "nut_position", qos)
        self.joint_pub = (
            self.create_publisher(JointState, "joint_states", qos) if joint_name else None
        )
        self.command = command
        self.command_pub = self.create_publisher(Float64, COMMAND_TOPIC, qos) if command else None
        self.followed = 0  # guarded commands followed (published as motor_speed)
        if command == "guarded":
            self.create_subscription(Float64, GUARDED_TOPIC, self._follow, qos)
        self.mic_pub = None
        self.mic_chunks = 0  # microphone chunks published
        if microphone:
            self.audio, self.squeak_hz = stroke_microphone(self.profile, params)
            self.mic_pub = self.create_publisher(Float32MultiArray, "microphone", qos)
            self._mic_sent = 0  # samples published
        self._timer = self.create_timer(1.0 / rate_hz, self._tick)

    @property
    def elapsed_s(self) -> float:
        """Stroke time so far (0 before the start)."""
        return 0.0 if self.started_at is None else time.monotonic() - self.started_at

    def _tick(self) -> None:
        if self.done:
            return
        if self.started_at is None:
            if self.wait_for_subscriber and not self._subscribers_matched():
                return
            self.started_at = time.monotonic()
        t = self.elapsed_s
        finished = not self.loop and t >= self.profile.duration_s
        self.publish(self.profile.state(self.profile.duration_s if finished else t, self.loop))
        if self.mic_pub is not None:
            self._publish_sound(self.audio.size if finished else int(t * MIC_RATE_HZ))
        if finished:
            self.done = True
            self._timer.cancel()

    def _publish_sound(self, upto: int) -> None:
        """The microphone's whole chunks whose sound ends by sample `upto` (and the last,
        shorter one when `upto` is the end)."""
        step = int(MIC_CHUNK_S * MIC_RATE_HZ)
        while self._mic_sent + step <= upto or self.audio.size == upto > self._mic_sent:
            chunk = self.audio[self._mic_sent : self._mic_sent + step]
            assert self.mic_pub is not None  # the sound exists only with a microphone
            self.mic_pub.publish(Float32MultiArray(data=array.array("f", chunk.tobytes())))
            self._mic_sent += chunk.size
            self.mic_chunks += 1

    def _subscribers_matched(self) -> bool:
        """Something subscribes to motor_speed, and every subscription the graph knows of has
        matched (one shown but not yet matched would miss the first samples: a recorder's)."""
        pubs = [self.speed_pub] + ([self.command_pub] if self.command_pub else [])
        for pub in pubs:
            matched = pub.get_subscription_count()
            if not (matched > 0 and matched >= self.count_subscribers(pub.topic_name)):
                return False
        return True

    def _follow(self, msg: Float64) -> None:
        """The simulated motor follows the guarded command at once."""
        self.speed_pub.publish(Float64(data=float(msg.data)))
        self.followed += 1

    def publish(self, s: ActuatorState) -> None:
        """Publish one state on every output topic.

        Parameters
        ----------
        s : ActuatorState
            Speed, load, nut position and screw angle.
        """
        if self.command != "guarded":
            self.speed_pub.publish(Float64(data=float(s.speed_rad_s)))
        self.load_pub.publish(Float64(data=float(s.load_n)))
        self.nut_pub.publish(Float64(data=float(s.nut_position_m)))
        if self.command_pub is not None:  # after load and nut: the guard steps on the command
            self.command_pub.publish(Float64(data=float(s.speed_rad_s)))
        if self.joint_pub is not None:
            msg = JointState(
                name=[self.joint_name],
                position=[float(s.screw_angle_rad)],
                velocity=[float(s.speed_rad_s)],
            )
            msg.header.stamp = self.get_clock().now().to_msg()
            self.joint_pub.publish(msg)
        self.last_state = s
        self.published += 1


def run_simulator(
    profile: StrokeProfile | None = None,
    rate_hz: float = 100.0,
    loop: bool = False,
    joint_name: str = "",
    wait_for_subscriber: bool = True,
    out: TextIO | None = None,
    ros_args: Sequence[str] = (),
) -> int:
    """`leadscrew-squeak simulate`: publish the stroke on the user's ROS_DOMAIN_ID (loopback
    discovery unless chosen otherwise) for a separately started predictor node.

    Parameters
    ----------
    profile, rate_hz, loop, joint_name, wait_for_subscriber
        As for `ActuatorSimulator`.
    out : text file, optional
        Where the progress lines go; default: stdout.
    ros_args : sequence of str
        `--ros-args -r __ns:=/seat_left ...`: configure the node as any ROS executable's; the
        topics are relative, so a namespace prefixes them.

    Returns
    -------
    int
        0: when the stroke is done, and when stopped by SIGINT/SIGTERM (with or without
        `loop`; `StopSignals.exit_status` writes its line on stderr).

    Raises
    ------
    ValueError
        rcl rejects `ros_args`.
    """
    out = out or sys.stdout
    profile = profile or StrokeProfile()
    confine_to_localhost()
    with StopSignals() as stop:
        ctx = init_context(ros_args)
        node = executor = None
        try:
            node = ActuatorSimulator(
                profile,
                rate_hz=rate_hz,
                loop=loop,
                joint_name=joint_name,
                wait_for_subscriber=wait_for_subscriber,
                context=ctx,
            )
            executor = SingleThreadedExecutor(context=ctx)
            executor.add_node(node)
            topics = ", ".join(
                p.topic_name
                for p in (node.speed_pub, node.load_pub, node.nut_pub, node.joint_pub)
                if p
            )
            print(
                f"simulating a {profile.duration_s:g} s stroke (0 -> "
                f"{profile.peak_speed_rad_s:g} rad/s -> 0, nut "
                f"{profile.start_nut_position_m:.3f} -> {profile.end_nut_position_m:.3f} m)"
                f"{', looped back and forth' if loop else ''} at {rate_hz:g} Hz on {topics} "
                f"(ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')})",
                file=out,
                flush=True,
            )
            if wait_for_subscriber:
                print(
                    f"waiting for a subscriber on {node.speed_pub.topic_name} ...",
                    file=out,
                    flush=True,
                )
            announced = False
            while not node.done and not stop.signum:
                executor.spin_once(timeout_sec=0.02)
                if node.started_at is not None and not announced:
                    print("stroke started", file=out, flush=True)
                    announced = True
            linger = time.monotonic() + 0.3  # let the last samples reach the subscribers
            while node.done and not stop.signum and time.monotonic() < linger:
                executor.spin_once(timeout_sec=0.02)
        finally:
            close(ctx, executor, [node] if node is not None else [])
    published = node.published if node is not None else 0
    if node is not None and node.done:
        print(f"stroke done: {published} samples published", file=out, flush=True)
        return 0
    print(f"stopped: {published} samples published", file=out, flush=True)
    return stop.exit_status()
