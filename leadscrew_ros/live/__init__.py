# SPDX-License-Identifier: Apache-2.0
"""rclpy-free runtime: input rules, the live recompute policy and verdict, the seat-stroke
profile. Imports `model` only."""

from .profile import StrokeProfile
from .recompute import LivePredictor
from .rules import InputRules
from .settings import JointSettings, LiveSettings

__all__ = ["InputRules", "JointSettings", "LivePredictor", "LiveSettings", "StrokeProfile"]
