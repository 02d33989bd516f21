# SPDX-License-Identifier: Apache-2.0
"""Calibration of units and of the fleet from heard squeak: the samplers (`sampling`, emcee)
around the model's likelihood (`model.calibration`). Imports `model`, `live` and `bag`."""

from ...model.calibration.posterior import Population, UnitPosterior
from .sampling import SamplerSettings, calibrate_unit, fit_population, unit_seed

__all__ = [
    "Population",
    "SamplerSettings",
    "UnitPosterior",
    "calibrate_unit",
    "fit_population",
    "unit_seed",
]
