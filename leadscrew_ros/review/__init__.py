# SPDX-License-Identifier: Apache-2.0
"""Offline review of logs without rclpy: operating-point timeline, replay, episodes, the fleet
review, and every plot (`plots`). Imports `model`, `live` and `bag` only.

The function `replay` is not re-exported here: `review.replay` stays the module of that name."""

from ..model.exports import lazy

_HOMES = {
    "FleetRun": "fleet",
    "FleetSettings": "fleet",
    "Heard": "listen",
    "InputSettings": "timeline",
    "SoundSettings": "listen",
    "ReplayResult": "replay",
    "ReplaySettings": "replay",
    "plot_fleet": "plots",
    "plot_frequencies": "plots",
    "plot_friction": "plots",
    "plot_heard": "plots",
    "plot_map": "plots",
    "plot_sweep": "plots",
    "plot_timeline": "plots",
    "plot_transient": "plots",
    "probability_overlay": "plots",
    "review_logs": "fleet",
    "write_fleet": "fleetreport",
    "write_report": "report",
}
__all__ = [
    "FleetRun",
    "FleetSettings",
    "Heard",
    "InputSettings",
    "SoundSettings",
    "ReplayResult",
    "ReplaySettings",
    "plot_fleet",
    "plot_frequencies",
    "plot_friction",
    "plot_heard",
    "plot_map",
    "plot_sweep",
    "plot_timeline",
    "plot_transient",
    "probability_overlay",
    "review_logs",
    "write_fleet",
    "write_report",
]


# Resolved on first use: a replay's prediction worker imports the timeline and its batch
# solve only, not the fleet, the plots and the acoustics (~0.5 s per process).
__getattr__ = lazy(__name__, _HOMES)
