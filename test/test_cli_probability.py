# SPDX-License-Identifier: Apache-2.0
"""P(squeak) on the command line: --scatter / --samples, predict's probability, sensitivities
and countermeasures, sweep and map --probability, the fig07p summary."""

import contextlib
import io
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadscrew_ros.cli import main
from leadscrew_ros.cli.figures import describe_probability_band
from leadscrew_ros.model import SqueakModel
from leadscrew_ros.model.studies.countermeasures import DESIGN, FRICTION, OPERATING, STEP
from leadscrew_ros.model.studies.fields import PROBABILITY_LEVELS
from leadscrew_ros.model.studies.stability_map import stability_map
from leadscrew_ros.model.uncertainty.scatter import DEFAULT_SCATTER, LOG_NORMAL, Scatter

OFF = [a for name in DEFAULT_SCATTER for a in ("--scatter", f"{name}=0")]


def run(*argv):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()) as out:
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def run_json(*argv):
    code, out, err = run(*argv, "--json")
    assert code == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def at_60():
    """Table 1, 200 N, 60 rad/s: nominally stable, a little above the upper band edge."""
    return run_json("predict", "--speed", "60", "--load", "200")


# ----------------------------------------------------------------------------- predict
def test_predict_probability_near_the_band_edge(at_60):
    d = at_60
    assert d["stable"] is True and d["margin"] > 0  # the nominal verdict: no squeak
    assert 0.05 < d["probability"] < 0.25  # ... yet about one drive in ten
    assert 0 < d["probability_stderr"] < 0.01 and d["probability_samples"] == 4096
    # the live (first-order) estimate agrees with the reference within the 0.03
    assert abs(d["probability_live"] - d["probability"]) <= 0.03


def test_predict_sensitivities_are_keyed_by_field_name(at_60):
    sens = at_60["sensitivities"]
    assert set(DEFAULT_SCATTER) | set(DESIGN) | set(OPERATING) <= set(sens)
    assert all(math.isfinite(v) for v in sens.values())
    # friction drop drives squeak (mu_s up, mu_k down), damping and radius calm it
    assert sens["mu_static"] > 0 > sens["mu_kinetic"]
    assert sens["modal_damping"] < 0 and sens["radius_m"] < 0


def test_predict_countermeasures_are_ranked_and_lower_p(at_60):
    found = at_60["countermeasures"]
    assert found and [c["probability"] for c in found] == sorted(c["probability"] for c in found)
    for c in found:
        assert c["parameter"] in DESIGN + FRICTION + OPERATING and abs(c["change"]) == STEP
        assert 0 <= c["probability"] < at_60["probability_live"]
    assert found[0]["parameter"] == "radius_m" and found[0]["change"] == STEP
    assert found[0]["probability"] < 0.01


def test_predict_text_has_the_advice_line():
    code, out, _ = run("predict", "--speed", "60", "--load", "200")
    line = next(x for x in out.splitlines() if x.startswith("P(squeak) "))
    prob, rest = line[len("P(squeak) ") :].split(" ± ")
    assert code == 0 and 0.05 < float(prob) < 0.25
    assert rest.split(": ")[1].startswith("raise the radius or ")
    assert "stable at the nominal parameters" in out and "d ln p" in out


@pytest.mark.parametrize("off", [OFF, ["--scatter", "none"]], ids=["each", "none"])
@pytest.mark.parametrize("speed, verdict", [("60", 0.0), ("20", 1.0)])
def test_no_scatter_gives_the_nominal_verdict(off, speed, verdict):
    d = run_json("predict", "--speed", speed, "--load", "200", *off)
    assert d["probability"] == d["probability_live"] == verdict
    assert d["probability_stderr"] is None and d["probability_samples"] == 0
    assert d["stable"] is (verdict == 0.0)


def test_none_then_one_scatter_switches_only_that_one_on():
    only = run_json(
        "predict",
        "--speed",
        "60",
        "--load",
        "200",
        "--scatter",
        "none",
        "--scatter",
        "mu_kinetic=0.05",
    )
    assert 0 < only["probability"] < 1 and only["probability_stderr"] > 0


def test_more_friction_scatter_raises_p_near_the_edge():
    """At 65 rad/s (stable, above the edge) a wider friction scatter reaches the band more
    often."""
    p = [
        run_json(
            "predict",
            "--speed",
            "65",
            "--load",
            "200",
            "--scatter",
            f"mu_static={s}",
            "--scatter",
            f"mu_kinetic={s}",
        )["probability"]
        for s in (0.02, 0.05, 0.1)
    ]
    assert p[0] < p[1] < p[2]


def test_samples_sets_the_live_estimator():
    d = run_json("predict", "--speed", "60", "--load", "200", "--samples", "64")
    assert d["probability_samples"] == 4096  # the reference is fixed
    assert d["probability_live"] * 64 == round(d["probability_live"] * 64)


def test_scatter_from_the_params_file(tmp_path):
    for body in (
        "    scatter:\n      mu_static: 0.0\n      mu_kinetic: 0.0\n"
        "      friction_decay_s_m: 0.0\n      modal_damping: 0.0\n",
        "".join(f"    scatter.{n}: 0.0\n" for n in DEFAULT_SCATTER),
    ):
        f = tmp_path / "p.yaml"
        f.write_text("squeak_predictor:\n  ros__parameters:\n" + body)
        d = run_json("predict", "--speed", "60", "--load", "200", "--params-file", str(f))
        assert d["probability"] == 0.0 and d["probability_stderr"] is None
    # the command line wins over the file
    d = run_json(
        "predict",
        "--speed",
        "60",
        "--load",
        "200",
        "--params-file",
        str(f),
        "--scatter",
        "mu_kinetic=0.05",
    )
    assert d["probability_stderr"] > 0


# ----------------------------------------------------------------------------- bad input
BAD_SCATTER = {
    "nan": ["--scatter", "mu_kinetic=nan"],
    "inf": ["--scatter", "mu_kinetic=inf"],
    "negative": ["--scatter", "mu_kinetic=-1"],
    "too large": ["--scatter", "modal_damping=2"],
    "unknown name": ["--scatter", "nosuch=0.1"],
    "not scatterable": ["--scatter", "axial_load_n=0.1"],
    "three geometry fields": [
        "--scatter",
        "radius_m=0.01",
        "--scatter",
        "nut_length_m=0.01",
        "--scatter",
        "helix_angle_rad=0.01",
    ],
    "missing =": ["--scatter", "mu_kinetic"],
    "missing name": ["--scatter", "=0.1"],
    "text value": ["--scatter", "mu_kinetic=abc"],
    "empty value": ["--scatter", "mu_kinetic="],
    "samples not a power of 2": ["--samples", "1000"],
    "samples too few": ["--samples", "8"],
    "samples text": ["--samples", "many"],
}


@pytest.mark.parametrize(
    "command",
    [["predict", "--speed", "20"], ["modes"], ["sweep", "--speed", "1:2:3"]],
    ids=lambda c: c[0],
)
@pytest.mark.parametrize("option", BAD_SCATTER.values(), ids=BAD_SCATTER.keys())
def test_bad_scatter_is_one_error_line_and_exit_2(command, option):
    code, out, err = run(*command, *option)
    assert (code, out) == (2, "")
    assert err.count("\n") == 1 and err.startswith(
        ("leadscrew-squeak: error: --s", "leadscrew-squeak: error: argument --s")
    ), err


def test_bad_scatter_in_the_params_file(tmp_path):
    for body in (
        "    scatter.nosuch: 0.1\n",
        "    scatter.mu_kinetic: -0.1\n",
        "    scatter.radius_m: 0.01\n    scatter.nut_length_m: 0.01\n    scatter.length_m: 0.01\n",
    ):
        f = tmp_path / "p.yaml"
        f.write_text("squeak_predictor:\n  ros__parameters:\n" + body)
        code, out, err = run("modes", "--params-file", str(f))
        assert (code, out) == (2, "") and err.count("\n") == 1
        assert err.startswith("leadscrew-squeak: error: --params-file: "), err


@settings(max_examples=200, deadline=None)
@given(
    item=st.one_of(
        st.text(max_size=30),
        st.builds(
            "{}={}".format,
            st.sampled_from(list(DEFAULT_SCATTER) + ["none", "radius_m", ""]),
            st.one_of(st.floats().map(repr), st.text(max_size=8)),
        ),
    )
)
def test_random_scatter_options_never_crash(item):
    code, out, err = run("modes", "--scatter", item)
    assert code in (0, 2)
    if code == 2:
        assert out == "" and err.count("\n") == 1 and "Traceback" not in err, err


def test_scatter_help_comes_from_the_field_metadata():
    code, out, _ = run("predict", "--help")
    text = " ".join(out.split())
    assert code == 0 and "--scatter NAME=SD" in text
    for name, sd in DEFAULT_SCATTER.items():
        assert f"{name} {sd:g}" in text
    assert "allowed [0, 1]" in text and f"for {', '.join(sorted(LOG_NORMAL))}" in text
    assert "(default 1024, allowed [16, 65536])" in text
    assert "radius_m" in text and "at most 2 geometry fields" in text


# ----------------------------------------------------------------------------- sweep, map
def test_sweep_probability_falls_across_the_upper_band_edge(tmp_path):
    png = tmp_path / "s.png"
    d = run_json(
        "sweep", "--speed", "50:70:21", "--load", "200", "--probability", "--plot", str(png)
    )
    assert png.read_bytes().startswith(b"\x89PNG")
    prob = np.array(d["probability"])
    assert prob[0] > 0.7 and prob[-1] < 0.01
    assert np.all(np.diff(prob) <= 0.02)  # monotone up to sampling noise
    assert all(s is None or 0 <= s < 0.02 for s in d["probability_stderr"])
    crossings = d["probability_crossings"]
    assert list(crossings) == ["0.01", "0.1", "0.5", "0.9"] and crossings["0.9"] == []
    edge = d["stability_boundaries"][0]
    # P falls through 50 % near the nominal boundary, 10 % and 1 % above it
    (p50,), (p10,), (p01,) = crossings["0.5"], crossings["0.1"], crossings["0.01"]
    assert abs(p50 - edge) < 2 and edge < p10 < p01 < 70
    code, out, _ = run("sweep", "--speed", "50:70:21", "--load", "200", "--probability")
    assert code == 0 and f"10 % at {p10:.4g}" in out and "90 % nowhere" in out


def test_map_probability_has_contours_at_every_level(tmp_path):
    png = tmp_path / "p.png"
    d = run_json(
        "map",
        "--x",
        "load_n:100:400:6",
        "--y",
        "speed_rad_s:30:90:13",
        "--probability",
        "--plot",
        str(png),
    )
    prob = np.array(d["probability"], dtype=float)
    assert prob.shape == (13, 6) and np.nanmin(prob) == 0 and np.nanmax(prob) > 0.95
    contours = d["probability_contours"]
    assert list(contours) == [f"{v:g}" for v in PROBABILITY_LEVELS]
    for key in ("0.1", "0.5", "0.9"):
        assert len(contours[key]) >= 6, key
        for x, y in contours[key]:
            assert 100 <= x <= 400 and 30 <= y <= 90
    # the 50 % line lies next to the nominal boundary, 10 % above it (higher speed)
    at_200 = [y for x, y in contours["0.5"] if x == 220]
    edge = [y for x, y in d["boundary"] if x == 220]
    assert at_200 and edge and abs(at_200[0] - edge[0]) < 5
    assert png.read_bytes().startswith(b"\x89PNG")
    assert "probability" not in run_json(
        "map", "--x", "load_n:100:400:3", "--y", "speed_rad_s:30:90:3"
    )


def test_fig07p_summary_brackets_the_nominal_boundary():
    model = SqueakModel()
    result = stability_map(
        model,
        "load_n",
        np.array([100.0, 200.0, 300.0]),
        "speed_rad_s",
        np.linspace(30.0, 90.0, 31),
        probability=True,
    )
    text = describe_probability_band(result, model)
    assert text.startswith("at F_z = 200 N (nearest the nominal load) P(squeak) crosses 1 % at")
    assert "nominal stability boundary 55.2 rad/s" in text
    # refined, not interpolated on the 2 rad/s grid: without scatter every level is the boundary
    nominal = model.with_scatter(Scatter({}))
    result = stability_map(
        nominal,
        "load_n",
        np.array([100.0, 200.0, 300.0]),
        "speed_rad_s",
        np.linspace(30.0, 90.0, 31),
        probability=True,
    )
    assert (
        "crosses 1 % at 55.2 rad/s; 10 % at 55.2 rad/s; 50 % at 55.2 rad/s; 90 % at 55.2 "
        "rad/s; nominal stability boundary 55.2 rad/s" in describe_probability_band(result, nominal)
    )


def test_sweep_probability_crossings_without_scatter_are_the_boundaries():
    """`sweep --scatter none`: P is the 0/1 verdict, so each level is crossed at the refined
    stability boundaries (0.809 and 55.207 rad/s at Table 1, 200 N), in JSON and text, not
    interpolated along the 2 rad/s grid (0.520 ... 56.9 rad/s)."""
    args = ("sweep", "--speed", "0.5:200:100", "--probability", "--scatter", "none")
    d = run_json(*args)
    edges = d["stability_boundaries"]
    np.testing.assert_allclose(edges, [0.809, 55.207], atol=1e-3)
    for level, found in d["probability_crossings"].items():
        np.testing.assert_allclose(found, edges, rtol=0, atol=2e-7, err_msg=level)  # root tol
    code, out, _ = run(*args)
    assert (
        code == 0
        and (
            "P(squeak) crosses 1 % at 0.8091, 55.21, 10 % at 0.8091, 55.21, "
            "50 % at 0.8091, 55.21, 90 % at 0.8091, 55.21 [rad/s]"
        )
        in out
    )
