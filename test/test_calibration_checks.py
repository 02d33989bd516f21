# SPDX-License-Identifier: Apache-2.0
"""What `calibrate` refuses before any work and what its outputs say (issue 31, items 3, 5-7):
a parameter without a prior scatter, an --out that cannot be written, an --out another run
holds (its lock); the clipping of calibrated.yaml printed and consistent with the file; the
predictive centre and spread explained; the held-out check's warnings; the formulation not
supported does not fail the run; and per unit what the data identified (a fleet where one
parameter cannot be identified)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from harness.calibration import synthetic_unit
from harness.logs import cli
from leadscrew_ros.cli.calibrate import LOCK_FILE, NOT_CONVERGED, exit_status
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.calibration import Prior
from leadscrew_ros.model.calibration.posterior import (
    DROP,
    PRIOR_ALONE_SD_RATIO,
    Population,
    UnitPosterior,
)
from leadscrew_ros.model.calibration.prior import DEFAULT_NAMES
from leadscrew_ros.model.uncertainty.scatter import Scatter
from leadscrew_ros.review.calibration import SamplerSettings, calibrate_unit
from leadscrew_ros.review.calibration.output import PREDICTIVE, calibrated_yaml, document, text
from leadscrew_ros.review.calibration.run import (
    MIN_HELD_OUT,
    CalibrationResult,
    Comparison,
    FormulationRun,
    HeldOut,
    UnitResult,
    _install,
)
from leadscrew_ros.review.calibration.settings import CalibrationSettings
from leadscrew_ros.review.outlock import DirectoryBusy, locked
from leadscrew_ros.review.timeline import ModelSpec

pytestmark = pytest.mark.timeout(600)

NOMINAL = ScrewParameters()
FAST = SamplerSettings(walkers=16, steps=120, first_steps=80, burn=40, max_reexpansions=1)


@pytest.fixture
def inputs(tmp_path: Path) -> Path:
    """A directory that `calibrate` finds an input in (a replay output's summary.json): the
    refusals below come before it is read."""
    d = tmp_path / "inputs"
    d.mkdir()
    (d / "summary.json").write_text("{}")
    return d


def _one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("leadscrew-squeak: error: "), err
    return lines[0]


# ----------------------------------------------------------------------------- refusals
def test_a_parameter_without_prior_scatter_is_refused_up_front(capsys, inputs, tmp_path):
    out = tmp_path / "out"
    code, _, err = cli(
        capsys, "calibrate", inputs, "--out", out, "--calibrate", "youngs_modulus_pa"
    )
    assert code == 2
    line = _one_error_line(err)
    assert "youngs_modulus_pa" in line and "--scatter youngs_modulus_pa=SD" in line
    assert all(name in line for name in Scatter().names)  # the ones that can be calibrated
    assert not out.exists()  # nothing done
    # with its scatter it is accepted (it gets as far as reading the input)
    code, _, err = cli(
        capsys, "calibrate", inputs, "--out", out, "--calibrate", "youngs_modulus_pa",
        "--scatter", "youngs_modulus_pa=0.02", "--workers", "1", "--quiet",
    )  # fmt: skip
    assert "youngs_modulus_pa" not in err


@pytest.mark.parametrize("where", ["under a file", "/proc", "a file"])
def test_an_out_that_cannot_be_written_is_refused_before_any_work(capsys, inputs, tmp_path, where):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    out = {
        "under a file": blocker / "out",
        "/proc": Path(f"/proc/leadscrew-calibrate-{os.getpid()}"),
        "a file": blocker,
    }[where]
    code, stdout, err = cli(capsys, "calibrate", inputs, "--out", out)
    assert code == 2 and not stdout
    line = _one_error_line(err)
    assert "--out" in line and str(out) in line and "Errno" not in line
    assert not (inputs / "replays").exists() and blocker.read_text() == "x"


HOLDER = """
import sys
from pathlib import Path
from leadscrew_ros.review.outlock import locked
with locked(Path(sys.argv[1]), sys.argv[2]):
    print("held", flush=True)
    sys.stdin.read()
"""


def test_a_second_run_on_one_out_is_refused_naming_the_run_that_holds_it(capsys, inputs, tmp_path):
    """Another process holds --out (as a running calibrate does): this one exits 2 naming its
    pid and start time, and touches nothing; when it ends, the lock is gone."""
    out = tmp_path / "out"
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(out), LOCK_FILE],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        code, _, err = cli(capsys, "calibrate", inputs, "--out", out)
        assert code == 2
        line = _one_error_line(err)
        assert f"pid {holder.pid}, started 20" in line and "another run" in line
        assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]
    finally:
        holder.communicate("", timeout=60)
    assert holder.returncode == 0 and not (out / LOCK_FILE).exists()


def test_a_stale_lock_of_a_dead_run_is_taken_over_and_said(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock = tmp_path / LOCK_FILE
    lock.write_text(f"pid={dead.pid}\nstarted=2026-01-01T00:00:00+00:00\n")
    with locked(tmp_path, LOCK_FILE) as note:
        assert f"pid {dead.pid}, started 2026-01-01T00:00:00+00:00" in note
        assert lock.read_text().startswith(f"pid={os.getpid()}\n")
        with pytest.raises(DirectoryBusy, match=f"pid {os.getpid()}"):
            with locked(tmp_path, LOCK_FILE):
                pass  # a second holder, even in this process (another open file)
    assert not lock.exists()
    with locked(tmp_path, LOCK_FILE) as note:  # a clean end leaves no stale lock
        assert note == ""


# ----------------------------------------------------------------------------- outputs
def _run(formulation: str, population: Population | None, units=()) -> FormulationRun:
    spec = ModelSpec(NOMINAL.with_(formulation=formulation), tuple(Scatter().sd.items()), 256)
    run = FormulationRun(formulation, spec, list(units))
    if population is None:
        run.population_status = "no population: 0 calibrated training unit(s), at least 2 needed"
    else:
        _install(run, [], (population, [], population.status))
    return run


def _population(hyper: np.ndarray) -> Population:
    return Population(
        names=DEFAULT_NAMES, prior=Prior(NOMINAL, Scatter(), DEFAULT_NAMES), hyper=hyper,
        status="calibrated", converged=True, ess={}, units=("a", "b"), evaluations=0,
        seconds=0.0,
    )  # fmt: skip


def _result(runs: dict[str, FormulationRun], comparison: Comparison | None = None):
    chosen = comparison.supported if comparison and comparison.supported else next(iter(runs))
    return CalibrationResult(runs, chosen, comparison, [], CalibrationSettings(), 1.0)


def test_a_clipped_population_is_said_and_the_printed_values_are_the_files():
    """Units that never squeak can put the fleet's mu_kinetic above its mu_static: the file
    sets mu_kinetic to mu_static; calibration.txt (and so stdout) prints the file's values
    and says what was clipped, as calibration.json and the file's header do."""
    hyper = np.zeros((10, 8))
    hyper[:, 1] = 9.0  # mu_k 0.2 (1 + 0.05 * 9) = 0.29 > mu_s 0.25
    result = _result({"paper": _run("paper", _population(hyper))})
    shown = text(result)
    assert "fleet population" in shown and PREDICTIVE in shown
    lines = shown.splitlines()
    values = lines[lines.index(PREDICTIVE + ":") + 1]  # the file's values, on the next line
    params = yaml.safe_load(calibrated_yaml(result, "2026-01-01"))["/**"]["ros__parameters"]
    assert params["mu_kinetic"] == params["mu_static"] < 0.29
    # its SD in the field's unit kept (the prior's 0.05 * 0.2: the population's SD 1 in u)
    sd_k = params["scatter"]["mu_kinetic"] * params["mu_kinetic"]
    assert sd_k == pytest.approx(0.05 * NOMINAL.mu_kinetic, rel=1e-9)
    assert f"mu_kinetic {params['mu_kinetic']:.4g} " in values
    assert f"mu_static {params['mu_static']:.4g} " in values
    [clip] = [line for line in shown.splitlines() if line.startswith("  clipped: ")]
    assert "mu_kinetic 0.29 above mu_static" in clip and "set to mu_static" in clip
    assert "# Clipped to the valid ranges: mu_kinetic 0.29" in calibrated_yaml(result, "x")
    doc = document(result, {})
    assert doc["calibrated"]["notes"] == [clip.removeprefix("  clipped: ")]
    assert doc["calibrated"]["params"]["mu_kinetic"] == pytest.approx(params["mu_kinetic"])
    # nothing clipped: no such line
    assert "clipped" not in text(_result({"paper": _run("paper", _population(hyper * 0))}))


@pytest.mark.parametrize(
    "held, warned",
    [
        (HeldOut(["a"], 100, 0.007, 0.020, {"a": (0.007, 0.020)}), ["only 1 units", "worse"]),
        (HeldOut(["a", "b", "c"], 300, 0.03, 0.01, {}), []),
        (HeldOut(["a", "b", "c"], 300, 0.01, 0.03, {"a": (0.01, 0.02)}), ["worse than the prior"]),
        (HeldOut(["a", "b"], 200, 0.03, 0.01, {}), [f"fewer than {MIN_HELD_OUT}"]),
        (HeldOut([]), ["only 0 units"]),
    ],
)
def test_the_held_out_check_warns_when_it_says_little_or_the_calibration_does_worse(held, warned):
    run = _run("paper", _population(np.zeros((10, 8))))
    run.held_out = held
    result = _result({"paper": run})
    shown = [line for line in text(result).splitlines() if line.startswith("  warning: ")]
    assert len(shown) == len(warned)
    for line, words in zip(shown, warned, strict=True):
        assert words in line
    assert document(result, {})["held_out"]["warnings"] == [
        s.removeprefix("  warning: ") for s in shown
    ]
    assert exit_status(result) == 0  # a warning, not a failure (the docs: exit status unchanged)


def test_both_formulations_exit_0_when_the_supported_one_converged():
    """The formulation not supported did not converge: said in calibration.txt, not the run's
    failure; when none is supported, both must converge."""
    ok = _run("consistent", _population(np.zeros((10, 8))), [UnitResult("a", [], "calibrated")])
    stuck = _run(
        "paper", None, [UnitResult("a", [], "not converged (effective sample size mu_static 3)")]
    )
    runs = {"paper": stuck, "consistent": ok}
    supported = _result(runs, Comparison("consistent", "strongly", "frequency match"))
    assert supported.converged and exit_status(supported) == 0
    lines = text(supported).splitlines()
    assert any(
        line.startswith("paper: 1 units not converged")
        and "not the supported formulation: reported, not an error" in line
        for line in lines
    ), lines
    undecided = _result(runs, Comparison(None, "no held-out score for both formulations"))
    assert exit_status(undecided) == NOT_CONVERGED
    assert (
        exit_status(_result({"consistent": ok, "paper": stuck}, Comparison("paper", "weakly")))
        == NOT_CONVERGED
    )


# ----------------------------------------------------------------------------- identifiability
@pytest.fixture(scope="module")
def unidentified():
    """Three units calibrated with the thread height, which heard / not-heard frames cannot
    tell (its prior scatter 5 %), besides the friction and the damping."""
    model = SqueakModel(NOMINAL, Scatter({**Scatter().sd, "thread_height_m": 0.05}))
    names = ("mu_static", "mu_kinetic", "modal_damping", "thread_height_m")
    units = [
        synthetic_unit(f"u{i}", np.random.default_rng([5, i]), duration_s=6.0) for i in range(3)
    ]
    return [calibrate_unit(model, u.obs, names, settings=FAST) for u in units]


def test_a_parameter_the_frames_cannot_tell_is_said_to_come_from_the_prior_alone(unidentified):
    for post in unidentified:
        ident = post.identifiability()
        ratio = ident["sd_ratio"]
        assert ratio["thread_height_m"] >= PRIOR_ALONE_SD_RATIO, ratio
        assert "thread_height_m" in ident["prior_alone"]
        assert ratio[DROP] < PRIOR_ALONE_SD_RATIO and DROP not in ident["prior_alone"], ratio
        r = ident["drop_damping_correlation"]
        assert r is not None and -1 <= r <= 1
        drop = post.drop()
        damping = post.samples[:, post.names.index("modal_damping")]
        assert r == pytest.approx(np.corrcoef(drop, damping)[0, 1])
    units = [UnitResult(p.unit_id, list(p.logs), "calibrated", posterior=p) for p in unidentified]
    lines = text(_result({"paper": _run("paper", None, units)})).splitlines()
    for p in unidentified:
        [line] = [x for x in lines if x.startswith(f"  {p.unit_id} ")]
        assert "prior alone: " in line and "thread_height_m" in line.split("prior alone: ")[1]
        assert f"r {p.drop_damping_correlation():+.2f}" in line
    doc = document(_result({"paper": _run("paper", None, units)}), {})
    assert all("thread_height_m" in u["identifiability"]["prior_alone"] for u in doc["units"])
    json.dumps(doc, allow_nan=False)


def test_a_posterior_as_wide_as_its_prior_is_prior_alone_and_a_narrow_one_is_not():
    """The rule itself, on samples drawn from the prior (ratio about 1) with one name
    narrowed to a tenth; no correlation without the damping."""
    prior = Prior(NOMINAL, Scatter(), ("mu_static", "mu_kinetic", "friction_decay_s_m"))
    u = prior.draw(4000, np.random.default_rng(1))
    u[:, 2] *= 0.1
    post = UnitPosterior(
        "x", (), "calibrated", prior.names, prior.from_u(u), {}, True, 0, 0, 0.0, prior, True
    )
    ident = post.identifiability()
    assert ident["prior_alone"] == ["mu_static", "mu_kinetic", DROP]
    assert ident["sd_ratio"]["friction_decay_s_m"] == pytest.approx(0.1, rel=0.1)
    assert ident["drop_damping_correlation"] is None


def test_the_growth_rate_match_decides_between_formulations_when_the_tones_do_not():
    """compare: the frequency match equal, the growth-rate match 0.9 vs 0.3 decides for the
    first; with no onsets the held-out score decides as before."""
    from leadscrew_ros.review.calibration.run import FormulationRun, UnitResult, compare
    from leadscrew_ros.review.timeline import ModelSpec

    def run(name: str, onsets: tuple[int, int], brier: float) -> FormulationRun:
        units = [
            UnitResult(f"u{k}", ["l"], "calibrated", matched_frames=90, heard_frames=100,
                       matched_onsets=onsets[0], onsets=onsets[1])
            for k in range(3)
        ]  # fmt: skip
        spec = ModelSpec(ScrewParameters(formulation=name), (), 64)
        r = FormulationRun(name, spec, units)
        r.held_out = HeldOut(["u0"], 100, 0.1, brier, {"u0": (0.1, brier)})
        return r

    c = compare(
        {"paper": run("paper", (9, 10), 0.05), "consistent": run("consistent", (3, 10), 0.04)}
    )
    assert (c.supported, c.decided_by) == ("paper", "growth-rate match")
    c = compare(
        {"paper": run("paper", (0, 0), 0.05), "consistent": run("consistent", (0, 0), 0.04)}
    )
    assert (c.supported, c.decided_by) == ("consistent", "held-out score")


def test_the_growth_rate_match_counts_onsets_near_the_predicted_growth_rate():
    """growth_match: an onset rate at the predicted Re(lambda) of the most unstable mode
    matches, one three times it does not; an onset where the model does not hold is not
    counted."""
    from leadscrew_ros.model import SqueakModel
    from leadscrew_ros.model.calibration import thin
    from leadscrew_ros.review.calibration.run import growth_match

    n, hop = 40, 0.01
    t = np.arange(n) * hop
    speed = np.where(t < 0.1, 0.0, 10.0)  # standing first: no point there
    nut = 0.1  # a multiple of the nut bin: the point is where it was predicted
    sigma = SqueakModel(ScrewParameters(nut_position_m=nut)).predict(10.0, 200.0).max_growth_rate
    assert sigma is not None and sigma > 0

    def obs(rate: float):
        return thin(
            "g", ["g"], t, np.where(speed > 0, speed, np.nan), np.full(n, 200.0),
            np.full(n, nut), np.zeros(n, bool), np.full(n, np.nan), hop,
            valid=speed > 0, onsets=[(0.3, rate, 1.0), (0.02, rate, 1.0)],
        )  # fmt: skip

    assert growth_match(ScrewParameters(), obs(sigma)) == (1, 1)
    assert growth_match(ScrewParameters(), obs(3.0 * sigma)) == (0, 1)
    # a rate within two SEs of zero is no growth measured: not counted, as in (A2)
    weak = thin(
        "g", ["g"], t, np.where(speed > 0, speed, np.nan), np.full(n, 200.0),
        np.full(n, nut), np.zeros(n, bool), np.full(n, np.nan), hop,
        valid=speed > 0, onsets=[(0.3, sigma, sigma)],
    )  # fmt: skip
    assert growth_match(ScrewParameters(), weak) == (0, 0)


# ------------------------------------------------------------------ the reported population
def test_the_reported_fit_shares_the_bench_hearing_with_the_held_out_units(monkeypatch):
    """Step 7 fits every calibrated unit, the held-out ones too: each enters with its samples
    re-weighted to the bench's hearing learned from the others, as the training units did,
    not with its samples under the grid's prior (a unit of another bench). Held-out unit a
    cannot tell the threshold (half its samples with each cell); b and c favour cell 1 9:1.
    When that fit fails, the training units' state stays."""
    from leadscrew_ros.model.calibration.amplitude import HearingPrior
    from leadscrew_ros.review.calibration import run as run_module

    settings = CalibrationSettings(hearing=HearingPrior(threshold_points=2, depth_points=1))
    n = 4000
    x = np.linspace(0.0, 1.0, n)

    def unit(uid: str, weights: np.ndarray, held_out: bool = False) -> UnitResult:
        post = UnitPosterior(
            uid, (uid,), "calibrated", ("x",), x[:, None], {"x": float(n)}, True, 0, 0, 0.0,
            None, True, weights,  # type: ignore[arg-type]
        )  # fmt: skip
        return UnitResult(uid, [uid], "calibrated", post, post, held_out=held_out)

    a = unit("a", np.column_stack([x < 0.5, x >= 0.5]).astype(float), held_out=True)
    b, c = (unit(u, np.tile([0.1, 0.9], (n, 1))) for u in "bc")
    run = _run("paper", _population(np.zeros((10, 8))), [a, b, c])
    trained = run.hearing = np.zeros((1, 2))  # stands for the training units' bench
    entered: list[dict[str, UnitPosterior]] = []
    outcome: list = [RuntimeError("the fit of all units failed")]

    def fit(runs, unit_sets, _settings, _client):
        entered.append({u.unit_id: u.posterior for u in unit_sets[0]})
        return outcome

    monkeypatch.setattr(run_module, "_fit_populations", fit)
    run_module._populations_of_all([run], settings, None)
    assert set(entered[0]) == {"a", "b", "c"}
    # a's samples re-weighted 81:1 towards the cell b and c favour
    assert np.mean(entered[0]["a"].samples[:, 0] >= 0.5) == pytest.approx(81 / 82, abs=0.01)
    assert run.hearing is trained and a.posterior is a.sampled  # the failed fit changed nothing
    assert "with all units: RuntimeError" in run.population_status
    outcome[0] = (_population(np.zeros((10, 8))), [a.sampled, b.sampled, c.sampled], "calibrated")
    run_module._populations_of_all([run], settings, None)
    cell1 = float(np.exp(run.hearing).ravel()[1])  # the bench's hearing from all three (a: 1:1)
    assert cell1 == pytest.approx(0.9**2 / (0.9**2 + 0.1**2), rel=1e-9)
    assert np.mean(a.posterior.samples[:, 0] >= 0.5) == pytest.approx(81 / 82, abs=0.01)
