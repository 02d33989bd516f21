# SPDX-License-Identifier: Apache-2.0
"""The linear physics of the screw (paper Sections 2-3, Appendix A): parameters and their
metadata, assumed modes, friction law, contact kernels and integrals, the assembled matrices of
eq. (27) and the eigen-analysis that classifies squeak. Imports nothing else of `model`."""

from .assembly import Geometry, SystemMatrices, build_geometry
from .modes import ModalBasis, modal_basis
from .parameters import FORMULATIONS, ParameterError, ScrewParameters, field_names
from .stability import ModeResult

__all__ = [
    "FORMULATIONS",
    "Geometry",
    "ModalBasis",
    "ModeResult",
    "ParameterError",
    "ScrewParameters",
    "SystemMatrices",
    "build_geometry",
    "field_names",
    "modal_basis",
]
