# SPDX-License-Identifier: Apache-2.0
"""Every PNG the commands write reads at a glance (issue 32): the real commands run in this
process on small inputs (a 3-unit virtual bench with sound, quick grids and sampler) with
`Figure.savefig` hooked to keep each figure, and each figure is checked at the dpi it was saved
with by `harness.pictures.figure_problems` (text of 8 pt or more on screen, every numeric axis
labelled with its [unit], every labelled series in a legend or a colourbar, no text outside the
figure or upside down). Then each rule is shown to fail on a figure made to break it."""

from __future__ import annotations

import numpy as np
import pytest

from harness import pictures
from harness.calibration import QUICK_SAMPLER, SMALL_BENCH
from leadscrew_ros.bag.virtual_bench import run
from leadscrew_ros.cli import main
from leadscrew_ros.cli.figures import FIGURE_FILES

pytestmark = pytest.mark.timeout(900)

REPLAY = ("timeline.png", "map_speed_load.png", "frequency_vs_speed.png")
PNGS = (
    *REPLAY,
    "fleet.png",
    "map.png",
    "sweep.png",
    "calibration.png",
    *FIGURE_FILES,
    "transient.png",
    "spectrogram.png",
)


def _recording(d):
    """A WAV and its speed CSV for `listen`: at rest 1 s, then a speed ramp with a drive tone
    at 100x the screw's rotation frequency, a fan all along, a squeak growing from 2.5 s."""
    from scipy.io import wavfile

    rate = 16000
    t = np.arange(5 * rate) / rate
    speed = np.where(t >= 1.0, 10.0 + 4.0 * (t - 1.0), 0.0)
    x = 0.005 * np.random.default_rng(2).standard_normal(t.size)
    x += 0.03 * np.sin(2 * np.pi * 1170.0 * t)
    x += 0.02 * (speed > 0) * np.sin(np.cumsum(100.0 * speed) / rate)
    x += np.clip(1e-3 * np.exp(5 * (t - 2.5)), 0, 0.1) * (t >= 2.5) * np.sin(2 * np.pi * 2200 * t)
    wavfile.write(d / "rec.wav", rate, x.astype(np.float32))
    rows = [f"{a:.3f},{v:.3f}" for a, v in zip(t[::160], speed[::160], strict=True)]
    (d / "speed.csv").write_text("time_s,speed_rad_s\n" + "\n".join(rows) + "\n")
    return d / "rec.wav", d / "speed.csv"


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """Every figure the commands save, run once: replay, review, map, sweep, calibrate,
    figures --quick and transient on the small bench, listen on a small recording."""
    mp = pytest.MonkeyPatch()
    keep = pictures.SavedFigures().install(mp)
    d = tmp_path_factory.mktemp("pictures")
    truth = run(SMALL_BENCH, d / "bench")
    logs = [d / "bench" / u["log"] for u in truth["units"]]
    (d / "broken.mcap").write_bytes(b"not a log")  # an error row in fleet.png
    wav, speed_csv = _recording(d)
    try:
        for argv in (
            ["replay", logs[0], "--out", d / "replay", "--quiet"],
            ["review", *logs, d / "broken.mcap", "--out", d / "review", "--workers", "1"]
            + ["--no-report", "--quiet"],
            ["map", "--x", "speed_rad_s:1:100:9", "--y", "load_n:5:600:7", "--probability"]
            + ["--plot", d / "map.png"],
            ["sweep", "--axis", "speed_rad_s", "--values", "1:100:30", "--probability"]
            + ["--plot", d / "sweep.png"],
            ["calibrate", d / "bench", "--out", d / "calibration", "--workers", "1", "--quiet"]
            + QUICK_SAMPLER,
            ["figures", "--quick", "--out", d / "figures"],
            ["transient", "--speed", "20", "--load", "200", "--duration", "0.02", "--modes", "6"]
            + ["--plot", d / "transient.png"],
            ["listen", wav, "--speed-csv", speed_csv, "--out", d / "listen"],
        ):
            main([str(a) for a in argv])
    finally:
        mp.undo()
    return keep


def test_every_png_of_the_commands_is_checked(saved):
    assert sorted(p.name for _, p, _ in saved.saved) == sorted(PNGS)


@pytest.mark.parametrize("name", PNGS)
def test_each_png_of_the_commands_reads_at_a_glance(saved, name):
    fig, dpi = saved.named(name)
    assert pictures.figure_problems(fig, dpi) == []


def test_figures_quick_is_legible_at_its_saved_size(saved):
    """The quick figures were 420 x 312 px with 10-pt text at 60 dpi (6 pt on screen)."""
    fig, dpi = saved.named("fig07_speed_load.png")
    width, height = fig.get_size_inches() * dpi
    assert width >= 600 and height >= 440, (width, height)


def test_the_replay_of_a_bench_log_has_its_sound_panel_with_stacked_colourbars(saved):
    """The bench log is heard: the timeline draws the spectrogram, its level's and P(squeak)'s
    colourbars one above the other (issue 32: side by side they crowded the panel), and no
    heard-episode mark confined to the bottom edge (it read as a 100 Hz tone)."""
    fig, dpi = saved.named("timeline.png")
    pictures.figure_problems(fig, dpi)  # drawn at the saved dpi: the extents below are of it
    (sound,) = [ax for ax in fig.axes if ax.get_yscale() == "log"]
    bars = [ax.get_window_extent() for ax in sound.child_axes]
    assert len(bars) == 2
    top, bottom = sorted(bars, key=lambda b: -b.y0)
    assert bottom.y1 < top.y0 and abs(top.x0 - bottom.x0) < 1.0, (top, bottom)
    edges = [p for p in sound.patches if p.get_label() == "heard episode: time"]
    assert edges and all(
        np.isclose(np.ptp(p.get_patch_transform().transform(p.get_path().vertices)[:, 1]), 1.0)
        for p in edges
    )  # each episode's time span over the whole height


# ----------------------------------------------------------------------------- each rule fails
def _bad(**kwargs):
    from leadscrew_ros.review.plots import new_figure

    fig = new_figure(figsize=(4, 3), layout="constrained")
    ax = fig.subplots()
    ax.plot([0, 1], [0, 1], label="_unlabelled")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("speed [rad/s]")
    return fig, ax


def test_a_readable_figure_has_no_problems():
    fig, _ = _bad()
    assert pictures.figure_problems(fig, 100) == []


@pytest.mark.parametrize(
    "spoil, problem",
    [
        (lambda fig, ax: ax.set_title("tiny", fontsize=6), "pt on screen"),
        (lambda fig, ax: ax.set_ylabel("speed"), "has no [unit]"),
        (lambda fig, ax: ax.twinx().plot([0, 1], [2, 3]), "has no [unit]"),
        (lambda fig, ax: ax.plot([0, 1], [1, 0], label="load"), "in no legend"),
        (lambda fig, ax: ax.scatter([0], [1], c=[1.0], label="points"), "in no legend"),
        (lambda fig, ax: fig.text(0.9, 0.5, "a long text leaving the figure"), "outside"),
        (lambda fig, ax: ax.text(0.5, 0.5, "90 %", rotation=200), "upside down"),
        (lambda fig, ax: ax.text(0.5, 0.5, "90 %", rotation=270), "upside down"),
    ],
)
def test_each_rule_fails_on_a_figure_that_breaks_it(spoil, problem):
    fig, ax = _bad()
    spoil(fig, ax)
    problems = pictures.figure_problems(fig, 100)
    assert len(problems) == 1 and problem in problems[0], problems


def test_the_size_rule_scales_with_the_saved_dpi():
    """10-pt text is 6.25 pt on screen at 60 dpi, 10.4 pt at 100 dpi."""
    fig, _ = _bad()
    assert any("pt on screen" in p for p in pictures.figure_problems(fig, 60))
    assert pictures.figure_problems(fig, 100) == []


def test_named_categories_and_colourbars_pass_and_a_colourbar_needs_its_unit():
    from leadscrew_ros.review.plots import new_figure

    fig = new_figure(figsize=(4, 3), layout="constrained")
    ax = fig.subplots()
    ax.barh(["unit a", "unit b"], [1.0, 2.0])
    ax.set_xlabel("time in squeak [s]")
    assert pictures.figure_problems(fig, 100) == []
    for label, problems in (("level [dB]", 0), ("level", 1)):
        fig, ax = _bad()
        mesh = ax.pcolormesh(np.zeros((2, 2)), label="level")
        fig.colorbar(mesh, ax=ax, label=label)
        found = pictures.figure_problems(fig, 100)
        assert len(found) == problems and all("has no [unit]" in p for p in found), found
