# SPDX-License-Identifier: Apache-2.0
"""Calibration from heard squeak: a unit's heard / not-heard detector frames thinned to
distinct operating points (`observations`), the cheap first-order likelihood of them given
friction and damping (`likelihood`), the observation model of a squeak that grows from its
floor (`amplitude`), the prior in standardised coordinates (`prior`), the
hierarchical population's densities (`population`) and posterior summaries (`summaries`).
numpy/scipy only: the sampler (emcee) runs in `review.calibration`. Imports `physics`,
`uncertainty` and `squeak_model`."""

from .amplitude import AmplitudeLikelihood, HearingPrior
from .likelihood import DetectionErrors, GrowthLikelihood
from .observations import CalibrationError, Observations, ThinSettings, merge, thin
from .prior import Prior

__all__ = [
    "AmplitudeLikelihood",
    "CalibrationError",
    "DetectionErrors",
    "GrowthLikelihood",
    "HearingPrior",
    "Observations",
    "Prior",
    "ThinSettings",
    "merge",
    "thin",
]
