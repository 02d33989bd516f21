# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak guard`: the policy offline on the demo stroke (issue 33's target), on a
recorded log, its picture's legibility, and its one-line errors."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from harness import pictures
from harness.logs import cli, f64, write_mcap
from leadscrew_ros.live.guard import GuardSettings
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.review.guard import (
    OUT_COLUMNS,
    Command,
    GuardRun,
    read_profile,
    summary,
    write_profile,
)

pytestmark = pytest.mark.timeout(600)


def read_run(out, profile):
    data = np.genfromtxt(out / "guarded.csv", delimiter=",", names=True)
    return GuardRun(
        read_profile(profile, None, None),
        data["guarded_speed_rad_s"],
        data["p_squeak_raw"],
        data["p_squeak_guarded"],
        [],
        GuardSettings(),
    )


def test_demo_stroke_target_and_picture(tmp_path, capsys, monkeypatch):
    """The demo stroke (`leadscrew-squeak demo`'s): <= 0.3 s in squeak, <= 10 % longer stroke
    time for the same travel; guarded.csv has its columns; the picture reads at a glance."""
    profile = tmp_path / "demo.csv"
    write_profile(profile, Command.of_profile(StrokeProfile()))
    keep = pictures.SavedFigures().install(monkeypatch)
    code, out, err = cli(capsys, "guard", profile, "--out", tmp_path / "out")
    assert code == 0, err
    assert "time in squeak" in out and "guarded.png" in out
    with open(tmp_path / "out" / "guarded.csv") as f:
        assert tuple(next(csv.reader(f))) == OUT_COLUMNS
    raw, guarded, stroke = summary(read_run(tmp_path / "out", profile))
    assert raw.time_in_squeak_s > 4.0  # the stroke squeaks without the guard
    assert guarded.time_in_squeak_s <= 0.3
    assert stroke <= 1.10 * raw.motion_time_s
    fig, dpi = keep.named("guarded.png")
    assert pictures.figure_problems(fig, dpi) == []


def test_log_with_constant_load(tmp_path, capsys):
    """A recorded log's motor speed is the command; --load stands in for a missing load."""
    profile = StrokeProfile(duration_s=4.0, peak_speed_rad_s=60.0)
    t0 = 1_700_000_000_000_000_000
    messages = []
    for k in range(81):
        s = profile.state(k / 20)
        t = t0 + k * 50_000_000
        messages += [
            f64("/motor_speed", s.speed_rad_s, t),
            f64("/nut_position", s.nut_position_m, t),
        ]
    log = write_mcap(tmp_path / "stroke.mcap", messages)
    code, out, err = cli(capsys, "guard", log, "--out", tmp_path / "out", "--load", "200")
    assert code == 0, err
    data = np.genfromtxt(tmp_path / "out" / "guarded.csv", delimiter=",", names=True)
    assert np.all(data["load_n"] == 200.0)
    assert data["speed_rad_s"].max() == pytest.approx(60.0, rel=0.01)
    inside = (data["p_squeak_guarded"] >= 0.1).sum()
    assert inside < (data["p_squeak_raw"] >= 0.1).sum() / 5
    code, _, err = cli(capsys, "guard", log, "--out", tmp_path / "out2")
    assert code == 2 and "--load" in err


@pytest.mark.parametrize(
    ("text", "extra", "said"),
    [
        ("time_s,load_n\n0,1\n1,2\n", [], "no column speed_rad_s"),
        ("time_s,speed_rad_s\n0,1\n1,2\n", [], "give --load"),
        ("time_s,speed_rad_s\n0,1\n1,2\n", ["--load", "100"], "give --nut"),
        ("time_s,speed_rad_s\n0,1\n1,nan\n", ["--load", "1", "--nut", "0.1"], "not finite"),
        ("time_s,speed_rad_s\n1,1\n0,2\n", ["--load", "1", "--nut", "0.1"], "increase"),
        ("time_s,speed_rad_s\n0,1\n1,x\n", ["--load", "1", "--nut", "0.1"], "speed_rad_s"),
        ("time_s,speed_rad_s\n0,1\n", ["--load", "1", "--nut", "0.1"], "two rows"),
        ("", [], "empty"),
        ("time_s,speed_rad_s\n0,1\n1,2\n", ["--load", "1", "--nut", "0.5"], "leave the screw"),
        ("time_s,speed_rad_s\n0,1\n1,2\n", ["--load", "1e308", "--nut", "0.1"], "load"),
        ("time_s,speed_rad_s\n0,1\n1,2\n", ["--load", "1", "--nut", "nan"], "nan"),
        (
            "time_s,speed_rad_s\n0,1\n1,2\n",
            ["--load", "1", "--nut", "0.1", "--p-max", "0"],
            "p_max",
        ),
    ],
)
def test_bad_profiles_are_one_line_errors(tmp_path, capsys, text, extra, said):
    profile = tmp_path / "p.csv"
    profile.write_text(text)
    code, out, err = cli(capsys, "guard", profile, "--out", tmp_path / "out", *extra)
    assert code == 2 and out == ""
    assert err.startswith("leadscrew-squeak: error:") and err.count("\n") == 1 and said in err


def _guard_example():
    """tools/guard_example.py as a module: its strokes are the doc's."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "guard_example", Path(__file__).parents[1] / "tools" / "guard_example.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


EXAMPLE = _guard_example()
OTHER_STROKES = list(EXAMPLE.STROKES.items())[1:]  # the first is the demo stroke's


@pytest.mark.parametrize("name, changes", OTHER_STROKES, ids=[n for n, _ in OTHER_STROKES])
def test_target_on_three_other_strokes(tmp_path, name, changes):
    """Other loads and nut travel (tools/guard_example.py's strokes, the doc's table): the
    same target as on the demo stroke."""
    assert len(OTHER_STROKES) == 3
    run, _ = EXAMPLE.run_stroke(StrokeProfile(**changes), tmp_path)
    raw, guarded, stroke = summary(run)
    assert raw.time_in_squeak_s > 1.0  # the stroke squeaks without the guard
    assert guarded.time_in_squeak_s <= EXAMPLE.TARGET_SQUEAK_S
    assert stroke <= (1 + EXAMPLE.TARGET_LONGER) * raw.motion_time_s
