# SPDX-License-Identifier: Apache-2.0
"""Unit-to-unit scatter and the live P(squeak): the scatter of friction, damping and geometry
(`scatter`) and the first-order estimator that turns one eigen-solve into P(squeak)
(`perturbation`). Imports `physics` only."""

from .perturbation import FirstOrderProbability
from .scatter import Samples, Scatter

__all__ = ["FirstOrderProbability", "Samples", "Scatter"]
