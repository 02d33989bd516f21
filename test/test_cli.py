# SPDX-License-Identifier: Apache-2.0
"""The `leadscrew-squeak` command line, called in-process through `main(argv)`."""

import contextlib
import csv
import fcntl
import io
import json
import os
import pty
import select
import signal
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadscrew_ros.cli import CliError, main, split_ros_args
from leadscrew_ros.cli.args import MAX_COUNT, parse_range
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.studies.stability_map import stability_map
from leadscrew_ros.model.studies.sweep import sweep
from leadscrew_ros.model.studies.work import MAX_MEMORY_BYTES, MAX_POINTS, map_work, sweep_work

REPO = Path(__file__).resolve().parents[1]
TABLE2_HZ = [224, 898, 2020, 2654, 3592, 5612, 7961, 8082]
PREDICTION_KEYS = {
    "speed_rad_s",
    "load_n",
    "formulation",
    "valid",
    "reason",
    "stable",
    "probability",
    "probability_stderr",
    "probability_samples",
    "probability_live",
    "margin",
    "sensitivities",
    "countermeasures",
    "max_growth_rate",
    "unstable_frequencies_hz",
    "divergence_rates",
    "modes",
}
NO_SCATTER = [
    "--scatter",
    "mu_static=0",
    "--scatter",
    "mu_kinetic=0",
    "--scatter",
    "friction_decay_s_m=0",
    "--scatter",
    "modal_damping=0",
]
MODE_KEYS = {"label", "frequency_hz", "growth_rate", "damping_ratio", "unstable"}


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def run_json(capsys, *argv):
    code, out, err = run(capsys, *argv, "--json")
    assert code == 0, err
    return json.loads(out)


def close(a, b, rel):
    return abs(a - b) <= rel * abs(b)


# ----------------------------------------------------------------------------- modes
def test_modes_json_reproduces_table2(capsys):
    modes = run_json(capsys, "modes")["modes"]
    freqs = [m["frequency_hz"] for m in modes]
    assert len(modes) == 18 and freqs == sorted(freqs)
    assert close(freqs[0], 224, 0.005) and modes[0]["label"].startswith("B1")
    for f in TABLE2_HZ:
        assert any(close(g, f, 0.005) for g in freqs), f


def test_modes_text_is_a_sorted_table(capsys):
    code, out, _ = run(capsys, "modes")
    rows = [line.split() for line in out.splitlines()[1:]]
    assert code == 0 and len(rows) == 18
    assert [float(r[1]) for r in rows] == sorted(float(r[1]) for r in rows)
    assert rows[0][0] == "B1x" and close(float(rows[0][1]), 224.5, 0.001)


def test_modes_follow_params(capsys):
    """Bending frequencies scale with R: --param reaches the model."""
    modes = run_json(capsys, "modes", "--param", "radius_m=0.006")["modes"]
    assert close(modes[0]["frequency_hz"], 224.49 * 1.2, 0.002)


# ----------------------------------------------------------------------------- predict
def test_predict_json_squeaks_at_20_rad_s(capsys):
    d = run_json(capsys, "predict", "--speed", "20", "--load", "200")
    assert set(d) == PREDICTION_KEYS
    assert d["valid"] is True and d["stable"] is False and d["margin"] < 0
    # deep in the band: (almost) every drive of the scatter squeaks
    assert d["probability"] > 0.99 and d["probability_live"] > 0.99
    assert d["formulation"] == "paper" and d["speed_rad_s"] == 20 and d["load_n"] == 200
    f = sorted(d["unstable_frequencies_hz"])
    assert len(f) == 2 and close(f[0], 224, 0.01) and close(f[1], 898, 0.01)
    growth = [m["growth_rate"] for m in d["modes"]]
    assert growth == sorted(growth, reverse=True) and growth[0] == d["max_growth_rate"] > 0
    assert all(set(m) == MODE_KEYS for m in d["modes"])


def test_predict_load_defaults_to_parameter(capsys):
    d = run_json(capsys, "predict", "--speed", "20", "--param", "axial_load_n=50")
    assert d["load_n"] == 50


def test_predict_text_summary(capsys):
    code, out, _ = run(capsys, "predict", "--speed", "20")
    assert code == 0 and "UNSTABLE" in out and "B1y 224" in out and "squeak" in out


def test_predict_outside_validity(capsys):
    d = run_json(capsys, "predict", "--speed", "0.1")
    assert d["valid"] is False and d["probability"] is None and d["stable"] is None
    assert d["probability_stderr"] is d["sensitivities"] is d["countermeasures"] is None
    assert "validity" in d["reason"] and d["modes"] == []
    code, out, err = run(capsys, "predict", "--speed", "0.1")
    assert code == 0 and "validity" in out and err == ""


def test_formulation_option_switches_the_physics(capsys):
    d = run_json(capsys, "predict", "--speed", "20", "--formulation", "consistent")
    assert d["formulation"] == "consistent"
    assert not any(close(f, 224, 0.01) for f in d["unstable_frequencies_hz"])


def test_params_file_applies_known_keys_only(capsys, tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text(
        "squeak_predictor:\n  ros__parameters:\n    radius_m: 0.006\n    publish_rate_hz: 10.0\n"
    )
    modes = run_json(capsys, "modes", "--params-file", str(f))["modes"]
    assert close(modes[0]["frequency_hz"], 224.49 * 1.2, 0.002)
    # --param wins over the file
    modes = run_json(capsys, "modes", "--params-file", str(f), "--param", "radius_m=0.005")["modes"]
    assert close(modes[0]["frequency_hz"], 224.49, 0.002)


def test_repository_config_file_is_accepted(capsys):
    d = run_json(
        capsys, "predict", "--speed", "20", "--params-file", str(REPO / "config" / "leadscrew.yaml")
    )
    assert d["valid"] and not d["stable"]


# ----------------------------------------------------------------------------- errors
BAD = {
    "nan speed": ["predict", "--speed", "nan"],
    "inf speed": ["predict", "--speed", "inf"],
    "text speed": ["predict", "--speed", "abc"],
    "missing speed": ["predict"],
    "no command": [],
    "unknown command": ["fly"],
    "negative radius": ["predict", "--speed", "20", "--param", "radius_m=-1"],
    "unknown param": ["predict", "--speed", "20", "--param", "nosuch=1"],
    "param without value": ["predict", "--speed", "20", "--param", "radius_m"],
    "param not a number": ["predict", "--speed", "20", "--param", "radius_m=abc"],
    "nut beyond screw": ["predict", "--speed", "20", "--param", "nut_position_m=0.29"],
    "bad formulation": ["predict", "--speed", "20", "--formulation", "foo"],
    "absurd load": ["predict", "--speed", "20", "--load", "1e12"],
    "missing params file": ["modes", "--params-file", "/nonexistent/p.yaml"],
    "x spec without count": ["map", "--x", "radius_m:1:2", "--y", "load_n:0:600:5"],
    "x spec unknown axis": ["map", "--x", "nosuch:0:1:3", "--y", "load_n:0:600:5"],
    "x spec count 1": ["map", "--x", "radius_m:0.004:0.006:1", "--y", "load_n:0:600:5"],
    "x spec nan": ["map", "--x", "radius_m:nan:0.006:3", "--y", "load_n:0:600:5"],
    "map same axes": ["map", "--x", "load_n:0:100:3", "--y", "load_n:0:600:5"],
    "sweep count not int": ["sweep", "--speed", "0.5:120:x"],
    "sweep empty range": ["sweep", "--speed", "1:1:5"],
    "sweep without range": ["sweep"],
    "sweep axis without values": ["sweep", "--axis", "radius_m"],
    "sweep json and csv": ["sweep", "--speed", "1:2:3", "--json", "--csv"],
    "ros args for predict": ["predict", "--speed", "20", "--ros-args", "-r", "__ns:=/a"],
    "ros args offline": ["replay", "x.mcap", "--ros-args", "-r", "__ns:=/a"],
}


@pytest.mark.parametrize("argv", BAD.values(), ids=BAD.keys())
def test_bad_input_is_one_error_line_and_exit_2(capsys, argv):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("leadscrew-squeak: error: "), err
    assert "Traceback" not in err


def test_parse_range_validates():
    assert list(parse_range("0:1:3", "x")) == [0.0, 0.5, 1.0]
    for bad in ("0:1", "0:1:1", "0:inf:3", "a:1:3", "0:1:2.5", "0:0:4"):
        with pytest.raises(Exception, match=r"x"):
            parse_range(bad, "x")


def test_module_entry_point_reports_error_without_traceback():
    r = subprocess.run(
        [sys.executable, "-m", "leadscrew_ros.cli", "predict", "--speed", "nan"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
    )
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert len(r.stderr.splitlines()) == 1 and "error" in r.stderr


def test_model_commands_load_neither_rclpy_nor_matplotlib_nor_the_ros_layer():
    """Every command group adds its parser at start-up: that must stay cheap and ROS-free."""
    code = (
        "import contextlib, io, sys\n"
        "from leadscrew_ros.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "    codes = [main([c, '--help']) for c in ('demo', 'simulate', 'replay')]\n"
        "    codes.append(main(['predict', '--speed', '20', '--json']))\n"
        "assert codes == [0, 0, 0, 0] and out.getvalue().rstrip().endswith('}'), codes\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('rclpy', 'matplotlib') or m.startswith('leadscrew_ros.ros')))\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


# ----------------------------------------------------------------------------- sweep
def test_sweep_json_has_the_refined_band(capsys):
    d = run_json(capsys, "sweep", "--speed", "0.5:120:60")
    assert len(d["speed_rad_s"]) == 60 and len(d["max_growth_rate"]) == 60
    bands = d["unstable_bands_rad_s"]
    assert len(bands) == 1
    lo, hi = bands[0]
    assert 0.5 < lo < 2 and 40 < hi < 70
    assert d["stability_boundaries"] == pytest.approx([lo, hi])


def test_sweep_csv_parses(capsys):
    code, out, _ = run(capsys, "sweep", "--speed", "0.5:120:25", "--csv")
    rows = list(csv.DictReader(io.StringIO(out)))
    assert code == 0 and len(rows) == 25
    assert list(rows[0]) == [
        "speed_rad_s",
        "valid",
        "max_growth_rate",
        "probability",
        "probability_stderr",
        "unstable_modes",
        "unstable_frequencies_hz",
    ]
    unstable = [r for r in rows if float(r["max_growth_rate"]) > 0]
    assert unstable and all(r["unstable_modes"] for r in unstable)
    # P(squeak) over the scatter: ~1 well inside the band, ~0 well above it
    for r in rows:
        g, prob = float(r["max_growth_rate"]), float(r["probability"])
        assert 0 <= prob <= 1
        assert prob > 0.95 if g > 20 else prob < 0.01 if float(r["speed_rad_s"]) > 70 else True, r
    assert all(
        any(close(float(f), 224, 0.01) for f in r["unstable_frequencies_hz"].split(";"))
        for r in unstable
    )


def test_sweep_text_reports_bands(capsys):
    code, out, _ = run(capsys, "sweep", "--speed", "0.5:120:30")
    assert code == 0 and "unstable bands [rad/s]: [0.80" in out


def test_sweep_reports_the_refined_peak_not_a_grid_point(capsys):
    """Table 1, 200 N on a 2 rad/s grid: the best grid point is 144.5 1/s at 4.5303 rad/s; the
    maximum, 144.54 1/s at 4.357 rad/s (fine grid, test_model_sweep), is in text and JSON."""
    d = run_json(capsys, "sweep", "--speed", "0.5:200:100")
    assert d["peak_speed_rad_s"] == pytest.approx(4.3569, abs=2e-4)
    assert d["peak_growth_rate"] == pytest.approx(144.543, abs=1e-3)
    assert max(g for g in d["max_growth_rate"]) < d["peak_growth_rate"] - 0.01
    code, out, _ = run(capsys, "sweep", "--speed", "0.5:200:100")
    assert (
        code == 0
        and (
            "largest growth rate 144.54 1/s at speed_rad_s = 4.35692 rad/s "
            "(refined between grid points; squeak modes at the nearest grid point "
            "B1y, B2y, B4y, B3y)"
        )
        in out
    )


def test_sweep_other_axis(capsys, tmp_path):
    png = tmp_path / "radius.png"
    d = run_json(
        capsys,
        "sweep",
        "--axis",
        "radius_m",
        "--values",
        "0.004:0.012:5",
        "--speed",
        "20",
        "--plot",
        str(png),
    )
    assert d["axis"] == "radius_m" and d["fixed"] == {"speed_rad_s": 20.0, "load_n": 200.0}
    assert len(d["radius_m"]) == 5 and len(d["unstable_bands_m"]) == 1
    assert d["unstable_bands_m"][0][0] == 0.004 and 0.006 < d["unstable_bands_m"][0][1] < 0.012
    assert png.read_bytes().startswith(b"\x89PNG")


# ----------------------------------------------------------------------------- map
def test_map_json_and_plot(capsys, tmp_path):
    png = tmp_path / "map.png"
    d = run_json(
        capsys, "map", "--x", "load_n:0:400:4", "--y", "speed_rad_s:0.5:80:5", "--plot", str(png)
    )
    assert d["x_axis"] == "load_n" and d["y_axis"] == "speed_rad_s"
    assert len(d["max_growth_rate"]) == 5 and len(d["max_growth_rate"][0]) == 4
    assert any(any(row) for row in d["unstable"]) and d["boundary"]
    assert png.read_bytes().startswith(b"\x89PNG")


def test_map_text_summary(capsys):
    code, out, _ = run(
        capsys, "map", "--x", "radius_m:0.004:0.008:3", "--y", "load_n:0:400:3", "--speed", "20"
    )
    assert code == 0 and "unstable fraction" in out and "boundary points" in out


# ----------------------------------------------------------------------------- work size
HUGE = {
    "map 1e5 x 1e5": (
        ["map", "--x", "speed_rad_s:1:100:100000", "--y", "load_n:5:600:100000"],
        "map of 100000 x 100000 = 1e+10 points (about 2500 GB) exceeds the limit "
        "of 1e+06 points; use fewer points",
    ),
    "map 5000 x 5000": (
        ["map", "--x", "speed_rad_s:1:100:5000", "--y", "load_n:5:600:5000"],
        "map of 5000 x 5000 = 2.5e+07 points (about 6.3 GB) exceeds the limit "
        "of 1e+06 points; use fewer points",
    ),
    "map just past the limit": (
        ["map", "--x", "speed_rad_s:1:100:1001", "--y", "load_n:5:600:1000"],
        "= 1.001e+06 points (about 0.34 GB) exceeds the limit of 1e+06 points",
    ),
    "map of a 40 + 40 mode model": (
        [
            "map",
            "--x",
            "speed_rad_s:1:100:100",
            "--y",
            "load_n:5:600:100",
            "--param",
            "n_bending=40",
            "--param",
            "n_torsion=40",
        ],
        "exceeds the limit of 3374 points for a model of 240 states",
    ),
    "map over the mode count": (
        ["map", "--x", "n_bending:1:40:40", "--y", "load_n:5:600:1000"],
        "for a model of 172 states",
    ),
    "sweep of a 40 + 40 mode model": (
        ["sweep", "--speed", "1:100:100000", "--param", "n_bending=40", "--param", "n_torsion=40"],
        "sweep of 100000 speed_rad_s values = 100000 points",
    ),
    "figures of a 40 + 40 mode model": (
        ["figures", "--out", "{tmp}/figs", "--param", "n_bending=40", "--param", "n_torsion=40"],
        "use --quick or fewer modes",
    ),
}


@pytest.mark.parametrize("argv, message", HUGE.values(), ids=HUGE.keys())
def test_too_much_work_is_refused_up_front_in_one_line(capsys, tmp_path, argv, message):
    t0 = time.monotonic()
    code, out, err = run(capsys, *(a.format(tmp=tmp_path) for a in argv))
    assert (code, out) == (2, "")
    assert err.count("\n") == 1 and err.startswith("leadscrew-squeak: error: "), err
    assert message in err and "Traceback" not in err
    assert time.monotonic() - t0 < 30  # refused, not attempted (a 1e6-point map: minutes)
    assert not (tmp_path / "figs").exists()


def test_work_limits_are_in_the_help(capsys):
    for command in ("map", "sweep", "figures"):
        code, out, _ = run(capsys, command, "--help")
        assert code == 0 and f"At most {MAX_POINTS} points" in " ".join(out.split())
        assert "Ctrl-C" in out


def test_the_largest_accepted_work_is_within_the_memory_limit():
    model = SqueakModel(ScrewParameters())
    for work in (
        map_work(model, "speed_rad_s", np.zeros(1000), "load_n", np.zeros(1000)),
        sweep_work(model, "speed_rad_s", np.zeros(100_000)),
    ):
        work.check()
        assert work.memory_bytes() <= MAX_MEMORY_BYTES


COUNTS = st.one_of(
    st.integers(-10, 10**12).map(str),
    st.sampled_from(["nan", "inf", "-inf", "", "1e3", "2.5", " ", "0x10", "1_000", "١٢"]),
    st.text(max_size=6),
)
ENDS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["1e308", "-1e308", "nan", "", "x"]),
)


@settings(max_examples=300, deadline=None)
@given(start=ENDS, stop=ENDS, count=COUNTS)
def test_range_specs_give_finite_values_or_one_error(start, stop, count):
    text = f"{start}:{stop}:{count}"
    try:
        values = parse_range(text, "argument --x")
    except CliError as exc:
        assert str(exc).startswith("argument --x") and "\n" not in str(exc)
        return
    assert 2 <= len(values) <= 100_000 == MAX_COUNT
    assert np.all(np.isfinite(values)) and values[0] == float(start) and values[-1] == float(stop)
    assert np.all(np.diff(values) > 0) or np.all(np.diff(values) < 0)


@settings(max_examples=100, deadline=None)
@given(nx=COUNTS, ny=st.integers(-5, 10**7).map(str))
def test_map_axis_counts_never_crash_the_cli(nx, ny):
    """Counts 0, negative, huge, NaN, text: exit 2 with one line (no MemoryError, no traceback)
    unless the grid is small enough to compute, which is then not attempted here."""
    with contextlib.suppress(ValueError):
        if (
            2 <= int(nx) <= MAX_COUNT
            and 2 <= int(ny) <= MAX_COUNT
            and int(nx) * int(ny) <= MAX_POINTS
        ):
            return
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()) as out:
        code = main(["map", "--x", f"speed_rad_s:1:100:{nx}", "--y", f"load_n:5:600:{ny}"])
    assert code == 2 and out.getvalue() == ""
    assert err.getvalue().count("\n") == 1, err.getvalue()
    assert (
        err.getvalue().startswith("leadscrew-squeak: error: argument --")
        or "exceeds the limit" in err.getvalue()
    )


def test_a_long_map_shows_progress_on_a_terminal_and_stops_cleanly_on_ctrl_c():
    """stderr on a pseudo-terminal: the progress bar shows; SIGINT then ends the run with exit
    130 and one line, no traceback, well before the 1e6-point map could finish."""
    leader, follower = pty.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))  # 80 columns
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "leadscrew_ros.cli",
            "map",
            "--x",
            "speed_rad_s:1:100:1000",
            "--y",
            "load_n:5:600:1000",
        ],
        stdout=subprocess.PIPE,
        stderr=follower,
        cwd=REPO,
    )
    os.close(follower)
    seen = b""
    try:
        deadline = time.monotonic() + 120
        while b"pt/s" not in seen and b"pt]" not in seen:
            assert time.monotonic() < deadline and proc.poll() is None, seen
            if select.select([leader], [], [], 1.0)[0]:
                seen += os.read(leader, 4096)
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=60)
        while select.select([leader], [], [], 0.5)[0]:
            try:
                chunk = os.read(leader, 4096)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            seen += chunk
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
        os.close(leader)
    text = seen.decode(errors="replace")
    assert code == 130, text
    assert "map:" in text and "leadscrew-squeak: interrupted" in text
    assert "Traceback" not in text and proc.stdout.closed


def test_progress_counts_every_point_once_valid_or_not():
    model = SqueakModel(ScrewParameters())
    done = []
    radii = np.array([-0.001, 0.004, 0.005, 0.0, 0.006])  # two invalid radii
    sweep(model, "radius_m", radii, progress=done.append)
    assert sum(done) == radii.size
    done.clear()
    stability_map(
        model, "radius_m", radii, "speed_rad_s", np.linspace(1.0, 1e6, 4), progress=done.append
    )  # 1e6 rad/s: invalid too
    assert sum(done) == radii.size * 4


def test_ros_args_are_split_off_as_rcl_delimits_them():
    assert split_ros_args(
        [
            "simulate",
            "--loop",
            "--ros-args",
            "-r",
            "__ns:=/a",
            "--",
            "--rate",
            "5",
            "--ros-args",
            "-p",
            "x:=1",
        ]
    ) == (
        ["simulate", "--loop", "--rate", "5"],
        ["--ros-args", "-r", "__ns:=/a", "--ros-args", "-p", "x:=1"],
    )
    assert split_ros_args(["map", "--x", "a:=b"]) == (["map", "--x", "a:=b"], [])
