# SPDX-License-Identifier: Apache-2.0
"""rclpy-free runtime: input rules, the live recompute policy and verdict, listening to a
microphone, the seat-stroke profile. Imports `model` only."""

from ..model.exports import lazy

_HOMES = {
    "InputRules": "rules",
    "JointSettings": "settings",
    "ListenSettings": "settings",
    "Listener": "listen",
    "LivePredictor": "recompute",
    "LiveSettings": "settings",
    "StrokeProfile": "profile",
}
__all__ = [
    "InputRules",
    "JointSettings",
    "ListenSettings",
    "Listener",
    "LivePredictor",
    "LiveSettings",
    "StrokeProfile",
]


# Resolved on first use: the input rules (a replay's prediction worker) do not import the
# listener and through it the acoustics and scipy.signal (~0.5 s per process).
__getattr__ = lazy(__name__, _HOMES)
