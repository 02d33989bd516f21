# SPDX-License-Identifier: Apache-2.0
"""Calibration from heard squeak (`leadscrew-squeak calibrate`): what each log says
(`gather`), the per-unit posteriors and the fleet's population (`sampling`, emcee), the whole
run with its held-out check and the comparison of the formulations (`run`), the files it
writes (`output`: calibration.json, .txt, .png and calibrated.yaml). Imports `model`, `live`,
`bag` and `review`."""

from ...model.calibration.posterior import Population, UnitPosterior
from .gather import Gathered, GatherSettings, find_inputs, gather, gather_one, observe_replay
from .output import calibrated_yaml, document, write
from .run import CalibrationResult, FormulationRun, HeldOut, UnitResult, calibrate
from .sampling import SamplerSettings, calibrate_unit, fit_population, unit_seed
from .settings import CalibrationSettings

__all__ = [
    "CalibrationResult",
    "CalibrationSettings",
    "FormulationRun",
    "GatherSettings",
    "Gathered",
    "HeldOut",
    "Population",
    "SamplerSettings",
    "UnitPosterior",
    "UnitResult",
    "calibrate",
    "calibrate_unit",
    "calibrated_yaml",
    "document",
    "find_inputs",
    "fit_population",
    "gather",
    "gather_one",
    "observe_replay",
    "unit_seed",
    "write",
]
