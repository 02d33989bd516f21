# SPDX-License-Identifier: Apache-2.0
"""What a calibration run calibrates and how it is checked (`CalibrationSettings`), declared
with field metadata: the options of `calibrate` come from here."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from ...model.calibration import DetectionErrors, HearingPrior
from ...model.calibration.prior import DEFAULT_NAMES, check_names
from ...model.physics.metadata import check, setting
from ...model.physics.parameters import FORMULATIONS, ParameterError
from ..jsonsafe import json_safe
from .sampling import SamplerSettings

BOTH = "both"


@dataclass(frozen=True)
class CalibrationSettings:
    """What is calibrated, how, and how it is checked.

    Attributes
    ----------
    names : tuple of str
        The calibrated parameters (scatterable `ScrewParameters` fields).
    holdout, formulation, reliability_bins
        See the field metadata.
    errors : DetectionErrors
        The detector's false-alarm and miss rates in the likelihood.
    hearing : HearingPrior
        The observation model's prior of the bench's detection threshold and floor depth.
    sampler : SamplerSettings
        The sampler (its seed also seeds the hold-out split).
    """

    names: tuple[str, ...] = field(
        default=DEFAULT_NAMES,
        metadata={"help": "a parameter to calibrate, any scatterable field"},
    )
    holdout: float = setting(
        0.2,
        "1",
        "share of the units held out of the population fit for the held-out check "
        "(rounded to whole units)",
        0.0,
        1.0,
        hi_open=True,
    )
    formulation: str = setting(
        "paper",
        "",
        "friction formulation calibrated; both: each, compared by the frequency match and "
        "the held-out check",
        choices=(*FORMULATIONS, BOTH),
    )
    reliability_bins: int = setting(
        10, "1", "bins of predicted P(squeak) in the held-out reliability curve", 2, 100
    )
    errors: DetectionErrors = field(default_factory=DetectionErrors)
    hearing: HearingPrior = field(default_factory=HearingPrior)
    sampler: SamplerSettings = field(default_factory=SamplerSettings)

    def __post_init__(self) -> None:
        check(self, ParameterError, "calibrate.")
        object.__setattr__(self, "names", check_names(self.names))

    @property
    def formulations(self) -> tuple[str, ...]:
        """The formulations calibrated."""
        return FORMULATIONS if self.formulation == BOTH else (self.formulation,)

    def as_dict(self) -> dict[str, Any]:
        """calibration.json's settings.

        Returns
        -------
        dict
            Every field, the nested settings as dicts, JSON-ready.
        """
        return json_safe(asdict(self))
