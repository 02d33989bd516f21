# SPDX-License-Identifier: Apache-2.0
"""rclpy-free runtime: input rules, the live recompute policy and verdict, listening to a
microphone, the seat-stroke profile. Imports `model` only."""

from .listen import Listener
from .profile import StrokeProfile
from .recompute import LivePredictor
from .rules import InputRules
from .settings import JointSettings, ListenSettings, LiveSettings

__all__ = [
    "InputRules",
    "JointSettings",
    "ListenSettings",
    "Listener",
    "LivePredictor",
    "LiveSettings",
    "StrokeProfile",
]
