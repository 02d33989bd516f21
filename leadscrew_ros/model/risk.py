# SPDX-License-Identifier: Apache-2.0
"""Squeak risk: one monotone number in [0, 1] from the least-stable oscillatory mode.

    risk = 1                              if zeta_min <= 0   (a squeak mode exists)
    risk = exp(-zeta_min / zeta_ref)      otherwise

zeta_min = min over oscillatory modes of the damping ratio -Re(lambda)/|lambda|; zeta_ref is the
parameter `risk_damping_scale` (default 1e-3). With the default, a mode left with the structural
damping alone (xi_n = 3e-3) gives 0.05, half of it (friction eating 1.5e-3) gives 0.22, and
risk rises continuously to 1 at the flutter boundary. The function is continuous and strictly
decreasing in zeta_min for zeta_min > 0.
"""

from __future__ import annotations

import numpy as np


def squeak_risk(min_damping_ratio, damping_scale: float):
    z = np.asarray(min_damping_ratio, dtype=float)
    r = np.exp(-np.maximum(z, 0.0) / damping_scale)
    return float(r) if r.ndim == 0 else r
