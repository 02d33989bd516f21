# SPDX-License-Identifier: Apache-2.0
"""The squeak's amplitude equation: growth at the model's rate, saturation, decay, a floor.

Near a Hopf bifurcation the amplitude A of the most unstable mode obeys a Stuart-Landau
equation, d(ln A)/dt = sigma - l A^2, with sigma = Re(lambda) of the mode. The linear model
gives sigma but not the Landau constant l, so the limit cycle's amplitude is a stated
`saturation` and l is set from it where the mode grows:

    d(ln A)/dt = sigma (1 - (A / saturation)^2)   where sigma > 0 (grows, saturates),
    d(ln A)/dt = sigma                            where sigma <= 0 (decays at the model's rate),

and A never falls below `floor` (the mode is kept ringing at that level by the broadband
friction and drive excitation). Both laws are solved exactly over each step with sigma held
(A^2 is logistic while it grows, exponential while it decays), so the step only sets where
sigma is sampled, not the accuracy; runs of one sign of sigma are vectorised.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Rate of the envelope grid [Hz]: sigma is sampled here, the audio interpolates ln A.
ENVELOPE_RATE_HZ = 2000.0


def squeak_envelope(
    growth_rate_per_s: Any, step_s: float, saturation: float, floor: float
) -> np.ndarray:
    """Amplitude A on a uniform grid, from `floor` at the first point.

    Parameters
    ----------
    growth_rate_per_s : array_like
        sigma [1/s] at each grid point, held over the step that starts there; finite.
    step_s : float
        Grid step [s].
    saturation : float
        Limit-cycle amplitude (any unit, the same as `floor`); > `floor` > 0.
    floor : float
        Lowest amplitude: the start and the level a stable mode decays to.

    Returns
    -------
    numpy.ndarray
        A at each grid point, in the unit of `saturation`.
    """
    sigma = np.asarray(growth_rate_per_s, float).reshape(-1)
    out = np.full(sigma.size, float(floor))
    if sigma.size < 2:
        return out
    steps = sigma[:-1] * step_s  # integral of sigma over step k: A[k] -> A[k + 1]
    grows = steps > 0
    bounds = [0, *(np.flatnonzero(np.diff(grows.astype(np.int8))) + 1).tolist(), steps.size]
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        cum = np.cumsum(steps[lo:hi])
        a0 = out[lo]
        if grows[lo]:  # logistic in A^2: (sat/A)^2 - 1 shrinks as exp(-2 int sigma)
            w0 = (saturation / a0) ** 2 - 1.0
            out[lo + 1 : hi + 1] = saturation / np.sqrt(1.0 + w0 * np.exp(-2.0 * cum))
        else:
            out[lo + 1 : hi + 1] = np.maximum(a0 * np.exp(cum), floor)
    return out
