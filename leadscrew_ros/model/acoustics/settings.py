# SPDX-License-Identifier: Apache-2.0
"""Settings of the squeak detector, declared once in field metadata (`physics.metadata`).

Why a 0.1 s frame: the detector decides on short-time spectra, so the frame length trades
frequency against time resolution. The smallest critical band of ECMA-418-1 (around 89-500 Hz)
is about 100 Hz wide; the Hann window's main lobe is 4 / frame_s wide (null to null), so a
0.1 s frame puts the tone's main lobe (40 Hz, 3 of the 10 Hz bins) well inside even the
narrowest band and leaves 7 or more bins of it to estimate the masking noise, as the TNR and PR
need. The frequency comes from a parabolic interpolation of the log power over the peak bin and
its two neighbours: its bias with a Hann window is below 0.06 bin (0.6 Hz), within +-2 % from
89 Hz on (1.8 Hz there). The frame still localises an onset to about its half length: with
`hop_s` 0.01 s the episode's start is within about 50 ms of the sound's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..physics.metadata import check, documented, setting


@documented
@dataclass(frozen=True)
class DetectorSettings:
    """How the bench microphone's sound is turned into squeak episodes (see the field
    metadata; times in s, frequencies in Hz, tolerances relative)."""

    frame_s: float = setting(
        0.1, "s", "analysis frame length (Hann window; 1 / frame_s is the bin spacing)", 0.02, 1.0
    )
    hop_s: float = setting(
        0.01,
        "s",
        "time between analysis frames (the detector's frame rate is 1 / hop_s)",
        0.001,
        0.5,
    )
    f_lo_hz: float = setting(
        89.1, "Hz", "lowest tone frequency considered (ECMA-418-1: 89.1 Hz)", 20.0, 20000.0
    )
    f_hi_hz: float = setting(
        11200.0,
        "Hz",
        "highest tone frequency considered (ECMA-418-1: 11.2 kHz; lowered "
        "automatically where the critical band would pass the Nyquist frequency)",
        20.0,
        40000.0,
    )
    track_tolerance: float = setting(
        0.02,
        "1",
        "a frame's tone joins a track within this relative distance of the track's "
        "running median frequency",
        0.001,
        0.2,
    )
    min_duration_s: float = setting(0.05, "s", "shortest squeak episode", 0.0, 60.0)
    max_gap_s: float = setting(
        0.03, "s", "gaps in a track shorter than this are bridged", 0.0, 10.0
    )
    order_tolerance: float = setting(
        0.02,
        "1",
        "a tone within this relative distance of r |speed| / 2 pi is at speed ratio r",
        0.0,
        0.2,
    )
    min_drive_ratio: float = setting(
        0.5,
        "1",
        "lowest ratio of a drive noise's frequency to the screw's rotation frequency",
        0.0,
        1e6,
        lo_open=True,
    )
    max_drive_ratio: float = setting(
        2000.0,
        "1",
        "highest ratio of a drive noise's frequency to the screw's rotation frequency "
        "(a geared motor's orders, its commutator: ratio x orders x segments)",
        0.0,
        1e6,
        lo_open=True,
    )
    drive_ratios: str = setting(
        "",
        "",
        "known ratios of drive noise to the screw's rotation frequency, comma-separated "
        "(e.g. '37.3, 74.6, 373'): tones at them are drive noise at constant speed too",
    )
    order_share: float = setting(
        0.75,
        "1",
        "a track follows ratio r when this share of its frames is within order_tolerance "
        "of r |speed| / 2 pi",
        0.0,
        1.0,
        lo_open=True,
    )
    max_peaks: int = setting(
        8,
        "1",
        "spectral peaks evaluated per frame before a background is learned (the largest TNR "
        "against its limit; and every peak within 3 dB of its limit); with one, every peak "
        "through its gate",
        1,
        64,
    )
    max_harmonic: int = setting(
        10,
        "1",
        "a tone at m times a simultaneous prominent tone (m = 2..this) and at most "
        "1.5 / m of its amplitude is its harmonic (clipping: 1 / m), not a squeak of its own",
        1,
        100,
    )
    max_tracks: int = setting(16, "1", "tone tracks followed at once (bounded memory)", 1, 256)
    max_episode_s: float = setting(
        60.0,
        "s",
        "a longer episode is closed and continued as a new one (bounded memory)",
        0.1,
        3600.0,
    )
    loudness_max_s: float = setting(
        2.0,
        "s",
        "loudness over the episode, or over its last this many seconds (0: no "
        "loudness); ISO 532-1 runs at about real time",
        0.0,
        60.0,
    )
    clip_level: float = setting(
        0.999,
        "1",
        "samples at or beyond this share of full scale count as clipped",
        0.0,
        1.0,
        lo_open=True,
    )
    motor_off_rad_s: float = setting(
        1.0,
        "rad/s",
        "the drive is at rest below this |speed|: what sounds then is background "
        "(model.acoustics.background)",
        0.0,
        1e4,
    )
    motor_off_min_s: float = setting(
        0.5, "s", "rest this long before its sound is learned as background", 0.0, 60.0
    )
    background_share: float = setting(
        0.2,
        "1",
        "a tone held by at least this share of the rest frames is a background tone",
        0.0,
        1.0,
        lo_open=True,
    )
    background_snr_db: float = setting(
        10.0,
        "dB",
        "with a background learned, a squeak candidate is a tone this far over the "
        "background's third-octave band at its frequency (before: ECMA-418-1 prominence)",
        -60.0,
        60.0,
    )
    background_infer_share: float = setting(
        0.5,
        "1",
        "offline (replay, listen), without motor-off time or a background recording: a tone "
        "held by more than this share of the frames (on each side of the prediction, when "
        "there is one) at a steady level is inferred as background",
        0.0,
        1.0,
        lo_open=True,
    )
    background_level_sd_db: float = setting(
        3.0,
        "dB",
        "a steady level (background_infer_share): the standard deviation of the tone's "
        "level over the frames holding it at most this",
        0.0,
        60.0,
    )
    background_margin_db: float = setting(
        6.0,
        "dB",
        "a tone at a background tone's frequency is squeak only when its mean level is "
        "more than this above the background tone's",
        0.0,
        60.0,
    )

    creak_pulse_db: float = setting(
        10.0,
        "dB",
        "a creak's pulse stands this far over the floor level (between pulses) of the high-passed "
        "sound, and falls back as far within 20 ms (model.acoustics.creak)",
        3.0,
        60.0,
    )
    creak_min_pulses: int = setting(
        10,
        "1",
        "pulses in a train before it is a creak (stick-slip noise; a squeak's reverberant "
        "tail on a realistic bench made trains of 7)",
        3,
        1000,
    )
    creak_min_rate_hz: float = setting(
        5.0, "Hz", "lowest pulse rate of a creak: longer pauses end a train", 0.1, 1000.0
    )
    creak_max_rate_hz: float = setting(
        200.0,
        "Hz",
        "highest pulse rate of a creak: pulses closer than its interval are one",
        1.0,
        5000.0,
    )
    creak_highpass_hz: float = setting(
        400.0,
        "Hz",
        "creak pulses are found in the sound above this frequency (away from hum and the "
        "drive's low orders)",
        20.0,
        20000.0,
    )

    def __post_init__(self) -> None:
        check(self)
        _ = self.known_ratios  # a malformed list is refused here
        if self.hop_s > self.frame_s:
            raise ValueError(f"hop_s = {self.hop_s:g} exceeds frame_s = {self.frame_s:g}")
        if self.f_lo_hz >= self.f_hi_hz:
            raise ValueError(f"f_lo_hz = {self.f_lo_hz:g} is not below f_hi_hz = {self.f_hi_hz:g}")
        if self.creak_min_rate_hz >= self.creak_max_rate_hz:
            raise ValueError(
                f"creak_min_rate_hz = {self.creak_min_rate_hz:g} is not below "
                f"creak_max_rate_hz = {self.creak_max_rate_hz:g}"
            )
        if self.min_drive_ratio > self.max_drive_ratio:
            raise ValueError(
                f"min_drive_ratio = {self.min_drive_ratio:g} exceeds max_drive_ratio = "
                f"{self.max_drive_ratio:g}"
            )

    @property
    def known_ratios(self) -> tuple[float, ...]:
        """`drive_ratios` as numbers.

        Raises
        ------
        ValueError
            An item is not a positive number.
        """
        out = []
        for item in self.drive_ratios.replace(";", ",").split(","):
            if not item.strip():
                continue
            try:
                r = float(item)
            except ValueError:
                r = math.nan
            if not (math.isfinite(r) and r > 0):
                raise ValueError(f"drive_ratios: {item.strip()!r} is not a positive number")
            out.append(r)
        return tuple(out)
