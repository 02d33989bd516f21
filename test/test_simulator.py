# SPDX-License-Identifier: Apache-2.0
"""The actuator simulator: the stroke profile (pure) and the ROS 2 node that publishes it."""

import math
import re
import uuid

import numpy as np
import pytest
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from harness.processes import CLI, domain, output, start, stop
from leadscrew_ros.cli import main
from leadscrew_ros.live.profile import ProfileError, StrokeProfile, expected_squeak, state
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.ros.simulator import ActuatorSimulator

PARAMS = ScrewParameters()
LEAD = PARAMS.radius_m * math.tan(PARAMS.helix_angle_rad)  # 0.437 mm/rad
TRAVEL_LIMIT = PARAMS.length_m - PARAMS.nut_length_m  # 0.24 m


def sample(profile, n=4001, loop=False, strokes=1):
    t = np.linspace(0.0, strokes * profile.duration_s, n)
    return t, np.array([profile.state(x, loop) for x in t])


# ----------------------------------------------------------------------------- profile
def test_default_profile_matches_table1_screw():
    p = StrokeProfile()
    assert p.duration_s == 12.0 and p.peak_speed_rad_s == 120.0
    assert p.lead_m_per_rad == pytest.approx(0.4374e-3, rel=1e-3) == LEAD
    assert p.max_nut_position_m == pytest.approx(0.24)
    assert StrokeProfile.for_params(PARAMS) == p
    assert state(3.0) == p.state(3.0)  # module-level function, same profile


def test_speed_ramps_through_and_beyond_the_squeak_band_and_back():
    p = StrokeProfile()
    t, s = sample(p)
    speed = s[:, 0]
    assert speed[0] == 0 and speed[-1] == 0 and np.all(speed >= 0)
    assert speed.max() == pytest.approx(p.peak_speed_rad_s)
    peak = np.flatnonzero(speed == speed.max())
    assert np.all(np.diff(speed[: peak[0] + 1]) >= 0)  # ramps up monotonically
    assert np.all(np.diff(speed[peak[-1] :]) <= 0)  # holds, then ramps down
    assert np.abs(np.diff(speed)).max() < 0.5  # continuous (dt = 3 ms)
    # The model (paper formulation, Table 1) squeaks on the way up and on the way down ...
    model = SqueakModel()
    verdicts = {x: model.predict(*p.state(x)[:2]) for x in (2.0, 3.0, 7.5, 8.5)}
    assert all(v.valid and not v.stable and v.probability > 0.5 for v in verdicts.values()), (
        verdicts
    )
    assert any(abs(f - 224.3) < 2 for v in verdicts.values() for f in v.unstable_frequencies_hz)
    # ... and not at the peak speed, beyond the band, at any load of the stroke: P(squeak) ~0.
    for x in t[speed == speed.max()][::50]:
        v = model.predict(*p.state(x)[:2])
        assert v.valid and v.stable and v.probability < 0.01, (x, v.probability)


def test_expected_squeak_along_the_stroke():
    p = StrokeProfile()
    times, flags = expected_squeak(p, samples=121)
    squeak_s = flags.mean() * p.duration_s
    assert 3.0 < squeak_s < 7.0  # a large part of the ramps, not the hold
    hold = (times > 0.45 * p.duration_s) & (times < 0.48 * p.duration_s)
    assert hold.any() and not flags[hold].any()
    assert not flags[0] and not flags[-1]  # at rest


def test_nut_stays_on_the_screw_and_load_in_range():
    p = StrokeProfile()
    for loop, strokes in ((False, 1), (True, 3)):
        _, s = sample(p, n=6001, loop=loop, strokes=strokes)
        nut, load = s[:, 2], s[:, 1]
        assert nut.min() >= 0 and nut.max() <= TRAVEL_LIMIT
        assert nut.min() == pytest.approx(p.start_nut_position_m)
        assert nut.max() == pytest.approx(p.end_nut_position_m) and nut.max() < TRAVEL_LIMIT - 0.01
        assert load.min() >= p.load_min_n - 1e-9 and load.max() <= p.load_max_n + 1e-9
        assert load.max() - load.min() > 0.8 * (p.load_max_n - p.load_min_n)  # it varies
    _, s = sample(p)
    assert np.abs(np.diff(s[:, 1])).max() < 1.0  # smoothly (N per 3 ms)
    assert s[-1, 2] - s[0, 2] == pytest.approx(p.travel_m) and 0.15 < p.travel_m < 0.22


def test_nut_travel_is_the_integral_of_speed_times_lead():
    p = StrokeProfile()
    for loop, strokes in ((False, 1), (True, 2)):
        t, s = sample(p, n=20001, loop=loop, strokes=strokes)
        speed, nut, angle = s[:, 0], s[:, 2], s[:, 3]
        integral = np.concatenate([[0.0], np.cumsum(np.diff(t) * (speed[1:] + speed[:-1]) / 2)])
        np.testing.assert_allclose(nut - nut[0], integral * LEAD, atol=2e-6)
        # The screw angle describes the same nut (the node's joint_states conversion).
        np.testing.assert_allclose(p.nut_position_at_zero_angle_m + angle * LEAD, nut, atol=1e-12)


def test_loop_runs_back_and_forth_without_jumps():
    p = StrokeProfile(duration_s=4.0)
    d = p.duration_s
    forward, back = p.state(0.5 * d, loop=True), p.state(1.5 * d, loop=True)
    assert forward.speed_rad_s > 0 > back.speed_rad_s
    assert back.speed_rad_s == -forward.speed_rad_s
    for k in (1, 2, 3):  # stroke boundaries: at rest, nut continuous
        before, after = p.state(k * d - 1e-9, loop=True), p.state(k * d, loop=True)
        assert before.speed_rad_s == after.speed_rad_s == 0
        assert before.nut_position_m == pytest.approx(after.nut_position_m, abs=1e-9)
    assert p.state(2 * d, loop=True) == p.state(0.0)
    # Without loop the end state holds, and before 0 the start state.
    assert p.state(10 * d) == p.state(d) and p.state(-1.0) == p.state(0.0)


def test_profile_is_deterministic_and_scales_with_duration():
    a, b = StrokeProfile(duration_s=3.0), StrokeProfile(duration_s=3.0)
    assert [a.state(x) for x in np.linspace(0, 3, 50)] == [
        b.state(x) for x in np.linspace(0, 3, 50)
    ]
    assert a.state(1.0).speed_rad_s == StrokeProfile().state(4.0).speed_rad_s
    assert a.travel_m == pytest.approx(StrokeProfile().travel_m / 4)


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"duration_s": 20.0}, r"off the screw .* longest stroke at this speed is 13\.1 s"),
        ({"duration_s": 0.0}, "duration_s must be"),
        ({"duration_s": math.nan}, "duration_s must be"),
        ({"peak_speed_rad_s": -5.0}, "peak_speed_rad_s must be"),
        ({"load_min_n": 400.0}, "load_min_n <= load_max_n"),
        ({"start_nut_position_m": -0.01}, "off the screw"),
    ],
)
def test_impossible_profiles_are_rejected(changes, match):
    with pytest.raises(ProfileError, match=match):
        StrokeProfile(**changes)


@pytest.mark.parametrize(
    "argv, match",
    [
        (["simulate", "--duration", "100"], "argument --duration: a 100 s stroke"),
        (["simulate", "--duration", "0"], "argument --duration: duration_s must be"),
        (["simulate", "--rate", "0"], "argument --rate: must be in (0, 10000] Hz"),
        (["simulate", "--rate", "1e5"], "argument --rate: must be in (0, 10000] Hz"),
        (["simulate", "--rate", "nan"], "argument --rate"),
        (["demo", "--duration", "-3"], "argument --duration"),
        (["demo", "--loop"], "unrecognized arguments"),
    ],
)
def test_cli_rejects_bad_simulator_arguments(capsys, argv, match):
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1
    assert err.startswith("leadscrew-squeak: error: ") and match in err, err


# ----------------------------------------------------------------------------- node
class Probe(Node):
    def __init__(self, ns, **kwargs):
        super().__init__("probe", namespace=ns, **kwargs)
        self.got = {name: [] for name in ("motor_speed", "axial_load", "nut_position")}
        self.joints = []
        for name in self.got:
            self.create_subscription(
                Float64,
                name,
                lambda msg, name=name: self.got[name].append(msg.data),
                qos_profile_sensor_data,
            )  # as the predictor does
        self.create_subscription(
            JointState, "joint_states", self.joints.append, qos_profile_sensor_data
        )


def test_simulator_node_publishes_the_stroke(ros_world):
    """What arrives is what the simulator published (its own record, not a count expected from
    the wall clock: a busy machine fires fewer timer ticks), in order, from the start, as the
    simulator waits until every subscriber matched."""
    ns = "/sim_" + uuid.uuid4().hex[:8]
    profile = StrokeProfile(duration_s=1.0)
    probe = ros_world.add(Probe(ns, context=ros_world.ctx))
    sim = ActuatorSimulator(
        profile,
        rate_hz=100.0,
        joint_name="screw",
        wait_for_subscriber=True,
        namespace=ns,
        context=ros_world.ctx,
    )
    sent, publish = [], sim.publish
    sim.publish = lambda s: (sent.append(s), publish(s))
    ros_world.add(sim)
    ros_world.spin_until(
        lambda: (
            sim.done
            and all(len(probe.got[n]) >= len(sent) for n in probe.got)
            and len(probe.joints) >= len(sent)
        ),
        30.0,
        "the whole stroke",
    )
    assert sim.done and sim.started_at is not None

    speeds, loads, nuts = (probe.got[n] for n in ("motor_speed", "axial_load", "nut_position"))
    assert len(sent) == sim.published >= 3
    assert speeds == [s.speed_rad_s for s in sent] and loads == [s.load_n for s in sent]
    assert nuts == [s.nut_position_m for s in sent]
    # the samples follow the profile (at the wall-clock times the timer fired)
    assert speeds[-1] == 0.0 and sent[-1] == profile.state(profile.duration_s)
    assert np.all(np.diff(nuts) >= 0) and max(speeds) <= profile.peak_speed_rad_s
    assert min(loads) >= profile.load_min_n and max(loads) <= profile.load_max_n
    assert nuts[0] == pytest.approx(profile.start_nut_position_m, abs=1e-3)
    assert nuts[-1] == pytest.approx(profile.end_nut_position_m)
    assert [j.velocity[0] for j in probe.joints] == speeds
    last = probe.joints[-1]
    assert list(last.name) == ["screw"] and last.velocity[0] == 0.0
    assert last.position[0] == pytest.approx(profile.state(1.0).screw_angle_rad)
    assert sim.published > 0 and sim.elapsed_s >= profile.duration_s


def test_joint_states_describe_the_same_nut_as_nut_position(ros_world):
    """The predictor fed by joint_states only (its nut_position input remapped away) sees the
    simulator's nut: the screw angle follows the node's nut_position_at_zero_angle_m."""
    from rclpy.parameter import Parameter

    from leadscrew_ros.ros.node import SqueakPredictorNode

    ns = "/joint_" + uuid.uuid4().hex[:8]
    profile = StrokeProfile(duration_s=1.0)
    predictor = ros_world.add(
        SqueakPredictorNode(
            namespace=ns,
            context=ros_world.ctx,
            cli_args=["--ros-args", "-r", "nut_position:=unused"],
            parameter_overrides=[Parameter("joint_name", value="screw")],
        )
    )
    sim = ros_world.add(
        ActuatorSimulator(
            profile,
            joint_name="screw",
            wait_for_subscriber=True,
            namespace=ns,
            context=ros_world.ctx,
        )
    )
    ros_world.spin_until(lambda: sim.done, 10.0, "the stroke")
    ros_world.spin_for(0.3)  # the last inputs
    inputs, recomputes = predictor.live.inputs, predictor.live.recomputes
    assert sim.done and recomputes >= 2  # a loaded machine fires the 1-s stroke's timer less
    assert inputs.nut_position_m == pytest.approx(profile.end_nut_position_m, abs=1e-9)
    assert inputs.speed_rad_s == 0.0


def test_simulate_in_a_namespace_from_ros_args(tmp_path, make_ros_world):
    """`simulate --ros-args -r __ns:=/seat_left` publishes /seat_left/motor_speed, ... (a
    subprocess, as a user runs it; the probe is started first, see test_demo)."""
    seat = "/seat_left_" + uuid.uuid4().hex[:8]
    dom = domain(7)
    world = make_ros_world(domain_id=dom)
    sim = None
    try:
        probe = world.add(Probe(seat, context=world.ctx))
        root = world.add(Probe("/", context=world.ctx))  # nothing arrives outside the namespace
        sim = start(
            CLI
            + [
                "simulate",
                "--duration",
                "0.5",
                "--rate",
                "50",
                "--ros-args",
                "-r",
                f"__ns:={seat}",
            ],
            dom,
            tmp_path,
            "sim",
        )
        world.spin_until(lambda: sim.poll() is not None, 60, "the simulator to finish")
        world.spin_for(0.5)
        code = sim.returncode
        out, err = output(sim)
    finally:
        stop(sim)
    assert code == 0 and err == "", (out, err)
    assert f"on {seat}/motor_speed, {seat}/axial_load, {seat}/nut_position" in out
    published = int(re.search(r"stroke done: (\d+) samples published", out)[1])
    speeds = probe.got["motor_speed"]
    assert 0 < len(speeds) <= published and speeds[-1] == 0.0  # the stroke, to its end
    assert all(v == [] for v in root.got.values())
