# SPDX-License-Identifier: Apache-2.0
"""The input rules (`live.rules.InputRules`), and that the node and the offline replay, which
both wrap them, decide alike: one message stream fed to the node over loopback DDS (recorded),
to the replay of that recording, and to LivePredictor and Timeline without ROS gives the same
recomputes, predictions and squeak episodes."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Float64MultiArray

from harness.cdr_reference import cdr_payload
from harness.squeak import SqueakWorld
from leadscrew_ros.bag.logfile import LogMessage, Topic, read_log
from leadscrew_ros.live import rules as rules_module
from leadscrew_ros.live.recompute import LivePredictor
from leadscrew_ros.live.rules import InputRules, Outcome, moved, read_joint_state
from leadscrew_ros.live.settings import JointSettings, LiveSettings
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.physics.parameters import field_info
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.timeline import InputSettings, ModelSpec, Timeline, predict_jobs

PARAMS = ScrewParameters()
LEAD = PARAMS.lead_per_rad_m
TRAVEL = PARAMS.nut_travel_m
LOAD_LIMIT = field_info("axial_load_n")["hi"]
SCREW = JointSettings(joint_name="screw")


def rules(joints: JointSettings = SCREW, **live) -> InputRules:
    return InputRules(PARAMS, LiveSettings(**live), joints)


# ----------------------------------------------------------------------------- single values
def test_values_are_taken_or_rejected_with_a_reason_and_the_exact_value():
    r = rules()
    assert r.set_speed(20.0) == Outcome(taken=("speed",))
    assert r.set_load(-200) == Outcome(taken=("load",)) and r.inputs.load_n == -200.0
    assert r.set_nut_position(TRAVEL).applies and r.inputs.nut_position_m == TRAVEL
    cases = [
        ("set_speed", math.nan, "speed not finite", "speed = nan is not finite (rad/s)"),
        ("set_speed", "20", "speed not a number", "speed = '20' is not a number (rad/s)"),
        ("set_speed", True, "speed not a number", "speed = True is not a number (rad/s)"),
        ("set_load", -math.inf, "load not finite", "load = -inf is not finite (N)"),
        (
            "set_load",
            1.0000001e7,
            "load beyond 1e+07 N",
            "load = 1.0000001e+07 N exceeds the plausible magnitude 1e+07 N",
        ),
        (
            "set_nut_position",
            0.2400001,
            "nut position off the screw [0, 0.24] m",
            "nut position 0.2400001 m is off the screw: allowed [0, 0.24] m (z_o + b <= L)",
        ),
        (
            "set_nut_position",
            None,
            "nut position not a number",
            "nut position None is not a number",
        ),
    ]
    for method, value, reason, message in cases:
        outcome = getattr(r, method)(value)
        assert outcome.rejected and not outcome.taken and not outcome.applies
        assert (outcome.rejected[0].reason, outcome.error) == (reason, message)
    assert (r.inputs.speed_rad_s, r.inputs.load_n, r.inputs.nut_position_m) == (
        20.0,
        -200.0,
        TRAVEL,
    )  # the last good values stay
    assert [e.reason for e in r.errors.values()] == [
        "speed not a number",
        "load beyond 1e+07 N",
        "nut position not a number",
    ]
    r.set_load(200.0)  # a good value clears its error
    assert set(r.errors) == {"speed", "nut"}


def test_the_operating_point_needs_speed_and_load_and_the_nut_defaults_to_the_parameters():
    r = rules()
    assert r.point() is None and not r.changed() and r.compute() is None
    r.set_speed(20.0)
    assert r.point() is None
    r.set_load(200.0)
    assert r.point() == (20.0, 200.0, PARAMS.nut_position_m) and not r.nut_measured
    r.set_nut_position(0.1)
    assert r.point() == (20.0, 200.0, 0.1) and r.nut_measured


def test_deadbands_and_the_contact_rule():
    r = rules()  # 0.1 rad/s, 1 N, 0.5 mm
    r.set_speed(20.0), r.set_load(200.0)
    assert r.changed()
    assert r.compute() == ((20.0, 200.0, 0.15), 0.15) and not r.changed()
    for setter, within, beyond in (
        (r.set_speed, 20.09, 20.2),
        (r.set_load, 201.0, 201.5),
        (r.set_nut_position, 0.1504, 0.1506),
    ):
        setter(within)
        assert not r.changed()
        setter(beyond)
        assert r.changed()
        r.compute()
    assert r.contact_nut_m == 0.1506
    r.set_nut_position(0.1509)  # 0.3 mm from the contact: kept there
    r.set_speed(30.0)
    assert r.compute() == ((30.0, 201.5, 0.1509), 0.1506)
    r.set_nut_position(0.1512)  # 0.6 mm: re-integrated
    assert r.compute()[1] == 0.1512
    assert moved((1.0, 1.0, 1.0), (1.0, 1.0, 1.0), LiveSettings(0, 0, 0)) is False
    r.reset(PARAMS, LiveSettings())
    assert r.changed() and r.contact_nut_m == PARAMS.nut_position_m


# ----------------------------------------------------------------------------- JointState
def test_an_empty_joint_name_ignores_joint_states_even_with_one_joint():
    r = rules(JointSettings())
    outcome = r.set_joint_state(["screw"], [1.0], [20.0])
    assert outcome == Outcome(ignored="joint_name not set") and not outcome.applies
    assert r.inputs.speed_rad_s is None and r.inputs.nut_position_m is None


def test_joint_states_give_speed_and_nut_of_the_named_joint():
    r = rules(JointSettings(joint_name="screw", nut_position_at_zero_angle_m=0.1))
    outcome = r.set_joint_state(["wheel", "screw"], [0.3, 50.0], [9.0, -20.0])
    assert outcome.applies and outcome.taken == ("speed", "nut")
    assert r.inputs.speed_rad_s == -20.0
    assert r.inputs.nut_position_m == pytest.approx(0.1 + 50.0 * LEAD, rel=1e-15)
    assert r.set_joint_state(["wheel"], [1.0], [1.0]).ignored == "no joint 'screw'"
    assert r.set_joint_state(["wheel", "screw"], [7.0, 8.0], [1.0, 2.0]).taken == ("speed", "nut")
    assert r.set_joint_state(["screw"], [0.0], []).taken == ("nut",)
    assert (
        r.set_joint_state(["screw"], [], []).ignored == "joint 'screw' without position or velocity"
    )
    # both first: a bad speed does not keep a good nut out, but no recompute decision follows
    outcome = r.set_joint_state(["screw"], [10.0], [math.nan])
    assert outcome.taken == ("nut",) and not outcome.applies
    assert outcome.error == "speed = nan is not finite (rad/s)"
    assert r.inputs.speed_rad_s == 2.0 and r.inputs.nut_position_m == 0.1 + 10.0 * LEAD
    outcome = r.set_joint_state(["screw"], [1e6], [5.0])
    assert outcome.taken == ("speed",) and "off the screw" in outcome.error


@pytest.mark.parametrize(
    "names, positions, velocities, reason, words",
    [
        (
            ["wheel", "screw"],
            [1.0],
            [1.0, 2.0],
            "array lengths differ",
            "2 names but 1 positions and 2 velocities (each empty or one per name)",
        ),
        (["screw"], [1.0], [1.0, 2.0], "array lengths differ", "1 names but 1 positions and 2"),
        ([], [1.0], [2.0], "no names", "no joint names (1 positions, 1 velocities)"),
        ([], [], [], "no names", "no joint names (0 positions, 0 velocities)"),
        (
            ["screw", "screw"],
            [1.0, 2.0],
            [3.0, 4.0],
            "a name twice",
            "joint name(s) 'screw' given twice",
        ),
    ],
)
def test_a_malformed_joint_state_is_rejected_as_a_whole_with_its_reason(
    names, positions, velocities, reason, words
):
    """Never read by index: one counted reason and an invalid-input error until a well-formed
    JointState arrives (it was used by index without a word)."""
    r = rules(JointSettings(joint_name="screw"))
    outcome = r.set_joint_state(names, positions, velocities)
    assert not outcome.taken and not outcome.applies
    assert [x.reason for x in outcome.rejected] == [f"joint_states malformed: {reason}"]
    assert outcome.error == f"joint_states rejected: {words}" or words in outcome.error
    assert r.inputs.speed_rad_s is None and r.inputs.nut_position_m is None
    assert "joint_states" in r.errors
    assert r.set_joint_state(["screw"], [0.0], [5.0]).applies
    assert "joint_states" not in r.errors and r.inputs.speed_rad_s == 5.0


def test_a_nan_nut_position_is_not_a_finite_number():
    """Not 'nan m is off the screw'."""
    outcome = rules().set_nut_position(math.nan)
    assert [x.reason for x in outcome.rejected] == ["nut position not finite"]
    assert outcome.error == "nut position nan m is not a finite number"


def test_the_empty_joint_name_is_documented():
    assert (
        "ignores joint_states"
        in JointSettings.__dataclass_fields__["joint_name"].metadata["description"]
    )
    for doc in (rules_module.__doc__, JointSettings.__doc__):
        assert "ignores joint_states" in " ".join(doc.split())
    assert InputSettings().joint_name == JointSettings().joint_name == ""


def test_node_and_replay_hold_the_same_rules():
    assert isinstance(LivePredictor(SqueakModel()).rules, InputRules)
    assert isinstance(Timeline(PARAMS).rules, InputRules)
    tl = Timeline(PARAMS, InputSettings(joint_name="screw", speed_deadband_rad_s=0.5))
    assert tl.rules.joints == SCREW and tl.rules.live.speed_deadband_rad_s == 0.5


# ----------------------------------------------------------------------------- bad values
ANY = st.one_of(
    st.floats(),
    st.integers(min_value=-(10**400), max_value=10**400),
    st.text(max_size=4),
    st.booleans(),
    st.none(),
    st.sampled_from([0.0, 0.1, 0.24, 20.0, 200.0, -1e7, 1e7]),
)
OPS = st.one_of(
    st.tuples(st.sampled_from(["speed", "load", "nut"]), ANY),
    st.tuples(
        st.just("joint"),
        st.tuples(
            st.lists(st.sampled_from(["screw", "wheel", ""]), max_size=3),
            st.lists(ANY, max_size=3),
            st.lists(ANY, max_size=3),
        ),
    ),
)


def _good(kind: str, value) -> bool:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        v = float(value)
    except OverflowError:
        return False
    return (
        math.isfinite(v)
        and (kind != "load" or abs(v) <= LOAD_LIMIT)
        and (kind != "nut" or 0.0 <= v <= TRAVEL)
    )


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(OPS, max_size=30), st.sampled_from(["", "screw"]))
def test_bad_values_never_raise_and_keep_the_last_good_state(ops, joint_name):
    r = rules(JointSettings(joint_name=joint_name))
    for kind, value in ops:
        before = (r.inputs.speed_rad_s, r.inputs.load_n, r.inputs.nut_position_m)
        if kind == "joint":
            outcome = r.set_joint_state(*value)
        else:
            outcome = getattr(r, {"nut": "set_nut_position"}.get(kind, f"set_{kind}"))(value)
            assert (outcome.taken == (kind,)) == _good(kind, value), (kind, value)
        assert outcome.applies == (bool(outcome.taken) and not outcome.rejected)
        if outcome.ignored:
            assert not outcome.taken and not outcome.rejected and "\n" not in outcome.ignored
        for rejection in outcome.rejected:
            assert rejection.reason and rejection.message
            assert "\n" not in rejection.reason + rejection.message
        after = (r.inputs.speed_rad_s, r.inputs.load_n, r.inputs.nut_position_m)
        for name, old, new in zip(("speed", "load", "nut"), before, after, strict=True):
            if name not in outcome.taken:
                assert new is old or new == old  # nan never gets in
            else:
                assert type(new) is float and math.isfinite(new)
        speed, load, nut = after
        assert load is None or abs(load) <= LOAD_LIMIT
        assert nut is None or 0.0 <= nut <= TRAVEL
        assert (r.point() is None) == (speed is None or load is None)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(
    st.lists(st.text(max_size=3), max_size=3), st.lists(ANY, max_size=3), st.lists(ANY, max_size=3)
)
def test_reading_any_joint_state_never_raises(names, positions, velocities):
    reading = read_joint_state(names, positions, velocities, SCREW, LEAD)
    malformed = (
        not names
        or len(set(names)) < len(names)
        or len(positions) not in (0, len(names))
        or len(velocities) not in (0, len(names))
    )
    assert (reading.rejected is not None) == malformed
    assert bool(reading.ignored) == (
        not malformed and ("screw" not in names or not (positions or velocities))
    )


# ----------------------------------------------------------------------------- one stream
def js(names, positions, velocities) -> JointState:
    return JointState(name=names, position=positions, velocity=velocities)


# (input topic, value): speeds and loads through the squeak band (Table 1 at 200 N squeaks
# between ~0.8 and ~55 rad/s; at 40 rad/s it squeaks from ~100 N on), nut moves, values within
# the deadbands, rejected values, and JointStates of the screw joint among others.
STREAM = [
    ("axial_load", 200.0),
    ("motor_speed", 100.0),  # stable: the first recompute
    ("motor_speed", 20.0),  # squeak
    ("motor_speed", 20.05),  # within the speed deadband
    ("nut_position", 0.10),  # contact re-integrated
    ("nut_position", 0.1003),  # within the nut deadband
    ("axial_load", math.nan),
    ("axial_load", 1e8),
    ("motor_speed", math.inf),
    ("nut_position", 0.3),  # off the screw
    ("motor_speed", 40.0),
    ("axial_load", 20.0),  # stable
    ("axial_load", 100.0),  # squeak
    ("axial_load", 100.5),  # within the load deadband
    ("axial_load", 50.0),  # stable
    ("axial_load", 200.0),  # squeak
    ("joint_states", js(["wheel", "screw"], [0.3, -50.0], [9.0, 60.0])),  # stable
    ("joint_states", js(["wheel"], [1.0], [2.0])),  # no screw
    ("joint_states", js(["wheel", "screw"], [0.3, -50.0], [9.0, 30.0])),  # squeak
    ("joint_states", js(["screw"], [], [35.0])),  # speed only
    ("joint_states", js(["screw"], [100.0], [])),  # nut only
    ("joint_states", js(["screw"], [0.0], [math.nan])),  # speed rejected
    ("joint_states", js(["screw"], [1000.0], [45.0])),  # nut off the screw
    ("motor_speed", 100.0),  # stable, at the nut of the joint state before
    ("axial_load", 3000.0),  # squeak
    ("motor_speed", 100.05),
    ("nut_position", 0.05),
    ("motor_speed", 70.0),
]
TYPES = {
    "motor_speed": Float64,
    "axial_load": Float64,
    "nut_position": Float64,
    "joint_states": JointState,
}


def message(topic: str, value):
    return value if isinstance(value, JointState) else Float64(data=value)


def live_predictions(stream) -> list:
    """The node's decisions without ROS: one LivePredictor, each input a second apart."""
    lp = LivePredictor(SqueakModel(), LiveSettings(), joints=SCREW)
    out = []
    try:
        for k, (topic, value) in enumerate(stream):
            now = float(k)
            if topic == "joint_states":
                outcome = lp.set_joint_state(value.name, value.position, value.velocity, now)
                if outcome.ignored:
                    continue
                error = outcome.error
            else:
                setter = {
                    "motor_speed": lp.set_speed,
                    "axial_load": lp.set_load,
                    "nut_position": lp.set_nut_position,
                }[topic]
                error = setter(value, now)
            if not error and lp.due(now):
                out.append(lp.update(now))
    finally:
        lp.close()
    return out


def timeline_predictions(stream) -> tuple[list, Timeline]:
    """The replay's decisions: a Timeline fed the serialized messages, batched predictions."""
    tl = Timeline(PARAMS, InputSettings(joint_name="screw"))
    jobs = []
    for k, (topic, value) in enumerate(stream):
        t = Topic(
            "/" + topic,
            f"{TYPES[topic].__module__.split('.')[0]}/msg/{TYPES[topic].__name__}",
            "ros2msg",
            "",
            "cdr",
            {},
        )
        job = tl.feed(LogMessage(t, k * 10**9, k * 10**9, k, cdr_payload(message(topic, value))), k)
        if job is not None:
            jobs.append(job)
    preds = (
        predict_jobs(
            ModelSpec.of(SqueakModel(PARAMS)),
            *(
                np.array([getattr(j, f) for j in jobs])
                for f in ("speed_rad_s", "load_n", "model_nut_m")
            ),
        )
        if jobs
        else []
    )
    return preds, tl


def same_predictions(a, b) -> None:
    """P(squeak), margin, squeak frequencies and squeak verdict, one for one (same solver, maybe
    batched; the same scatter samples)."""
    assert len(a) == len(b)
    for k, (p, q) in enumerate(zip(a, b, strict=True)):
        assert p.keys() == q.keys()
        assert p["active"] == q["active"], k
        assert p["probability"] == q["probability"], k
        assert p["margin"] == pytest.approx(q["margin"], rel=1e-9), k
        assert p["frequencies"] == pytest.approx(q["frequencies"], rel=1e-9), k


def outputs(p) -> dict:
    return {
        "probability": p.probability,
        "margin": p.margin,
        "frequencies": list(p.unstable_frequencies_hz),
        "active": not p.stable,
    }


def test_live_predictor_and_timeline_decide_alike_without_ros():
    live = live_predictions(STREAM)
    offline, tl = timeline_predictions(STREAM)
    assert all(p is not None and p.valid for p in live + offline)
    same_predictions([outputs(p) for p in live], [outputs(p) for p in offline])
    actives = [not p.stable for p in live]
    assert 14 <= len(live) <= 20 and actives.count(True) >= 5 and actives.count(False) >= 5
    assert sum(a != b for a, b in zip(actives, actives[1:], strict=False)) >= 8  # through the band
    assert dict(tl.ignored) == {"/joint_states: no joint 'screw'": 1}
    assert dict(tl.rejected) == {
        "load not finite": 1,
        "load beyond 1e+07 N": 1,
        "speed not finite": 2,
        "nut position off the screw [0, 0.24] m": 2,
    }


def wrap_calls(live: LivePredictor) -> Counter:
    """Count the node's input callbacks through the LivePredictor methods they call."""
    calls = Counter()
    for name in ("set_speed", "set_load", "set_nut_position", "set_joint_state"):
        method = getattr(live, name)
        setattr(live, name, lambda *a, _m=method, _n=name: (calls.update([_n]), _m(*a))[1])
    return calls


def test_node_and_replay_of_its_recording_predict_alike(tmp_path):
    with SqueakWorld() as ros:
        node = ros.start(
            **{
                "record.enabled": True,
                "record.directory": str(tmp_path / "bags"),
                "joint_name": "screw",
                "max_rate_hz": 10000.0,
            }
        )
        assert node.recorder.active
        calls = wrap_calls(node.live)
        pubs = {}
        for topic, msg_type in TYPES.items():
            pubs[topic] = pub = ros.probe.create_publisher(msg_type, topic, 10)
            # the node's subscription and the recording's
            ros.spin_until(
                lambda p=pub: p.get_subscription_count() >= 2, 30.0, f"subscribers on {topic}"
            )
        sent = Counter()
        for k, (topic, value) in enumerate(STREAM):
            pubs[topic].publish(message(topic, value))
            sent[topic] += 1
            name = f"{ros.ns}/{topic}"
            # processed by the node, no recompute held back by the rate limit (its timer runs
            # only then), and recorded, before the next one is sent
            ros.spin_until(
                lambda k=k, name=name, n=sent[topic]: (
                    sum(calls.values()) == k + 1
                    and node._rate_timer.is_canceled()
                    and node.recorder.count(name) == n
                ),
                30.0,
                f"message {k} ({topic})",
            )
        recomputes = node.live.recomputes
        bag = node.recorder.bag
        node.destroy_node()  # the bag is finished
        ros.executor.remove_node(node)
        ros.node = None

    recorded: dict[str, list] = {}
    for m in read_log(bag):
        recorded.setdefault(m.topic.name, []).append(m)
    for topic, n in Counter(t for t, _ in STREAM).items():
        assert len(recorded[f"{ros.ns}/{topic}"]) == n, topic  # none lost
    node_out = [
        {
            "probability": deserialize_message(r.data, Float64).data,
            "margin": deserialize_message(g.data, Float64).data,
            "frequencies": list(deserialize_message(f.data, Float64MultiArray).data),
            "active": deserialize_message(a.data, Bool).data,
        }
        for r, g, f, a in zip(
            *(
                recorded[f"{ros.ns}/squeak/{name}"]
                for name in ("risk", "margin", "unstable_frequencies", "active")
            ),
            strict=True,
        )
    ]
    assert len(node_out) == recomputes == len(recorded[f"{ros.ns}/squeak/active"])

    r = replay(
        bag,
        SqueakModel(),
        tmp_path / "out",
        ReplaySettings(InputSettings(joint_name="screw"), workers=0, progress=False),
    )
    assert r.namespace == ros.ns and not r.no_prediction
    assert r.recomputes == r.predictions == recomputes
    out_ns = f"/replay{ros.ns}/squeak"
    annotated = {}
    names = ("risk", "margin", "unstable_frequencies", "active")
    for m in read_log(r.annotated, topics={f"{out_ns}/{n}" for n in names}):
        annotated.setdefault(m.topic.name.rsplit("/", 1)[1], []).append(m)
    replay_out = [
        {
            "probability": deserialize_message(a.data, Float64).data,
            "margin": deserialize_message(g.data, Float64).data,
            "frequencies": list(deserialize_message(f.data, Float64MultiArray).data),
            "active": deserialize_message(b.data, Bool).data,
        }
        for a, g, f, b in zip(*(annotated[n] for n in names), strict=True)
    ]
    same_predictions(node_out, replay_out)
    # and both as without ROS
    same_predictions(node_out, [outputs(p) for p in live_predictions(STREAM)])
    assert dict(r.ignored) == {f"{ros.ns}/joint_states: no joint 'screw'": 1}

    # episodes: where the node's squeak/active was true, from the recompute that turned it on
    # to the one that turned it off (or the end of the log), at the replay's recompute times
    times = [(m.log_time_ns - r.start_ns) / 1e9 for m in annotated["active"]]
    actives = [o["active"] for o in node_out]
    expected, start = [], None
    for t, active in zip(times, actives, strict=True):
        if active and start is None:
            start = t
        elif not active and start is not None:
            expected.append((start, t))
            start = None
    if start is not None:
        expected.append((start, r.duration_s))
    assert len(expected) >= 4
    assert [(e.start_s, e.end_s) for e in r.episodes] == expected
    assert [e.predictions for e in r.episodes] == [
        len(run) for run in "".join("1" if a else "0" for a in actives).split("0") if run
    ]
