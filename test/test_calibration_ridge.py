# SPDX-License-Identifier: Apache-2.0
"""What heard / not-heard frames cannot tell (doc/user/calibration.md, "Known limit"): in the
consistent formulation the friction drop and the damping scaled together move a stroke's
squeak edges by less than the collar of frames not scored, while either alone moves them by
more (tools/calibration_ridge.py, whose functions these are)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from leadscrew_ros.bag.virtual_bench import BenchSettings, simulate_unit
from leadscrew_ros.model import ScrewParameters
from leadscrew_ros.model.uncertainty.scatter import Scatter
from leadscrew_ros.review.listen import COLLAR_S

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location(
    "calibration_ridge", ROOT / "tools" / "calibration_ridge.py"
)
RIDGE = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(RIDGE)
POPULATION = {"mu_static": 0.27, "mu_kinetic": 0.19, "modal_damping": 0.002}


@pytest.fixture(scope="module")
def changes():
    """`changes` along the ratio (`ratio_variants`) of three units of a consistent bench of the
    worked example's population."""
    settings = BenchSettings(units=3, seed=11, formulation="consistent", population=POPULATION)
    nominal = ScrewParameters(formulation="consistent", **POPULATION)
    rng = np.random.default_rng(settings.seed)
    out = []
    for i in range(settings.units):
        unit = simulate_unit(settings, i, rng, nominal, Scatter())
        stroke = {k: getattr(unit.stroke, k) for k in RIDGE.STROKE}
        out.append(
            RIDGE.changes(
                unit.params,
                RIDGE.ratio_variants(unit.params),
                stroke,
                settings.input_rate_hz,
                RIDGE.DetectorSettings.f_hi_hz,
            )
        )
    return out


def test_the_ratio_of_drop_to_damping_moves_the_edges_less_than_the_collar(changes):
    for unit in changes:
        for label in (
            "drop and damping x 0.8",
            "drop and damping x 1.25",
            "drop and damping x 1.5",
        ):
            assert unit[label][1] < 1e3 * COLLAR_S, label


def test_drop_or_damping_alone_moves_the_edges_several_times_more(changes):
    along = np.mean([u["drop and damping x 1.25"][0] for u in changes])
    for label in ("drop x 1.25 alone", "damping x 1.25 alone"):
        alone = np.mean([u[label][0] for u in changes])
        assert alone > 3 * along, (label, alone, along)
        assert np.mean([u[label][1] for u in changes]) > 1e3 * COLLAR_S
