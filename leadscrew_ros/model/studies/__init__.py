# SPDX-License-Identifier: Apache-2.0
"""What is computed from a `SqueakModel`: the Monte Carlo reference of P(squeak)
(`probability`), its sensitivities and countermeasures, the safe-speed advice, sweeps and
stability maps, and mode tracking. Imports `physics`, `uncertainty` and `squeak_model`.

The functions `sweep` and `stability_map` are not re-exported here: `studies.sweep` stays the
module of that name."""

from .probability import monte_carlo
from .sweep import MapResult, SweepResult
from .tracking import track_modes

__all__ = ["MapResult", "SweepResult", "monte_carlo", "track_modes"]
