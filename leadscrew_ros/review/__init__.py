# SPDX-License-Identifier: Apache-2.0
"""Offline review of logs without rclpy: operating-point timeline, replay, episodes, report
plots. Imports `model`, `live` and `bag` only."""
