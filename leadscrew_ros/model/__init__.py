# SPDX-License-Identifier: Apache-2.0
"""Pure model of friction-induced squeak in lead screws (numpy/scipy only, never rclpy).

Sub-packages, imports flowing one way: `physics` (parameters, modes, friction, contact,
assembly, stability) -> `acoustics` (the bench microphone: ECMA-418-1 tone prominence, squeak
episodes, agreement with predictions, a simulated microphone; needs only `physics.metadata`) ->
`uncertainty` (scatter, the live P(squeak) estimator) ->
`squeak_model` (`SqueakModel`: one operating point -> `Prediction`) -> `studies` (Monte Carlo
reference, sensitivities, countermeasures, advice, sweeps and maps, mode tracking) ->
`calibration` (heard squeak -> the likelihood of friction and damping, the population's
densities) -> `nonlinear` (the time-domain check).
"""

from .physics import (
    FORMULATIONS,
    Geometry,
    ModalBasis,
    ModeResult,
    ParameterError,
    ScrewParameters,
    SystemMatrices,
    build_geometry,
    field_names,
    modal_basis,
)
from .squeak_model import OperatingPointError, Prediction, SqueakModel, Validity

__all__ = [
    "FORMULATIONS",
    "Geometry",
    "ModalBasis",
    "ModeResult",
    "OperatingPointError",
    "ParameterError",
    "Prediction",
    "ScrewParameters",
    "SqueakModel",
    "SystemMatrices",
    "Validity",
    "build_geometry",
    "field_names",
    "modal_basis",
]
