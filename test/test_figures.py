"""`leadscrew-squeak figures --quick` and the helpers that turn data into summary sentences."""

import math
import re
import time

import numpy as np
import pytest

from leadscrew_ros.cli import main
from leadscrew_ros.figures import FIGURE_FILES, _envelope, track_modes
from leadscrew_ros.model import SqueakModel

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def quick_figures(tmp_path_factory):
    out = tmp_path_factory.mktemp("figs")
    start = time.perf_counter()
    code = main(["figures", "--out", str(out), "--quick"])
    return out, code, time.perf_counter() - start


def test_quick_figures_writes_eight_pngs(quick_figures):
    out, code, seconds = quick_figures
    assert code == 0
    assert len(FIGURE_FILES) == 8
    for name in FIGURE_FILES:
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000, name
    assert seconds < 20


def test_summary_describes_every_figure(quick_figures):
    out, _, _ = quick_figures
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


def test_summary_is_printed(capsys, tmp_path):
    assert main(["figures", "--out", str(tmp_path), "--quick", "--formulation", "consistent"]) == 0
    out = capsys.readouterr().out
    assert out == (tmp_path / "summary.txt").read_text()
    assert "consistent formulation" in out.splitlines()[0]


def test_envelope_uses_roots_and_open_ends():
    values = np.arange(6.0)
    growth = np.array([-1.0, 1.0, 2.0, -1.0, np.nan, 3.0])
    assert _envelope(values, growth, [0.5, 2.5]) == (0.5, 5.0)
    assert all(math.isnan(v) for v in _envelope(values, -np.abs(growth), []))


def test_track_modes_follows_continuous_branches():
    preds = SqueakModel().predict_many(np.geomspace(1, 100, 80), 200.0)
    branches = track_modes(preds)
    assert sum(np.isfinite(b.frequency_hz).sum() for b in branches) == sum(
        len(p.modes) for p in preds)
    for b in branches:      # consecutive eigenvalues of a branch are close (relative)
        lam = (b.growth + 2j * np.pi * b.frequency_hz)[np.isfinite(b.frequency_hz)]
        jump = np.abs(np.diff(lam)) / np.maximum(np.abs(lam[1:]), np.abs(lam[:-1]))
        assert np.all(jump < 0.15)
    first = min(branches, key=lambda b: abs(b.typical_frequency_hz - 224))
    assert first.label.startswith("B1") and np.isfinite(first.growth).all()
