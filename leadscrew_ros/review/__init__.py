# SPDX-License-Identifier: Apache-2.0
"""Offline review of logs without rclpy: operating-point timeline, replay, episodes, the fleet
review, and every plot (`plots`). Imports `model`, `live` and `bag` only.

The function `replay` is not re-exported here: `review.replay` stays the module of that name."""

from .fleet import FleetRun, FleetSettings, review_logs
from .fleetreport import write_fleet
from .listen import Heard, SoundSettings
from .plots import (
    plot_fleet,
    plot_frequencies,
    plot_friction,
    plot_heard,
    plot_map,
    plot_sweep,
    plot_timeline,
    plot_transient,
    probability_overlay,
)
from .replay import ReplayResult, ReplaySettings
from .report import write_report
from .timeline import InputSettings

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
