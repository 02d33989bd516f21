# SPDX-License-Identifier: Apache-2.0
"""Numbers for doc/theory/probability.md: P(squeak) at Table 1 from both estimators.

Also their largest gap.

    .venv/bin/python tools/probability_table.py

prints (1) P(squeak) at 200 N with the default scatter for the speeds of issue 10 in both
formulations: the Monte Carlo reference (4096 samples, with its standard error) and the live
first-order estimate (`SqueakModel.predict`, its own 1024 samples); (2) the largest gap
between the two over the speed x load grid of test/test_probability.py, which asserts it is
<= 0.03.
"""

from __future__ import annotations

from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.studies.probability import monte_carlo
from leadscrew_ros.model.uncertainty.scatter import Scatter, draw

LOAD_N = 200.0
SPEEDS = {"paper": (20.0, 50.0, 55.0, 60.0, 70.0), "consistent": (20.0, 45.0, 49.0, 52.0, 55.0)}
GRID_SPEEDS = (5.0, 20.0, 40.0, 45.0, 50.0, 52.0, 55.0, 57.0, 60.0, 70.0, -40.0, -55.0)
GRID_LOADS = (50.0, 100.0, 200.0, 400.0, 600.0)


def main() -> int:
    print("| formulation | speed [rad/s] | P Monte Carlo (4096) ± stderr | P live (1024) |")
    print("|---|---:|---:|---:|")
    worst = []
    for formulation, speeds in SPEEDS.items():
        model = SqueakModel(ScrewParameters(formulation=formulation))
        ref = draw(model.params, Scatter(), 4096, seed=11)
        for speed in speeds:
            mc, live = monte_carlo(model, speed, LOAD_N, ref), model.predict(speed, LOAD_N)
            print(
                f"| {formulation} | {speed:g} | {mc.probability:.3f} ± {mc.stderr:.3f} | "
                f"{live.probability:.3f} |"
            )
        gap, where = 0.0, None
        for load in GRID_LOADS:
            for speed in GRID_SPEEDS:
                mc, live = monte_carlo(model, speed, load, ref), model.predict(speed, load)
                if mc is not None and abs(live.probability - mc.probability) >= gap:
                    gap, where = abs(live.probability - mc.probability), (speed, load)
        worst.append((formulation, gap, where))
    print()
    for formulation, gap, (speed, load) in worst:
        print(
            f"- {formulation}: largest |P live - P Monte Carlo| over {len(GRID_SPEEDS)} speeds "
            f"x {len(GRID_LOADS)} loads: {gap:.3f} (at {speed:g} rad/s, {load:g} N)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
