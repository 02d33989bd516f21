# SPDX-License-Identifier: Apache-2.0
"""Offline replay of MCAP logs (`leadscrew_ros.review.replay`,
`leadscrew-squeak replay/recover/info`).

Logs come from our Recorder (`synthetic_log`), from rosbags' rosbag2 writer (an independent
producer) and from hand-written MCAP files. Predictions are checked against the core
(`SqueakModel.predict`) at operating points rebuilt by the test itself from the original
messages, decoded with mcap_ros2 (not with the replay's own decoders).
"""

import json
import math
import re
import shutil
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader

from harness.compare import REL, mode_differences, same_probability
from harness.logs import EXACT, TYPESTORE, cli, decoded, f64, rosbags_log, run_replay, write_mcap
from leadscrew_ros.bag.messages import PREDICTION_TOPICS
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.physics.stability import GROWTH_TOL
from leadscrew_ros.review.replay import ratio_text
from leadscrew_ros.review.report import QUICK, write_report
from leadscrew_ros.review.timeline import InputSettings

PARAMS = ScrewParameters()
LEAD = PARAMS.radius_m * math.tan(PARAMS.helix_angle_rad)
CYCLE = DutyCycle(duration_s=30.0, rate_hz=50.0, rest_s=3.0)  # two strokes, back and forth
SHORT = DutyCycle(duration_s=12.5, rate_hz=25.0, rest_s=0.5)  # one stroke
OUT_NAMES = [f"/replay/{topic}" for topic in PREDICTION_TOPICS]
SAMPLES = SqueakModel(PARAMS).samples.count  # behind each P(squeak)


def the_mcap(bag: Path) -> Path:
    (file,) = bag.glob("*.mcap")
    return file


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    return write_log(CYCLE, tmp_path_factory.mktemp("bag"))


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    return the_mcap(write_log(SHORT, tmp_path_factory.mktemp("short")))


@pytest.fixture(scope="module")
def replayed(bag, tmp_path_factory):
    return run_replay(bag, tmp_path_factory.mktemp("out"), joint_name=CYCLE.joint_name)


def plain(messages):
    """Comparable content of decoded messages: the decoded values, not the bytes (Fast CDR
    leaves alignment padding inside a payload uninitialised, so equal messages can differ in
    their padding bytes)."""
    return [(m[0], m[1], m[2], m[3], repr(m[5])) for m in messages]


# ----------------------------------------------------------------------------- the oracle
def expected_recomputes(messages, joint="", nut_zero=0.15):
    """The node's rule with zero deadbands, rebuilt independently: after every input message
    that changed the point (speed and load known), (index, log time, speed, load, nut).
    joint_states count only with a `joint` (as the node's joint_name)."""
    speed = load = None
    nut, last, out = PARAMS.nut_position_m, None, []
    for i, (topic, t, _, _, _, msg) in enumerate(messages):
        if topic == "/motor_speed":
            speed = msg.data
        elif topic == "/axial_load":
            load = msg.data
        elif topic == "/nut_position":
            nut = msg.data
        elif topic == "/joint_states" and joint:
            k = msg.name.index(joint)
            speed, nut = msg.velocity[k], nut_zero + msg.position[k] * LEAD
        else:
            continue
        point = (speed, load, nut)
        if speed is not None and load is not None and point != last:
            out.append((i, t, *point))
            last = point
    return out


_models: dict[float, SqueakModel] = {}


def core(speed, load, nut):
    if nut not in _models:
        _models[nut] = SqueakModel(PARAMS.with_(nut_position_m=nut))
    return _models[nut].predict(speed, load)


def check_against_core(annotated: Path, joint="", nut_zero=0.15):
    """Every recompute of the rebuilt timeline has exactly the core's prediction right after
    its input (same log time), or nothing when the core says it is outside validity.
    Returns [(t_ns, prediction)] of the recomputes."""
    messages = decoded(annotated)
    originals = [m for m in messages if not m[0].startswith("/replay/")]
    outputs = [m for m in messages if m[0].startswith("/replay/")]
    position = {id(m): i for i, m in enumerate(messages)}
    it = iter(outputs)
    seen = []
    for i, t, speed, load, nut in expected_recomputes(originals, joint, nut_zero):
        p = core(speed, load, nut)
        seen.append((t, p))
        if not p.valid:
            continue
        group = [next(it) for _ in OUT_NAMES]
        assert [g[0] for g in group] == OUT_NAMES
        assert all(g[1] == g[2] == t for g in group)
        # right after the triggering input in file order
        assert position[id(group[0])] > position[id(originals[i])]
        risk, margin, freqs, active, modes = (g[5] for g in group)
        # squeak/risk is P(squeak) over the model's scatter, the core's number (a share of the
        # scatter samples, harness/compare.py); squeak/margin the least damping ratio
        assert same_probability(risk.data, p.probability, SAMPLES) and 0.0 <= risk.data <= 1.0
        labels = modes.layout.dim[0].label.removeprefix("modes:").split(",")
        rows = np.reshape(modes.data, (-1, 3)).tolist()
        assert not mode_differences(
            [(label, *row) for label, row in zip(labels, rows, strict=True)], p.modes
        )
        assert margin.data == min(row[2] for row in rows)  # the least of these damping ratios
        assert (margin.data < 0) == any(m.unstable for m in p.modes)
        squeak = [
            row[0] for row in rows if row[1] > GROWTH_TOL * math.hypot(row[1], 2 * math.pi * row[0])
        ]
        assert sorted(freqs.data) == sorted(squeak)  # these modes' squeak frequencies
        assert active.data == (not p.stable)
    assert next(it, None) is None, "a prediction the core did not make"
    return seen


def intervals(seen, start_ns, end_s):
    """Squeak intervals from the core's verdicts: from the first unstable recompute to the next
    recompute that is not (stable, or outside validity), or the end of the log."""
    out, start = [], None
    for t, p in seen:
        squeak = p.valid and not p.stable
        s = (t - start_ns) / 1e9
        if squeak and start is None:
            start = s
        elif not squeak and start is not None:
            out.append((start, s))
            start = None
    if start is not None:
        out.append((start, end_s))
    return out


# ----------------------------------------------------------------------------- our recorder
def test_replay_of_a_recorded_log(replayed, bag):
    r = replayed
    samples = CYCLE.samples
    assert r.files == sorted(bag.glob("*.mcap")) and r.messages == 3 * samples
    assert dict(r.inputs) == {
        "/motor_speed": samples,
        "/axial_load": samples,
        "/joint_states": samples,
    }
    assert r.duration_s == pytest.approx(CYCLE.duration_s - 1 / CYCLE.rate_hz, abs=1e-3)
    assert 0 < r.predictions <= r.recomputes < r.messages / 3  # the deadbands coalesce
    assert set(r.no_prediction) == {"speed below min_speed_rad_s"}  # at rest
    assert not r.rejected and not r.ignored
    assert len(r.episodes) >= 2  # each stroke squeaks
    assert r.annotated.name == f"{bag.name}.annotated.mcap"
    episodes = json.loads((r.out_dir / "episodes.json").read_text())
    assert len(episodes) == len(r.episodes)
    for e in episodes:
        assert 0 <= e["start_s"] < e["end_s"] <= r.duration_s
        assert e["frequencies_hz"] == sorted(e["frequencies_hz"]) and e["frequencies_hz"]
        assert e["peak_growth_rate"] > 0 and len(e["modes"]) == len(e["frequencies_hz"])
        assert e["speed_min_rad_s"] <= e["speed_max_rad_s"]
    assert any(224 < f < 226 for e in episodes for f in e["frequencies_hz"])  # B1y
    summary = json.loads((r.out_dir / "summary.json").read_text())
    assert summary["predictions"] == r.predictions and summary["episodes"] == len(episodes)
    assert summary["time_in_squeak_s"] == pytest.approx(sum(e["duration_s"] for e in episodes))
    # P(squeak): peaks near 1 in the band; at or above WARN in every episode and around them
    for e in episodes:
        assert 0.9 < e["peak_probability"] <= 1.0
        assert e["start_s"] <= e["peak_probability_t_s"] < e["end_s"]
        assert 0 < e["time_above_error_s"] <= e["time_above_warn_s"] <= e["duration_s"] + 1e-9
    assert summary["peak_probability"] == max(e["peak_probability"] for e in episodes)
    assert summary["time_above_warn_s"] > sum(e["time_above_warn_s"] for e in episodes)
    assert (summary["warn_probability"], summary["error_probability"]) == (0.1, 0.5)
    assert (r.out_dir / "summary.txt").read_text().startswith("replay of ")


def test_zero_deadbands_give_the_core_prediction_at_every_input(short_log, tmp_path):
    r = run_replay(short_log, tmp_path, joint_name=SHORT.joint_name, **EXACT)
    seen = check_against_core(r.annotated, joint=SHORT.joint_name)
    assert r.recomputes == len(seen) and r.predictions == sum(p.valid for _, p in seen)
    assert r.predictions > 100
    probabilities = [p.probability for _, p in seen if p.valid]
    assert min(probabilities) == 0.0 and max(probabilities) > 0.98  # fast; in the band
    assert any(0.2 < q < 0.8 for q in probabilities)  # near a band edge
    # Episodes are exactly the intervals where the core says unstable.
    expected = intervals(seen, r.start_ns, r.duration_s)
    assert len(expected) >= 1
    assert [(e.start_s, e.end_s) for e in r.episodes] == expected
    for e in r.episodes:
        inside = [p for t, p in seen if e.start_s <= (t - r.start_ns) / 1e9 < e.end_s]
        assert set(e.modes) == {m.label for p in inside for m in p.squeak_modes}
        scale = max(
            math.hypot(m.growth_rate, 2 * math.pi * m.frequency_hz)
            for q in inside
            for m in q.squeak_modes
        )
        assert e.peak_growth_rate == pytest.approx(
            max(p.max_growth_rate for p in inside), rel=0, abs=REL * scale
        )
        assert same_probability(e.probability.peak, max(p.probability for p in inside), SAMPLES)


def test_input_defaults_are_the_nodes():
    from leadscrew_ros.ros.parameters import PARAMETERS

    defaults = {s.name: s.default for s in PARAMETERS}
    s = InputSettings()
    for name in (
        "speed_deadband_rad_s",
        "load_deadband_n",
        "nut_deadband_m",
        "nut_position_at_zero_angle_m",
    ):
        assert getattr(s, name) == defaults[name], name
    assert StrokeProfile().nut_position_at_zero_angle_m == s.nut_position_at_zero_angle_m


def test_annotated_log_holds_every_original_message_unchanged(replayed, bag):
    original = [m[:5] for f in sorted(bag.glob("*.mcap")) for m in decoded(f)]
    annotated = decoded(replayed.annotated)
    assert [m[:5] for m in annotated if not m[0].startswith("/replay/")] == original
    counts = {t: sum(m[0] == t for m in annotated) for t in OUT_NAMES}
    assert set(counts.values()) == {replayed.predictions}

    def channels(path):
        with open(path, "rb") as f:
            s = make_reader(f).get_summary()
        return {
            c.topic: (
                c.message_encoding,
                dict(c.metadata),
                s.schemas[c.schema_id].name,
                s.schemas[c.schema_id].encoding,
                s.schemas[c.schema_id].data,
            )
            for c in s.channels.values()
        }

    before = channels(next(bag.glob("*.mcap")))
    after = channels(replayed.annotated)
    assert {t: after[t] for t in before} == before
    assert after["/replay/squeak/modes"][2:4] == ("std_msgs/msg/Float64MultiArray", "ros2msg")


def test_annotated_log_reads_with_rosbags(replayed):
    counts = {}
    with Reader(replayed.annotated) as reader:
        for conn, _, raw in reader.messages():
            TYPESTORE.deserialize_cdr(raw, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    assert counts["/replay/squeak/risk"] == replayed.predictions
    assert counts["/joint_states"] == CYCLE.samples


def test_split_directory_is_read_in_order(tmp_path, replayed):
    bag = write_log(CYCLE, tmp_path / "split", split_duration_s=2.5)
    files = list(bag.glob("*.mcap"))
    assert len(files) == 12  # `_10` sorts before `_2` by name: ordered by index
    r = run_replay(bag, tmp_path / "out", joint_name=CYCLE.joint_name)
    assert r.files == sorted(files, key=lambda p: int(p.stem.rsplit("_", 1)[1]))
    assert (r.messages, r.predictions, r.recomputes) == (
        replayed.messages,
        replayed.predictions,
        replayed.recomputes,
    )
    assert [e.as_dict() for e in r.episodes] == [e.as_dict() for e in replayed.episodes]


def test_prediction_workers_give_the_same_log(tmp_path, bag):
    """Long logs solve in spawned worker processes: same predictions as in-process."""
    a = run_replay(bag, tmp_path / "a", workers=0, joint_name=CYCLE.joint_name, **EXACT)
    b = run_replay(bag, tmp_path / "b", workers=2, joint_name=CYCLE.joint_name, **EXACT)
    assert a.predictions > 4 * 256  # several batches: the pool starts
    assert plain(decoded(a.annotated)) == plain(decoded(b.annotated))


# In a fresh interpreter: a worker's start, then a 20 MB array filled, freed and filled again.
_WORKER_HEAP = """
import resource, signal, sys
import numpy as np
if sys.argv[1] == "1":
    from leadscrew_ros.review.worker import start
    start()
np.ones(20 << 17)  # 20 MB: mapped on its own by glibc's first threshold, freed at once
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
np.ones(20 << 17)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before,
      signal.getsignal(signal.SIGINT) is signal.SIG_IGN)
"""


@pytest.mark.parametrize("started", [False, True])
def test_a_worker_keeps_the_memory_its_batches_free(started):
    """A prediction worker (`worker.start`) ignores Ctrl-C and takes a batch's arrays from
    the memory earlier batches freed: a freed 20 MB array comes back without a page fault per
    page (5120 pages); a plain interpreter faults on every page again. numpy's transparent
    huge pages are off in both (NUMPY_MADVISE_HUGEPAGE=0): where the kernel grants them, a
    plain interpreter took 11-508 faults (2-MB pages), which says nothing of the allocator."""
    import os
    import subprocess

    done = subprocess.run(
        [sys.executable, "-c", _WORKER_HEAP, str(int(started))],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "NUMPY_MADVISE_HUGEPAGE": "0"},
    )
    faults, ignores_sigint = done.stdout.split()
    assert ignores_sigint == str(started)
    assert (int(faults) < 500) is started, faults


# In a fresh interpreter, as a prediction worker: the pool's initializer and a task from stdin.
_WORKER_IMPORTS = """
import pickle, sys
start, initargs, solve, args = pickle.load(sys.stdin.buffer)
start(*initargs)
verdicts, _ = solve(*args)
assert all(v.valid and v.probability is not None for v in verdicts), verdicts
print(" ".join(sorted(sys.modules)))
"""


def test_a_prediction_worker_imports_what_it_solves_with_only():
    """A worker loads the timeline and its batch solve, given the replaying process's scatter
    samples: not the fleet, the plots, the acoustics, nor scipy.stats to draw the samples again
    (~0.7 s of every worker's start)."""
    import pickle
    import subprocess

    from leadscrew_ros.review import replay, worker
    from leadscrew_ros.review.timeline import ModelSpec, _spec_model

    spec = ModelSpec.of(SqueakModel())
    task = (
        worker.start,
        (spec, _spec_model(spec).samples),
        replay.solve,
        (spec, np.array([20.0, 30.0]), np.array([200.0, 150.0]), np.array([0.05, 0.06])),
    )
    done = subprocess.run(
        [sys.executable, "-c", _WORKER_IMPORTS],
        input=pickle.dumps(task),
        capture_output=True,
        check=True,
    )
    loaded = set(done.stdout.decode().split())
    assert "leadscrew_ros.review.timeline" in loaded
    heavy = {
        "scipy.stats",
        "scipy.signal",
        "matplotlib",
        "leadscrew_ros.model.acoustics",
        "leadscrew_ros.live.listen",
        "leadscrew_ros.review.fleet",
        "leadscrew_ros.review.listen",
        "leadscrew_ros.review.plots",
    }
    assert not heavy & loaded


def test_a_dead_worker_is_replaced_by_solving_here():
    from concurrent.futures import Future
    from concurrent.futures.process import BrokenProcessPool

    from leadscrew_ros.bag.messages import prediction_payloads
    from leadscrew_ros.review.replay import Verdict, _Segment
    from leadscrew_ros.review.timeline import ModelSpec, predict_jobs

    args = (
        ModelSpec.of(SqueakModel()),
        np.array([20.0]),
        np.array([200.0]),
        np.array([PARAMS.nut_position_m]),
    )
    future = Future()
    future.set_exception(BrokenProcessPool("killed"))
    (v,), (payloads,) = _Segment(solved=future, args=args).result()
    p = predict_jobs(*args)[0]
    assert p == SqueakModel().predict(20.0, 200.0) and not p.stable
    assert (
        v == Verdict.of(p)
        and v.squeak
        == tuple((m.label, m.frequency_hz, m.growth_rate) for m in p.squeak_modes)
        != ()
    )
    assert payloads == tuple(data for _, data in prediction_payloads(p))


def test_output_directory_must_not_be_the_log_directory(bag, capsys):
    code, _, err = cli(capsys, "replay", bag, "--out", bag, "--quiet")
    assert code == 2 and "must not be the log directory" in err
    assert not list(bag.glob("*annotated*"))


def test_report_pngs(replayed, tmp_path):
    paths = write_report(replayed, SqueakModel(), tmp_path, QUICK)
    assert [p.name for p in paths] == [
        "timeline.png",
        "map_speed_load.png",
        "frequency_vs_speed.png",
    ]
    for p in paths:
        assert p.read_bytes().startswith(b"\x89PNG") and p.stat().st_size > 5000


# ----------------------------------------------------------------------------- rosbags writer
def test_replay_of_a_rosbags_log_with_joint_states_only(tmp_path):
    log = rosbags_log(tmp_path / "rosbags_bag", ["wheel", "screw"])
    r = run_replay(log, tmp_path / "out", joint_name="screw", **EXACT)
    assert dict(r.inputs) == {"/joint_states": 120, "/axial_load": 120}
    seen = check_against_core(r.annotated, joint="screw")
    assert r.predictions == sum(p.valid for _, p in seen) > 50
    assert r.episodes


def test_joint_states_with_several_joints_need_a_joint_name(tmp_path, capsys):
    log = rosbags_log(tmp_path / "rosbags_bag", ["wheel", "screw"], samples=10)
    code, out, err = cli(capsys, "replay", log, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and out == "" and len(err.splitlines()) == 1
    assert "no speed" in err and "--joint-name" in err and "/joint_states" in err
    assert not list((tmp_path / "out").glob("*.mcap*"))  # no half-written output


def test_joint_states_without_a_joint_name_are_ignored(tmp_path, capsys):
    """joint_name '' ignores joint_states, as the node does, even with a single joint; the
    error and the summary say how to use them."""
    log = rosbags_log(tmp_path / "rosbags_bag", ["screw"], samples=40)
    code, out, err = cli(capsys, "replay", log, "--out", tmp_path / "x", "--quiet")
    assert code == 2 and len(err.splitlines()) == 1
    assert "40 x /joint_states: joint_name not set; use --joint-name (joints screw)" in err
    r = run_replay(
        log,
        tmp_path / "load",
        load_topic="/unused",
        nominal_load_n=200.0,
        speed_topic="/axial_load",
    )  # a speed from elsewhere: a summary
    assert dict(r.ignored) == {"/joint_states: joint_name not set; use --joint-name": 40}
    text = (tmp_path / "load" / "summary.txt").read_text()
    assert (
        "ignored inputs: 40 x /joint_states: joint_name not set; use --joint-name "
        "(first: joints screw)"
    ) in text
    r = run_replay(log, tmp_path / "out", joint_name="screw", **EXACT)
    assert r.predictions > 0 and not r.ignored
    check_against_core(r.annotated, joint="screw")


# ----------------------------------------------------------------------------- bad values
def test_invalid_inputs_are_counted_never_predicted(tmp_path):
    s = 1_000_000_000
    log = write_mcap(
        tmp_path / "bad.mcap",
        [
            f64("/motor_speed", math.nan, 1 * s),
            f64("/axial_load", 200.0, 2 * s),
            f64("/motor_speed", 20.0, 3 * s),  # the one valid prediction
            f64("/axial_load", math.inf, 4 * s),
            f64("/axial_load", 2e7, 5 * s),
            f64("/nut_position", 5.0, 6 * s),
            ("/motor_speed", "std_msgs/msg/Float64", b"\x00\x01\x00\x00\x01", 7 * s),
            f64("/motor_speed", 0.1, 8 * s),
            f64("/motor_speed", 2000.0, 9 * s),
        ],
    )
    r = run_replay(log, tmp_path / "out")
    assert r.predictions == 1 and r.recomputes == 3
    assert dict(r.rejected) == {
        "speed not finite": 1,
        "load not finite": 1,
        "load beyond 1e+07 N": 1,
        "nut position off the screw [0, 0.24] m": 1,
        "/motor_speed: undecodable payload": 1,
    }
    assert dict(r.no_prediction) == {
        "speed below min_speed_rad_s": 1,
        "speed at or above the first critical speed": 1,
    }
    (p,) = decoded(r.annotated, topics=["/replay/squeak/risk"])
    assert p[1] == 3 * s and math.isfinite(p[5].data)
    t, lo, _, _, count = r.plot_data.probability.series()  # seconds from the first message
    (k,) = np.flatnonzero(np.isfinite(lo[:, 0]))
    assert abs(t[k] - 2.0) <= r.plot_data.probability.bin_s and count.sum() == r.recomputes


def test_wrong_input_type_is_a_one_line_error(tmp_path, capsys):
    string = "std_msgs/msg/String"
    text = TYPESTORE.serialize_cdr(TYPESTORE.types[string]("1.0"), string)
    log = write_mcap(
        tmp_path / "typed.mcap",
        [("/motor_speed", string, bytes(text), 1), f64("/axial_load", 1.0, 2)],
    )
    code, _, err = cli(capsys, "replay", log, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and len(err.splitlines()) == 1
    assert (
        f"{log}: --speed-field data: {string}: data is a string, not a number "
        "(topic /motor_speed)" in err
    )


# ----------------------------------------------------------------------------- command line
def test_cli_replay_with_report(bag, tmp_path, capsys):
    code, out, err = cli(
        capsys,
        "replay",
        bag,
        "--out",
        tmp_path,
        "--speed-deadband",
        "0.5",
        "--out-namespace",
        "/offline",
    )
    assert code == 0, err
    assert "squeak episodes:" in out and "x real time" in out and "wrote:" in out
    assert not re.search(r"\(0x real time\)", out)
    names = {p.name for p in tmp_path.iterdir()}
    assert {
        f"{bag.name}.annotated.mcap",
        "episodes.json",
        "summary.json",
        "summary.txt",
        "timeline.png",
        "map_speed_load.png",
        "frequency_vs_speed.png",
    } <= names
    topics = {m[0] for m in decoded(tmp_path / f"{bag.name}.annotated.mcap")}
    assert "/offline/squeak/active" in topics and "/replay/squeak/active" not in topics


def test_cli_replay_takes_node_parameters_from_the_params_file(short_log, tmp_path, capsys):
    params = tmp_path / "p.yaml"
    params.write_text(
        "squeak_predictor:\n  ros__parameters:\n    speed_deadband_rad_s: 0.0\n"
        "    load_deadband_n: 0.0\n    nut_deadband_m: 0.0\n"
        "    record: {enabled: false}\n"
    )
    code, _, err = cli(
        capsys,
        "replay",
        short_log,
        "--out",
        tmp_path / "a",
        "--no-report",
        "--quiet",
        "--params-file",
        params,
    )
    assert code == 0, err
    exact = json.loads((tmp_path / "a" / "summary.json").read_text())
    code, _, err = cli(
        capsys,
        "replay",
        short_log,
        "--out",
        tmp_path / "b",
        "--no-report",
        "--quiet",
        "--params-file",
        params,
        "--speed-deadband",
        "5",
    )
    coarse = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert code == 0 and coarse["recomputes"] < exact["recomputes"]


@pytest.mark.parametrize(
    "make, problem",
    [
        (lambda d: d / "missing.mcap", "no such file or directory"),
        (
            lambda d: (d / "empty_dir").mkdir() or d / "empty_dir",
            "directory holds no .mcap or .db3 files",
        ),
        (lambda d: d / "image.png", "not an MCAP file (bad magic)"),
        (lambda d: d / "notes.txt", "not an MCAP file (bad magic)"),
        (
            lambda d: write_mcap(d / "plain.mcap", [f64("/motor_speed", 1.0, 1)], profile=""),
            "foreign MCAP: profile ''",
        ),
        (
            lambda d: write_mcap(
                d / "json.mcap", [f64("/motor_speed", 1.0, 1)], encodings=("json", "jsonschema")
            ),
            "foreign MCAP: topic /motor_speed",
        ),
        (lambda d: d / "empty.mcap", "not an MCAP file (bad magic)|empty file"),
    ],
)
def test_cli_bad_logs_are_one_line_errors(tmp_path, capsys, make, problem):
    (tmp_path / "image.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    (tmp_path / "notes.txt").write_text("speed,load\n1,2\n")
    (tmp_path / "empty.mcap").write_bytes(b"")
    log = make(tmp_path)
    for command in (["replay", log, "--out", tmp_path / "out", "--quiet"], ["info", log]):
        code, out, err = cli(capsys, *command)
        assert code == 2 and out == ""
        assert err.count("\n") == 1 and err.startswith("leadscrew-squeak: error: ")
        assert re.search(problem.replace("(", r"\(").replace(")", r"\)"), err)
        assert str(log) in err
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())


def test_cli_truncated_log_then_recover_then_replay(short_log, tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    data = short_log.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.7)])
    code, _, err = cli(capsys, "replay", cut, "--out", tmp_path / "out", "--quiet")
    assert code == 2 and err.count("\n") == 1
    assert "truncated" in err and f"leadscrew-squeak recover {cut}" in err

    code, out, err = cli(capsys, "info", cut)
    assert code == 0 and "TRUNCATED" in out and "recover" in out

    recovered = tmp_path / "elsewhere.mcap"
    code, out, err = cli(capsys, "recover", cut, "-o", recovered)
    assert code == 0, err
    assert out.startswith("recovered ") and str(recovered) in out
    assert "damage: " in out and "/joint_states" in out and "time span: " in out
    n = int(out.split()[1])
    assert 0 < n < 3 * SHORT.samples

    code, out, err = cli(capsys, "info", recovered)
    assert code == 0 and ": complete" in out.splitlines()[0]
    code, out, err = cli(
        capsys, "replay", recovered, "--out", tmp_path / "out", "--quiet", "--no-report"
    )
    assert code == 0 and err == ""
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["messages"] == n

    code, out, err = cli(capsys, "recover", cut)  # default: in place
    assert code == 0 and f"{cut}: recovered {n} messages" in out
    assert cli(capsys, "info", cut)[1].splitlines()[0] == f"{cut}: complete"


def test_cli_info(bag, capsys):
    code, out, err = cli(capsys, "info", bag)
    assert code == 0 and err == ""
    assert ": complete" in out and "/joint_states" in out and "sensor_msgs/msg/JointState" in out
    code, out, _ = cli(capsys, "info", bag, "--json")
    (info,) = json.loads(out)
    assert info["complete"] and info["messages"] == 3 * CYCLE.samples
    assert {t["name"]: t["count"] for t in info["topics"]}["/axial_load"] == CYCLE.samples


@pytest.mark.parametrize(
    "argv, problem",
    [
        (["--rate", "2"], "--rate needs --publish"),
        (["--loop"], "--loop needs --publish"),
        (["--publish", "--out", "x"], "--out is for the offline replay, not --publish"),
        (["--publish", "--load", "200"], "--load is for the offline replay, not --publish"),
        (["--publish", "--namespace", "/a"], "--namespace is for the offline replay"),
        (["--publish", "--out-namespace", "/a"], "--out-namespace is for the offline replay"),
        (["--publish", "--remap", "speed"], "expected OLD:=NEW"),
        (
            ["--speed-deadband", "-1"],
            "speed_deadband_rad_s = -1 is out of range, allowed [0, 1000]",
        ),
        (["--speed-deadband", "1001"], "speed_deadband_rad_s = 1001 is out of range"),  # the node's
        (["--nut-position-at-zero-angle", "-101"], "nut_position_at_zero_angle_m = -101 is out"),
        (["--namespace", "/bad name"], "namespace must be a ROS name"),
        (["--out-namespace", "/bad name"], "output namespace must be a ROS name"),
        (["--load", "1e8"], "nominal load = 1e+08 N exceeds the plausible magnitude 1e+07 N"),
        (["--workers", "-1"], "workers must be in [0, 64], got -1"),
        (["--workers", "100000"], "workers must be in [0, 64], got 100000"),
        (["--load-topic", "motor_speed"], "input topics must be distinct"),
        (["--speed-deadband", "nan"], "is not a finite number"),
    ],
)
def test_cli_replay_bad_options(bag, tmp_path, capsys, argv, problem):
    code, out, err = cli(capsys, "replay", bag, "--quiet", *argv)
    assert code == 2 and out == "" and err.count("\n") == 1 and problem in err


def test_cli_publish_calls_publish_log(bag, monkeypatch, capsys):
    calls = []
    fake = types.ModuleType("leadscrew_ros.ros.replay_live")
    fake.publish_log = lambda paths, **kwargs: calls.append((paths, kwargs)) or 7
    fake.WAIT_FOR_SUBSCRIBER_S = 5.0
    monkeypatch.setitem(sys.modules, "leadscrew_ros.ros.replay_live", fake)
    code, _, err = cli(
        capsys,
        "replay",
        bag,
        "--publish",
        "--rate",
        "4",
        "--loop",
        "--start-offset",
        "1.5",
        "--topics",
        "motor_speed",
        "/axial_load",
        "--remap",
        "motor_speed:=/seat/motor_speed",
        "--no-wait",
        "--quiet",
    )
    assert code == 0, err
    ((paths, kwargs),) = calls
    assert paths == sorted(bag.glob("*.mcap"))
    assert kwargs == dict(
        rate=4.0,
        loop=True,
        start_offset_s=1.5,
        topics=["/motor_speed", "/axial_load"],
        remap={"/motor_speed": "/seat/motor_speed"},
        progress=False,
        wait_for_subscriber_s=0.0,
        ros_args=[],
    )
    calls.clear()
    assert cli(capsys, "replay", bag, "--publish")[0] == 0
    assert calls[0][1] == dict(
        rate=1.0,
        loop=False,
        start_offset_s=0.0,
        topics=None,
        remap={},
        progress=True,
        wait_for_subscriber_s=5.0,
        ros_args=[],
    )
    calls.clear()
    assert cli(capsys, "replay", bag, "--publish", "--ros-args", "-r", "__ns:=/seat")[0] == 0
    assert calls[0][1]["ros_args"] == ["--ros-args", "-r", "__ns:=/seat"]

    def refuse(paths, **kwargs):
        raise ValueError("rate must be a finite number > 0")

    fake.publish_log = refuse
    code, _, err = cli(capsys, "replay", bag, "--publish", "--rate", "0")
    assert code == 2 and err == "leadscrew-squeak: error: rate must be a finite number > 0\n"


def test_default_output_directory(short_log, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    shutil.copy(short_log, tmp_path / "run.mcap")
    code, _, err = cli(capsys, "replay", "run.mcap", "--no-report", "--quiet")
    assert code == 0, err
    assert (tmp_path / "run_replay" / "run.annotated.mcap").is_file()


@pytest.mark.parametrize(
    "ratio,text", [(12.0 / 61.11, "0.20x"), (0.004, "0.0040x"), (3.46, "3.5x"), (154.2, "154x")]
)
def test_a_slower_than_real_time_replay_says_so(ratio, text):
    """A 12 s log replayed in 61 s printed '(0x real time)'."""
    assert ratio_text(ratio) == text
