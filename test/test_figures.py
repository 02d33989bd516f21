# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak figures --quick` and the helpers that turn data into summary sentences."""

import re
import subprocess
import sys

import numpy as np
import pytest

from leadscrew_ros.cli import figures, main
from leadscrew_ros.cli.figures import (
    BOUNDARY,
    FIGURE_FILES,
    GRID,
    VALIDITY,
    Limit,
    describe_frequencies,
    describe_speed_map,
    line_bands,
    squeak_branches,
)
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.physics.friction import friction_coefficient, friction_slope
from leadscrew_ros.model.studies.stability_map import stability_map
from leadscrew_ros.model.studies.sweep import sweep
from leadscrew_ros.model.studies.tracking import track_modes
from leadscrew_ros.review.plots import plot_frequencies

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def quick_figures(tmp_path_factory):
    out = tmp_path_factory.mktemp("figs")
    return out, main(["figures", "--out", str(out), "--quick"])


def test_quick_figures_writes_nine_pngs(quick_figures):
    out, code = quick_figures
    assert code == 0
    assert len(FIGURE_FILES) == 9 and "fig07p_speed_load_probability.png" in FIGURE_FILES
    for name in FIGURE_FILES:
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000, name


def test_summary_describes_every_figure(quick_figures):
    out, _ = quick_figures
    lines = (out / "summary.txt").read_text().splitlines()
    assert "paper formulation" in lines[0]
    for name in FIGURE_FILES:
        line = next(line for line in lines if line.startswith(name + ": "))
        assert re.search(r"\d", line.split(": ", 1)[1]), line


def test_summary_numbers_come_from_the_model(quick_figures):
    text = (quick_figures[0] / "summary.txt").read_text()
    lo, hi = map(float, re.search(r"unstable band ([\d.]+)-([\d.]+) rad/s", text).groups())
    assert 0.5 < lo < 2 and 40 < hi < 70
    assert re.search(r"B1y 22\d Hz", text) and re.search(r"B2y 89\d Hz", text)
    # Fig. 6: the upper speed bound falls as R grows
    up = re.search(r"upper speed bound of squeak (\w+) from", text.split("fig06")[1])
    assert up.group(1) == "falls"


def test_fig04_steepest_slope_is_the_derivative_of_the_law_at_rest(quick_figures):
    """-(mu_s - mu_k) d = -0.500 s/m at Table 1, not a one-sided difference (-0.496)."""
    p = ScrewParameters()
    exact = -(p.mu_static - p.mu_kinetic) * p.friction_decay_s_m
    assert float(friction_slope(p, 0.0)) == pytest.approx(exact, rel=0, abs=1e-9)
    v, h = np.array([0.01, 0.05, 0.3]), 1e-6  # elsewhere: central differences
    fd = (friction_coefficient(p, v + h) - friction_coefficient(p, v - h)) / (2 * h)
    np.testing.assert_allclose(friction_slope(p, v), fd, rtol=1e-7)
    text = (quick_figures[0] / "summary.txt").read_text()
    assert f"steepest slope {exact:.3f} s/m at rest" in text and "-0.500 s/m" in text


def test_fig05_largest_growth_is_refined(quick_figures):
    """The speed sweep's peak is maximised between grid points (144.54 1/s at 4.357 rad/s at
    Table 1), not the best point of the 60-point quick grid."""
    text = (quick_figures[0] / "summary.txt").read_text()
    assert "largest growth 144.5 1/s at Omega = 4.36 rad/s (refined)" in text


def test_summary_is_printed(capsys, tmp_path):
    assert main(["figures", "--out", str(tmp_path), "--quick", "--formulation", "consistent"]) == 0
    out = capsys.readouterr().out
    assert out == (tmp_path / "summary.txt").read_text()
    assert "consistent formulation" in out.splitlines()[0]


def test_line_bands_tell_boundaries_from_validity_and_grid_edges():
    values = np.arange(8.0)
    growth = np.array([1.0, -1.0, 2.0, np.nan, -1.0, 3.0, -1.0, 4.0])
    limits = (Limit(0.0, "low"), Limit(np.inf, "high"))
    bands = line_bands(values, growth, [0.5, 1.5, 4.5, 5.5, 6.5], lambda: limits)
    assert [[(e.value, e.kind) for e in b] for b in bands] == [
        [(0.0, VALIDITY), (0.5, BOUNDARY)],  # grid start at the lower validity limit
        [(1.5, BOUNDARY), (2.0, VALIDITY)],  # the next point is invalid
        [(4.5, BOUNDARY), (5.5, BOUNDARY)],
        [(6.5, BOUNDARY), (7.0, GRID)],
    ]  # valid beyond the grid end
    assert bands[0][0].limit == limits[0] and bands[1][0].text("speed_rad_s", False) == "1.5 rad/s"
    assert bands[1][1].text("speed_rad_s", True) == "2 rad/s (last valid grid point)"
    assert line_bands(values, -np.abs(growth), []) == []


@pytest.fixture(scope="module")
def radius_columns():
    """Fig. 6 columns at R = 2, 2.2, 5 and 10 mm on the figure's speed grid."""
    model = SqueakModel()
    spec = next(s for s in figures.MAPS if s.file.startswith("fig06"))
    y = figures._grid(spec.y_axis, *spec.y_range, figures.FULL.map_y)
    result = stability_map(
        model, "radius_m", np.array([0.002, 0.0022, 0.005, 0.010]), "speed_rad_s", y
    )
    return result, figures.map_bands(result, "y", model.params), model


def test_band_at_2mm_ends_at_the_edge_of_validity(radius_columns):
    result, bands, model = radius_columns
    ((lo, hi),) = bands[0]
    critical = model.with_params(radius_m=0.002).critical_speed_rad_s
    assert lo.kind == BOUNDARY and 1.9 < lo.value < 2.1
    assert hi.kind == VALIDITY and hi.value < critical < 570 and hi.limit.value == critical
    text = describe_speed_map(result, model.params)
    assert (
        "squeak bands at R = 2 mm: 1.98 rad/s to 559 rad/s (last valid grid point; "
        "validity ends at the first critical speed 564 rad/s)"
    ) in text


def test_two_bands_at_2_2mm_are_both_listed(radius_columns):
    result, bands, model = radius_columns
    (a_lo, a_hi), (b_lo, b_hi) = bands[1]
    assert [e.kind for e in (a_lo, a_hi, b_lo)] == [BOUNDARY] * 3 and b_hi.kind == GRID
    assert a_lo.value == pytest.approx(1.80, abs=0.01)
    assert a_hi.value == pytest.approx(423, abs=1) and b_lo.value == pytest.approx(555, abs=1)
    # the grid ends below the critical speed (~621 rad/s): squeak continues beyond it
    assert b_hi.value == 600 < model.with_params(radius_m=0.0022).critical_speed_rad_s
    assert (
        "more than one band at R = 2.2 mm (1.8-423 rad/s and 555 rad/s to >= 600 rad/s (grid edge))"
    ) in describe_speed_map(result, model.params)


def test_lower_bound_at_10mm_is_the_validity_limit_not_a_boundary(radius_columns):
    result, bands, model = radius_columns
    ((lo, hi),) = bands[3]
    assert lo.kind == VALIDITY and lo.value == model.params.min_speed_rad_s == lo.limit.value
    assert hi.kind == BOUNDARY
    # the linearised boundary lies below min_speed_rad_s: the grid start is no boundary
    low = model.with_params(radius_m=0.010, min_speed_rad_s=0.1)
    assert low.predict(0.46, 200.0).max_growth_rate < 0 < low.predict(0.48, 200.0).max_growth_rate
    text = describe_speed_map(result, model.params)
    assert (
        "at R = 10 mm: 0.5 rad/s (first valid grid point; validity ends at "
        "min_speed_rad_s 0.5 rad/s) to 16.6 rad/s"
    ) in text
    assert "nearest the nominal value, at R = 5 mm: 0.809-55.2 rad/s" in text


def test_fig11_label_and_summary_give_the_same_frequency():
    result = sweep(SqueakModel(), "speed_rad_s", np.geomspace(0.5, 120, 120))
    labels = sorted(t.get_text() for t in plot_frequencies(result).axes[0].texts)
    branches = squeak_branches(result)
    assert labels == sorted(b.squeak_text for b in branches)
    summary = describe_frequencies(result)
    for label in labels:
        assert label in summary
    b1 = next(b for b in branches if b.label.startswith("B1"))
    assert b1.squeak_text == f"{b1.label} {np.median(b1.frequency_hz[b1.growth > 0]):.0f} Hz"


def test_map_json_and_import_do_not_load_matplotlib():
    code = (
        "import sys, io, contextlib\n"
        "import leadscrew_ros.cli.figures\n"
        "from leadscrew_ros.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "    rc = main(['map', '--x', 'radius_m:0.004:0.006:3', '--y', 'speed_rad_s:5:50:3',"
        " '--json'])\n"
        "assert rc == 0 and out.getvalue().startswith('{'), rc\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib'))\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"


def test_the_report_plots_do_not_import_the_cli():
    code = (
        "import sys\n"
        "import leadscrew_ros.review.plots\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'matplotlib')"
        " or m.startswith(('leadscrew_ros.cli', 'leadscrew_ros.ros'))))\n"
        "import leadscrew_ros.review.report\n"
        "print(sorted(m for m in sys.modules if m.startswith('leadscrew_ros.cli')))\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["[]", "[]"]


def test_track_modes_follows_continuous_branches():
    preds = SqueakModel().predict_many(np.geomspace(1, 100, 80), 200.0)
    branches = track_modes(preds)
    assert sum(np.isfinite(b.frequency_hz).sum() for b in branches) == sum(
        len(p.modes) for p in preds
    )
    for b in branches:  # consecutive eigenvalues of a branch are close (relative)
        lam = (b.growth + 2j * np.pi * b.frequency_hz)[np.isfinite(b.frequency_hz)]
        jump = np.abs(np.diff(lam)) / np.maximum(np.abs(lam[1:]), np.abs(lam[:-1]))
        assert np.all(jump < 0.15)
    first = min(branches, key=lambda b: abs(b.typical_frequency_hz - 224))
    assert first.label.startswith("B1") and np.isfinite(first.growth).all()
