# SPDX-License-Identifier: Apache-2.0
"""The bench microphone: ECMA-418-1 tone prominence on short-time spectra (`tonality`), squeak
episodes that do not follow the motor orders, offline and streaming (`detection`), agreement
of predictions with what was heard (`agreement`), and a simulated microphone (`synthesis`).
The function `agreement` is not re-exported: `acoustics.agreement` stays the module of that
name. numpy/scipy only; MOSQITO (loudness) is imported only when a calibrated episode needs it.
"""

from .agreement import Agreement, FrequencyMatch
from .detection import AudioError, Detection, Episode, StreamingDetector, detect, frames_heard
from .settings import DetectorSettings
from .synthesis import microphone
from .tonality import pr_limit_db, tnr_limit_db

__all__ = [
    "Agreement",
    "AudioError",
    "Detection",
    "DetectorSettings",
    "Episode",
    "FrequencyMatch",
    "StreamingDetector",
    "detect",
    "frames_heard",
    "microphone",
    "pr_limit_db",
    "tnr_limit_db",
]
