# SPDX-License-Identifier: Apache-2.0
"""What is computed from a `SqueakModel`: the Monte Carlo reference of P(squeak)
(`probability`), its sensitivities and countermeasures, the safe-speed advice, sweeps
(`sweep`) and stability maps (`stability_map`) with their work-size limits (`work`), the
growth and P(squeak) fields they evaluate (`fields`) and the roots they refine (`roots`),
and mode tracking. Imports `physics`, `uncertainty` and `squeak_model`.

The functions `sweep` and `stability_map` are not re-exported here: the names stay those of
their modules."""

from .fields import GrowthField
from .probability import monte_carlo
from .stability_map import MapResult
from .sweep import SweepResult
from .tracking import track_modes

__all__ = ["GrowthField", "MapResult", "SweepResult", "monte_carlo", "track_modes"]
