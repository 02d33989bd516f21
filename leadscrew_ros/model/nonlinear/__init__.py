# SPDX-License-Identifier: Apache-2.0
"""The nonlinear time-domain check: the nut's friction over the helix at the actual contact
velocity (`friction_force`), the modal equations integrated in time (`transient`) and the
analysis of a run against the linear eigenvalues (`transient_analysis`)."""

from .transient import TransientResult, simulate
from .transient_analysis import TransientAnalysis, analyse

__all__ = ["TransientAnalysis", "TransientResult", "analyse", "simulate"]
