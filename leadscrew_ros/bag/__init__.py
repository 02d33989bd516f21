# SPDX-License-Identifier: Apache-2.0
"""MCAP logs and CDR payloads without rclpy: reader and recovery, recorder, message
definitions, CDR encode and decode, synthetic logs. Imports `model` and `live` only."""

from .logfile import LogError, recover
from .logsource import LogSource, open_log
from .recorder import Recorder, RecordSettings

__all__ = ["LogError", "LogSource", "RecordSettings", "Recorder", "open_log", "recover"]
