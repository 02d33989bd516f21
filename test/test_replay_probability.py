# SPDX-License-Identifier: Apache-2.0
"""P(squeak) in the offline replay (issue 10): squeak/risk and squeak/margin in the annotated
MCAP, peak probability and time at or above the WARN / ERROR probabilities in episodes.json and
the summary, the model's scatter, and the P(squeak) panel of the report.

The log dwells at known operating points (Table 1, 200 N, paper formulation): 60 rad/s (stable
at the nominal parameters, P ~ 0.12), 55 rad/s (nominally squeaking by a hair, P ~ 0.46),
20 rad/s (P ~ 1), 70 rad/s (P = 0), with speed noise inside the deadband, so that each dwell is
one recompute whose P holds until the next. The expected numbers are computed here from the
dwells and `SqueakModel.predict`, and the annotated file is read back with mcap_ros2 and
rosbags.
"""

import json
import math
import pickle
from pathlib import Path

import numpy as np
import pytest
from matplotlib.lines import Line2D
from rosbags.rosbag2 import Reader

from harness.logs import TYPESTORE, cli, decoded, f64, write_mcap
from leadscrew_ros.bag.messages import MARGIN, PREDICTION_TOPICS, RISK
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.model.uncertainty.scatter import Scatter
from leadscrew_ros.review import report
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.timeline import InputSettings, ModelSpec, predict_jobs

T0 = 1_700_000_000_000_000_000
STEP_NS = 100_000_000  # a speed sample every 0.1 s
LOAD_N = 200.0
# (speed [rad/s], samples): at rest, then the dwells, then at rest again
DWELLS = ((0.0, 5), (60.0, 15), (55.0, 20), (20.0, 10), (70.0, 15), (55.0, 10), (0.0, 6))
NOISE_RAD_S = 0.02  # well inside the default speed deadband (0.1 rad/s)


def dwell_log(path: Path) -> tuple[Path, list[tuple[float, float]]]:
    """The log, and (start [s from the first message], speed) of each dwell: its first sample,
    the one that recomputes."""
    rng = np.random.default_rng(3)
    messages, starts, k = [f64("/axial_load", LOAD_N, T0)], [], 0
    for speed, n in DWELLS:
        for j in range(n):
            value = speed + (rng.uniform(-NOISE_RAD_S, NOISE_RAD_S) if speed else 0.0)
            if j == 0:
                starts.append((k * STEP_NS / 1e9, value))
            messages.append(f64("/motor_speed", value, T0 + k * STEP_NS))
            k += 1
    return write_mcap(path, messages), starts


def expected(starts, model, end_s, warn, error):
    """P(squeak) as published, from the dwells: each dwell's P (None at rest) holds to the
    next dwell; episodes are the runs of nominally squeaking dwells."""
    dwells = []
    for (t, speed), nxt in zip(starts, [s[0] for s in starts[1:]] + [end_s], strict=True):
        p = model.predict(speed, LOAD_N)
        dwells.append((t, nxt - t, p.probability if p.valid else None, p.valid and not p.stable))

    def stats(ds):
        valid = [d for d in ds if d[2] is not None]
        peak = max((d[2] for d in valid), default=None)
        return {
            "peak_probability": peak,
            "peak_probability_t_s": next((d[0] for d in valid if d[2] == peak), None),
            "time_above_warn_s": sum(d[1] for d in valid if d[2] >= warn),
            "time_above_error_s": sum(d[1] for d in valid if d[2] >= error),
        }

    episodes, run = [], []
    for d in dwells + [(end_s, 0.0, None, False)]:
        if d[3]:
            run.append(d)
        elif run:
            episodes.append({"start_s": run[0][0], "end_s": d[0], **stats(run)})
            run = []
    return stats(dwells), episodes, dwells


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    return dwell_log(tmp_path_factory.mktemp("dwell") / "dwell.mcap")


def run(log_path, out, model=None, **inputs):
    return replay(
        log_path,
        model or SqueakModel(),
        out,
        ReplaySettings(InputSettings(**inputs), workers=0, progress=False),
    )


def approx(d):
    return {k: v if v is None else pytest.approx(v, abs=1e-9) for k, v in d.items()}


@pytest.mark.parametrize("warn, error", [(0.1, 0.5), (0.05, 0.9), (0.5, 0.5)])
def test_peak_and_time_above_warn_match_the_dwells(log, tmp_path, warn, error):
    path, starts = log
    model = SqueakModel()
    r = run(path, tmp_path, warn_probability=warn, error_probability=error)
    overall, episodes, dwells = expected(starts, model, r.duration_s, warn, error)
    p = {round(abs(speed)): q for (_, speed), (_, _, q, _) in zip(starts, dwells, strict=True)}
    # the dwells are where the issue says: P ~ 0.12, ~ 0.46 (nominally squeaking), ~ 1, 0
    assert 0.05 < p[60] < 0.2 and 0.3 < p[55] < 0.5 and p[20] > 0.95 and p[70] == 0.0
    assert p[0] is None and [d[3] for d in dwells] == [False, False, True, True, False, True, False]
    assert r.recomputes == len(DWELLS) and r.predictions == len(DWELLS) - 2
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert {k: summary[k] for k in overall} == approx(overall)
    assert (summary["warn_probability"], summary["error_probability"]) == (warn, error)
    assert summary["warn_share"] == pytest.approx(overall["time_above_warn_s"] / r.duration_s)
    got = json.loads((tmp_path / "episodes.json").read_text())
    assert len(got) == len(episodes) == 2
    for g, e in zip(got, episodes, strict=True):
        assert {k: g[k] for k in e} == approx(e)
        assert g["time_above_warn_s"] <= g["duration_s"] + 1e-12
    if (warn, error) == (0.1, 0.5):  # the numbers behind the assertions, spelled out
        assert overall["time_above_warn_s"] == pytest.approx(1.5 + 2.0 + 1.0 + 1.0)
        assert overall["time_above_error_s"] == pytest.approx(1.0)  # the 20 rad/s dwell
        assert overall["peak_probability_t_s"] == pytest.approx(4.0)  # 20 rad/s
    text = (tmp_path / "summary.txt").read_text()
    assert (
        f"P(squeak): peak {overall['peak_probability']:.3f} at "
        f"{overall['peak_probability_t_s']:.2f} s; >= WARN {warn:g} for "
        f"{overall['time_above_warn_s']:.2f} s"
    ) in text
    assert (
        "scatter: friction_decay_s_m 0.1, modal_damping 0.35, mu_kinetic 0.05, "
        "mu_static 0.05 (relative SD; SD of ln for modal_damping), 1024 samples"
    ) in text


def test_annotated_mcap_carries_the_probability_and_the_margin(log, tmp_path):
    path, starts = log
    model = SqueakModel()
    r = run(path, tmp_path)
    valid = [model.predict(speed, LOAD_N) for _, speed in starts]
    valid = [p for p in valid if p.valid]
    # mcap_ros2: every prediction topic, at the log time of its dwell's first sample
    names = [f"/replay/{t}" for t in PREDICTION_TOPICS]
    out = [m for m in decoded(r.annotated) if m[0].startswith("/replay/")]
    assert [m[0] for m in out] == names * len(valid)
    risk = [m[5].data for m in out if m[0] == f"/replay/{RISK}"]
    margin = [m[5].data for m in out if m[0] == f"/replay/{MARGIN}"]
    assert risk == [p.probability for p in valid]  # exactly
    assert margin == pytest.approx([p.margin for p in valid], rel=1e-12, abs=1e-15)
    assert [m < 0 for m in margin] == [not p.stable for p in valid]
    # rosbags reads the same values, with the node's types
    got = {}
    with Reader(r.annotated) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, _, raw in reader.messages():
            if conn.topic.startswith("/replay/"):
                got.setdefault(conn.topic, []).append(TYPESTORE.deserialize_cdr(raw, conn.msgtype))
    assert types[f"/replay/{RISK}"] == types[f"/replay/{MARGIN}"] == "std_msgs/msg/Float64"
    assert [m.data for m in got[f"/replay/{RISK}"]] == risk
    assert [m.data for m in got[f"/replay/{MARGIN}"]] == margin


def test_the_replay_predicts_with_the_models_scatter(log, tmp_path):
    path, starts = log
    for scatter, samples in ((Scatter({"mu_kinetic": 0.1}), 64), (Scatter({}), 1024)):
        model = SqueakModel(scatter=scatter, samples=samples)
        r = run(path, tmp_path / str(samples), model)
        risk = [m[5].data for m in decoded(r.annotated, topics=[f"/replay/{RISK}"])]
        want = [p.probability for p in (model.predict(s, LOAD_N) for _, s in starts) if p.valid]
        assert risk == want and risk != [
            p.probability for p in (SqueakModel().predict(s, LOAD_N) for _, s in starts) if p.valid
        ]
        summary = json.loads((tmp_path / str(samples) / "summary.json").read_text())
        assert summary["scatter"] == dict(scatter.sd)
        assert summary["scatter_samples"] == samples
    assert set(risk) == {0.0, 1.0}  # no scatter: the nominal verdict
    assert (
        "scatter: mu_kinetic 0.1 (relative SD), 64 samples"
        in (tmp_path / "64" / "summary.txt").read_text()
    )
    assert "scatter: none" in (tmp_path / "1024" / "summary.txt").read_text()


def test_worker_processes_get_the_scatter():
    """A worker rebuilds the model from a pickled ModelSpec (a Scatter holds a mapping proxy,
    which does not pickle): the same predictions as the model itself."""
    model = SqueakModel(scatter=Scatter({"mu_static": 0.08, "modal_damping": 0.2}), samples=128)
    spec = pickle.loads(pickle.dumps(ModelSpec.of(model)))
    speeds, loads = np.array([20.0, 55.0, 0.1, 60.0]), np.full(4, LOAD_N)
    nuts = np.full(4, model.params.nut_position_m)
    assert predict_jobs(spec, speeds, loads, nuts) == model.predict_many(speeds, loads)


def test_cli_threshold_options_and_episode_lines(log, tmp_path, capsys):
    path, _ = log
    code, out, err = cli(
        capsys,
        "replay",
        path,
        "--out",
        tmp_path,
        "--no-report",
        "--warn-probability",
        "0.2",
        "--error-probability",
        "0.4",
    )
    assert code == 0, err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert (summary["warn_probability"], summary["error_probability"]) == (0.2, 0.4)
    assert ">= WARN 0.2 for " in out and ">= ERROR 0.4 for " in out
    lines = [line for line in out.splitlines() if line.startswith("  squeak ")]
    assert len(lines) == 2 and all("peak P(squeak) 0." in line for line in lines)
    params = tmp_path / "p.yaml"
    params.write_text("squeak_predictor:\n  ros__parameters:\n    warn_probability: 0.3\n")
    code, _, err = cli(
        capsys,
        "replay",
        path,
        "--out",
        tmp_path / "b",
        "--no-report",
        "--quiet",
        "--params-file",
        params,
    )
    assert code == 0, err
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["warn_probability"] == 0.3


@pytest.mark.parametrize(
    "argv, problem",
    [
        (["--warn-probability", "1.5"], "warn_probability = 1.5 is out of range, allowed [0, 1]"),
        (["--warn-probability", "0.6"], "warn_probability = 0.6 exceeds error_probability = 0.5"),
        (["--error-probability", "nan"], "is not a finite number"),
        (["--publish", "--warn-probability", "0.2"], "--warn-probability is for the offline"),
    ],
)
def test_cli_bad_thresholds_are_one_line_errors(log, tmp_path, capsys, argv, problem):
    out_dir = [] if "--publish" in argv else ["--out", tmp_path]
    code, out, err = cli(capsys, "replay", log[0], *out_dir, "--quiet", *argv)
    assert code == 2 and out == "" and err.count("\n") == 1 and problem in err


def test_report_draws_p_squeak_with_the_thresholds(log, tmp_path):
    r = run(log[0], tmp_path, warn_probability=0.2, error_probability=0.7)
    paths = report.write_report(r, SqueakModel(), tmp_path, report.QUICK)
    assert paths[0].name == "timeline.png" and paths[0].read_bytes().startswith(b"\x89PNG")
    ax = r.plot().axes[-1]
    assert ax.get_ylabel() == "P(squeak) [-]"
    assert ax.get_title() == r.probability_text()
    assert ax.get_ylim()[0] == 0.0  # no P below 0 drawn (issue 32: the bars were below it)
    dashed = {
        line.get_label(): line.get_ydata()[0]
        for line in ax.get_lines()
        if line.get_linestyle() == "--"
    }
    assert dashed == {"WARN 0.2": 0.2, "ERROR 0.7": 0.7}
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == [
        "P(squeak)",
        "squeak (nominal)",
        "P >= WARN",
        "P >= ERROR",
        "WARN 0.2",
        "ERROR 0.7",
        "peak",
    ]
    # P(squeak) is a curve: a line in the legend, not a patch (issue 32)
    assert isinstance(ax.get_legend().legend_handles[0], Line2D)
    # the areas under the thresholds cover the time at or above WARN and ERROR (bin
    # resolution), from 0 up to their level

    for name, seconds in (
        ("WARN", r.probability.above_warn_s),
        ("ERROR", r.probability.above_error_s),
    ):
        bars = [p for p in ax.patches if p.get_label() == f"P >= {name}"]
        x = [p.get_patch_transform().transform(p.get_path().vertices)[:, 0] for p in bars]
        level = r.warn_probability if name == "WARN" else r.error_probability
        lo, hi = ax.get_ylim()
        for p in bars:  # a span's y is in axes fraction
            y = lo + (hi - lo) * p.get_patch_transform().transform(p.get_path().vertices)[:, 1]
            assert y.min() == pytest.approx(0.0, abs=1e-9)
            assert y.max() == pytest.approx(level, abs=1e-9)
        assert sum(v.max() - v.min() for v in x) == pytest.approx(
            seconds, abs=4 * r.plot_data.probability.bin_s
        )
    assert 0 < r.probability.above_error_s < r.probability.above_warn_s
    (peak,) = [line for line in ax.get_lines() if line.get_label() == "peak"]
    assert (peak.get_xdata()[0], peak.get_ydata()[0]) == (
        r.probability.peak_t_s,
        r.probability.peak,
    )
    assert math.isclose(r.probability.peak_t_s, 4.0)


def test_cli_scatter_options_reach_the_replay(log, tmp_path, capsys):
    """--scatter / --samples (and scatter.* of --params-file) build the replay's model as they
    build every model command's: the summary names that scatter and P follows it."""
    path, starts = log
    code, _, err = cli(
        capsys,
        "replay",
        path,
        "--out",
        tmp_path / "a",
        "--no-report",
        "--quiet",
        "--scatter",
        "none",
    )
    assert code == 0, err
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["scatter"] == {} and summary["peak_probability"] == 1.0
    risk = {
        m[5].data
        for m in decoded(tmp_path / "a" / "dwell.annotated.mcap", topics=[f"/replay/{RISK}"])
    }
    assert risk == {0.0, 1.0}
    code, _, err = cli(
        capsys,
        "replay",
        path,
        "--out",
        tmp_path / "b",
        "--no-report",
        "--quiet",
        "--scatter",
        "mu_kinetic=0.1",
        "--samples",
        "64",
    )
    assert code == 0, err
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summary["scatter"]["mu_kinetic"] == 0.1 and summary["scatter_samples"] == 64
    model = SqueakModel(scatter=Scatter(summary["scatter"]), samples=64)
    want = [p.probability for p in (model.predict(s, LOAD_N) for _, s in starts) if p.valid]
    assert [
        m[5].data
        for m in decoded(tmp_path / "b" / "dwell.annotated.mcap", topics=[f"/replay/{RISK}"])
    ] == want
