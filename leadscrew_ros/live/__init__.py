# SPDX-License-Identifier: Apache-2.0
"""rclpy-free runtime: input rules, the live recompute policy and verdict, the seat-stroke
profile. Imports `model` only."""
