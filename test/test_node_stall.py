# SPDX-License-Identifier: Apache-2.0
"""The node never stalls its executor on safe-speed advice (issue 8).

With 40/40 modes one band search costs up to a second or more; it used to run inside the
node's single-threaded executor, so parameter services, predictions and diagnostics waited for
it. Here the node spins its own executor on a thread, like a real process, while a driver node
(its own executor, this thread) streams speed and load at 50 Hz into the squeak band through
several 5 % load bins and calls `get_parameters` every 50 ms: every call must answer within
0.2 s and a risk message must follow every recompute, with no gap longer than a few
predictions. On a machine so busy that one 40/40 prediction itself takes longer than about
70 ms (measured in the run), the bounds are a few predictions instead of 0.2 s and 0.5 s: the
issue's rule is that nothing waits longer than about one prediction. `stall_run` is also what
benchmarks/bench_advice.py measures.
"""

from __future__ import annotations

import math
import time
import uuid
from dataclasses import dataclass, field
from unittest import mock

from rcl_interfaces.srv import GetParameters
from rclpy.parameter import Parameter
from std_msgs.msg import Float64

from harness.ros import COLLECT, RosWorld, Spinner, new_executor
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.ros.node import SqueakPredictorNode

RATE_HZ = 50.0
CALL_PERIOD_S = 0.05  # get_parameters calls start this far apart (or on answer)
MAX_PARAMETER_LATENCY_S = 0.2  # the bound for get_parameters
MAX_RISK_GAP_S = 0.5  # a band search took 1.7 s (40/40) inside the executor
LATENCY_PREDICTIONS = 3  # ... or this many of the longest prediction of the run
GAP_PREDICTIONS = 6  # (recomputes start >= 2 prediction times apart)


def operating_point(t: float) -> tuple[float, float]:
    """Speed (rad/s) and load (N) at time t of the stream: the speed swings between 70 rad/s
    (squeak-free) and 10 rad/s, in and out of the squeak band (~0.8..55 rad/s at Table 1)
    every 4 s, while the load climbs one 5 % bin every 0.7 s from 150 N."""
    return 40.0 + 30.0 * math.cos(2 * math.pi * t / 4.0), 150.0 * 1.05 ** (t / 0.7)


@dataclass
class StallStats:
    latencies_s: list[float] = field(default_factory=list)  # one per get_parameters call
    risk_times: list[float] = field(default_factory=list)  # monotonic receipt times
    recomputes: int = 0  # during the stream
    searches: int = 0  # advice searches requested
    safe_speeds: list[float] = field(default_factory=list)
    stream_s: tuple[float, float] = (0.0, 0.0)  # monotonic start and end
    predictions_s: list[float] = field(default_factory=list)  # SqueakModel.predict wall times

    @property
    def max_risk_gap_s(self) -> float:
        """Longest time without a risk message while the stream ran."""
        start, end = self.stream_s
        t = [start] + [x for x in self.risk_times if start < x < end] + [end]
        return max(b - a for a, b in zip(t, t[1:], strict=False))


def stall_run(n_modes: int, duration_s: float, count_searches=None) -> StallStats:
    """Stream `operating_point` at RATE_HZ for `duration_s` into a node with `n_modes` bending
    and torsion orders, calling get_parameters from another node every CALL_PERIOD_S.
    `count_searches()`, if given, returns how many advice searches the node has requested."""
    ns, stats = f"/s{uuid.uuid4().hex}", StallStats()
    predict = SqueakModel.predict

    def timed(self, *args, **kwargs):
        start = time.monotonic()
        try:
            return predict(self, *args, **kwargs)
        finally:
            stats.predictions_s.append(time.monotonic() - start)

    with mock.patch.object(SqueakModel, "predict", timed):
        return _stall_run(n_modes, duration_s, count_searches, ns, stats)


def _stall_run(n_modes, duration_s, count_searches, ns, stats) -> StallStats:
    world = RosWorld(ns=ns)  # the driver's side, spun in this thread
    node_executor = new_executor("events", world.ctx)  # the node's own, as in squeak_node
    node = spinner = None
    try:
        node = SqueakPredictorNode(
            context=world.ctx,
            namespace=ns,
            parameter_overrides=[
                Parameter("n_bending", value=n_modes),
                Parameter("n_torsion", value=n_modes),
            ],
        )
        node_executor.add_node(node)
        spinner = Spinner(node_executor)
        driver = world.make_node("driver")
        executor = world.executor
        speed_pub = driver.create_publisher(Float64, "motor_speed", 10)
        load_pub = driver.create_publisher(Float64, "axial_load", 10)
        driver.create_subscription(
            Float64, "squeak/risk", lambda _: stats.risk_times.append(time.monotonic()), COLLECT
        )
        driver.create_subscription(
            Float64, "squeak/safe_speed", lambda m: stats.safe_speeds.append(m.data), COLLECT
        )
        client = driver.create_client(
            GetParameters, f"{node.get_fully_qualified_name()}/get_parameters"
        )
        world.spin_until(
            lambda: (
                client.service_is_ready()
                and speed_pub.get_subscription_count()
                and load_pub.get_subscription_count()
            ),
            20.0,
            "discovery",
        )

        request = GetParameters.Request(names=["n_bending", "speed_deadband_rad_s"])
        recomputes0, searches0 = node.live.recomputes, count_searches() if count_searches else 0
        pending: tuple[float, object] | None = None
        t0 = next_call = time.monotonic()
        for tick in range(int(duration_s * RATE_HZ)):
            speed, load = operating_point(tick / RATE_HZ)
            speed_pub.publish(Float64(data=speed))
            load_pub.publish(Float64(data=load))
            next_tick = t0 + (tick + 1) / RATE_HZ
            while True:  # serve the driver until the next tick, one call at a time
                if pending is not None and pending[1].done():
                    assert pending[1].result().values[0].integer_value == n_modes
                    stats.latencies_s.append(time.monotonic() - pending[0])
                    pending = None
                if pending is None and time.monotonic() >= next_call:
                    pending = (time.monotonic(), client.call_async(request))
                    next_call = pending[0] + CALL_PERIOD_S
                remaining = next_tick - time.monotonic()
                if remaining <= 0:
                    break
                executor.spin_once(timeout_sec=min(remaining, 0.005))
        stats.stream_s = (t0, time.monotonic())
        end = time.monotonic() + 10.0  # the last call, answered or timed out
        while pending is not None and not pending[1].done() and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
        if pending is not None:
            stats.latencies_s.append(time.monotonic() - pending[0])
        quiet = time.monotonic() + 1.0  # the node catches up, its last risks arrive
        while time.monotonic() < quiet:
            heard = len(stats.risk_times)
            executor.spin_once(timeout_sec=0.05)
            if len(stats.risk_times) > heard or node.live.due(time.monotonic()):
                quiet = time.monotonic() + 1.0
        stats.recomputes = node.live.recomputes - recomputes0
        stats.searches = (count_searches() if count_searches else 0) - searches0
        return stats
    finally:
        if spinner is not None:  # ends after the current callback (minutes on old code)
            spinner.stop(timeout=120.0)
        if node is not None:
            node.destroy_node()
        node_executor.shutdown(timeout_sec=1.0)
        world.close()


def test_parameters_and_predictions_never_wait_for_safe_speed_advice(monkeypatch):
    """40/40 modes (one band search: up to ~1 s alone, more on a busy machine), speed and load
    at 50 Hz in and out of the squeak band through several load bins: get_parameters always
    answers within 0.2 s, every recompute publishes its risk and none waits for advice."""
    from leadscrew_ros.live.recompute import LatestWorker  # here: stall_run runs on old code too

    requests = []
    submit = LatestWorker.submit

    def counted(self, job):
        requests.append(job)
        return submit(self, job)

    monkeypatch.setattr(LatestWorker, "submit", counted)
    stats = stall_run(40, 6.0, count_searches=lambda: len(requests))
    assert stats.searches >= 3  # advice was asked for meanwhile
    assert len(stats.latencies_s) >= 20
    slowest, prediction = sorted(stats.latencies_s)[-5:], max(stats.predictions_s)
    print(
        f"get_parameters: {len(stats.latencies_s)} calls, slowest {slowest}; recomputes "
        f"{stats.recomputes}, longest prediction {prediction:.3f} s, longest risk gap "
        f"{stats.max_risk_gap_s:.3f} s, advice requests {stats.searches}"
    )
    assert max(stats.latencies_s) <= max(
        MAX_PARAMETER_LATENCY_S, LATENCY_PREDICTIONS * prediction
    ), slowest
    assert stats.recomputes >= 6 and len(stats.risk_times) == stats.recomputes
    assert stats.max_risk_gap_s <= max(MAX_RISK_GAP_S, GAP_PREDICTIONS * prediction)
    assert stats.safe_speeds  # advice still reaches the topic
