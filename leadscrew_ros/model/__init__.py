# SPDX-License-Identifier: Apache-2.0
"""Pure model of friction-induced squeak in lead screws (numpy/scipy only, never rclpy)."""

from .assembly import Geometry, SystemMatrices, build_geometry
from .modes import ModalBasis, modal_basis
from .parameters import FORMULATIONS, ParameterError, ScrewParameters, field_names
from .predictor import OperatingPointError, Prediction, SqueakModel, Validity
from .stability import ModeResult

__all__ = ["FORMULATIONS", "Geometry", "ModalBasis", "ModeResult", "OperatingPointError",
           "ParameterError", "Prediction", "ScrewParameters", "SqueakModel", "SystemMatrices",
           "Validity", "build_geometry", "field_names", "modal_basis"]
