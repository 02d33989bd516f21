# SPDX-License-Identifier: Apache-2.0
"""MCAP logs and CDR payloads without rclpy: reader and recovery, recorder, message
definitions, CDR encode and decode, synthetic logs. Imports `model` and `live` only."""
