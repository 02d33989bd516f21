# SPDX-License-Identifier: Apache-2.0
"""`replay` of a log with the squeak guard's topics (speed_command, speed_command_guarded,
guard/active in the input namespace, as `ros.guard_node` publishes them): the summary and the
timeline picture show the raw and the guarded command; a log without them is replayed as
before."""

from __future__ import annotations

import json
import math

import numpy as np
from std_msgs.msg import Bool

from harness import pictures
from harness.cdr_reference import cdr_payload
from harness.logs import f64, run_replay, write_mcap
from leadscrew_ros.live.profile import StrokeProfile
from leadscrew_ros.review.commands import LABELS

NS = "/seat_left"
RATE_HZ = 50.0


def guard_log(path, with_commands=True, bad_payloads=0):
    """A 4 s stroke at 50 Hz: the inputs, and (`with_commands`) the raw command, a guarded
    command that holds 60 % of it while the raw one is in 5..30 rad/s, and guard/active."""
    profile = StrokeProfile(duration_s=4.0)
    times, speed, load, nut = profile.sampled(RATE_HZ)
    messages, raw, guarded = [], [], []
    for k, (t, w, f, z) in enumerate(zip(times, speed, load, nut, strict=True)):
        ns = 1_000_000_000 + int(round(t * 1e9))
        active = bool(5.0 <= w <= 30.0)
        g = 0.6 * w if active else w
        messages += [
            f64(f"{NS}/motor_speed", float(g), ns),
            f64(f"{NS}/axial_load", float(f), ns),
            f64(f"{NS}/nut_position", float(z), ns),
        ]
        if with_commands:
            messages += [
                f64(f"{NS}/speed_command", float(w), ns),
                f64(f"{NS}/speed_command_guarded", float(g), ns),
                (f"{NS}/guard/active", "std_msgs/msg/Bool", cdr_payload(Bool(data=active)), ns),
            ]
            if k < bad_payloads:
                messages.append((f"{NS}/speed_command", "std_msgs/msg/Float64", b"\x00\x01", ns))
            raw.append(w)
            guarded.append(g)
    write_mcap(path, messages)
    active_s = sum(1 / RATE_HZ for w in speed[:-1] if 5.0 <= w <= 30.0)
    return np.array(raw), np.array(guarded), active_s


def test_summary_and_picture_show_raw_and_guarded_command(tmp_path, monkeypatch):
    raw, guarded, active_s = guard_log(tmp_path / "log.mcap", bad_payloads=3)
    keep = pictures.SavedFigures().install(monkeypatch)
    r = run_replay(tmp_path / "log.mcap", tmp_path / "out")
    summary = r.summary()
    topics = summary["speed_commands"]["topics"]
    assert topics[f"{NS}/speed_command"]["messages"] == len(raw)
    assert topics[f"{NS}/speed_command"]["max_rad_s"] == max(raw)
    assert topics[f"{NS}/speed_command_guarded"]["messages"] == len(guarded)
    assert math.isclose(summary["speed_commands"]["guard_active_s"], active_s, rel_tol=0.05)
    assert summary["speed_commands"]["undecodable"] == {"speed_command": 3}
    text = r.summary_text()
    assert f"raw command ({NS}/speed_command): {len(raw)} messages" in text
    assert f"guarded command ({NS}/speed_command_guarded)" in text
    assert "guard active (changing the command)" in text and "not decodable" in text
    written = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert written["speed_commands"]["topics"][f"{NS}/speed_command"]["messages"] == len(raw)

    fig = r.plot()
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert LABELS["speed_command"] in labels and LABELS["speed_command_guarded"] in labels
    drawn = {line.get_label(): line.get_ydata() for line in fig.axes[0].get_lines()}
    # each command's line is its own values (the bins' last, held), not the motor's
    assert np.nanmax(drawn[LABELS["speed_command"]]) == max(raw)
    assert np.nanmax(drawn[LABELS["speed_command_guarded"]]) == max(guarded)
    gap = drawn[LABELS["speed_command"]] - drawn[LABELS["speed_command_guarded"]]
    assert 0.3 * 30.0 <= np.nanmax(gap) <= 0.4 * 30.0 + 1e-9  # where the guard held 60 %
    fig.savefig(tmp_path / "timeline.png", dpi=100)
    fig, dpi = keep.named("timeline.png")
    assert pictures.figure_problems(fig, dpi) == []


def test_a_log_without_the_guard_topics_has_none(tmp_path):
    guard_log(tmp_path / "log.mcap", with_commands=False)
    r = run_replay(tmp_path / "log.mcap", tmp_path / "out")
    assert r.commands is None and r.summary()["speed_commands"] is None
    assert "command" not in r.summary_text()
    labels = [line.get_label() for line in r.plot().axes[0].get_lines()]
    assert not set(labels) & set(LABELS.values())
