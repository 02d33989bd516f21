# SPDX-License-Identifier: Apache-2.0
"""Listening, free of rclpy: the node's microphone analysed off the executor thread, and the
measurement status that compares what was heard with what was predicted.

The node's microphone callback only hands the chunk over (`Listener.offer`: the payload, its
arrival time and how to decode it) to a bounded queue; a chunk that finds the queue full is
dropped and counted, so a callback never waits. One worker thread decodes each chunk and
pushes it into a `model.acoustics.StreamingDetector` with the latest motor speed (so that tones
following the motor orders are rejected). A chunk carries no usable time of its own, so the
sound is placed on the node's monotonic clock: a chunk continues the previous one (samples
counted, arrival jitter ignored) unless chunks were dropped before it, or its arrival time says
it started more than `RESYNC_S` after the previous one ended (a gap: the microphone paused) or
the sound runs more than `AHEAD_S` ahead of the clock (chunks faster than real time; a burst
delivered late after a stall stays contiguous); then it starts at its arrival time minus its
duration (the detector closes its tracks and restarts framing).

Per analysed chunk the worker queues what the detector hears at its latest frame
(`StreamingDetector.heard_now`, `frequency_now_hz`: provisional, before the episode is decided)
for `Listener.collect`, which the node calls from its housekeeping timer: it updates the heard
state (squeak/heard, squeak/heard_frequency) and compares each chunk with the prediction in force
at its time (`Listener.predicted`, recorded by the node after every recompute).

The measurement status (`Listener.status`) judges the last `window_s` of analysed sound,
ending at its latest frame E: the detector needs `delay_s` (a frame, the shortest episode, a
bridged gap and a chunk) before it hears a squeak that has begun, so a squeak predicted only in
its last `delay_s` is not yet expected to be heard, and a prediction up to `delay_s` before the
window still counts for a squeak heard in it:

- WARN "heard squeak at F Hz, none predicted": a squeak heard in [E - window_s, E] and none
  predicted in [E - window_s - delay_s, E];
- WARN "predicted squeak (P p), none heard": a squeak predicted in [E - window_s,
  E - delay_s] (the prediction in force at the start counts) and none heard in the window;
- OK otherwise: both squeak, or neither;
- STALE when no chunk arrived for `window_s`, or none has been analysed yet.

Chunks dropped (or malformed) during the window raise the level to WARN with their count.
"""

from __future__ import annotations

import math
import queue
import threading
from collections import deque
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from ..model import Prediction
from ..model.acoustics.agreement import MATCH_TOLERANCE, nearest_mode
from ..model.acoustics.detection import StreamingDetector
from ..model.acoustics.settings import DetectorSettings
from .settings import ListenSettings
from .status import Level, Status, value_text

#: A chunk that starts this much after the end of the previous one starts a new segment [s].
RESYNC_S = 0.25
#: The sound may run this far ahead of the chunks' arrival times before it is put back [s].
AHEAD_S = 2.0
_MAX_PREDICTIONS = 100_000  # predictions kept for the comparison (also trimmed by time)

# Key names of the measurement diagnostic status (`Listener.status`).
KEY_HEARD = "heard"  # "true" while the detector hears a squeak
KEY_HEARD_FREQUENCY = "heard_frequency_hz"  # its frequency, '' when none
KEY_PREDICTED = "predicted"  # "true" while the prediction in force squeaks
KEY_WINDOW_AGREEMENT = "window_agreement"  # share of the window heard == predicted
KEY_HEARD_S = "heard_s"  # time heard in squeak since the start [s]
KEY_PREDICTED_S = "predicted_s"  # time predicted in squeak, same sound [s]
KEY_AGREEMENT = "agreement"  # share of the analysed sound heard == predicted
KEY_ANALYSED_S = "analysed_s"  # sound analysed since the start [s]
KEY_HEARD_MODES = "heard_modes"  # heard frequencies by predicted mode
KEY_CHUNKS = "chunks"  # chunks received
KEY_DROPPED = "dropped_chunks"  # chunks dropped: the analysis could not keep up
KEY_MALFORMED = "malformed_chunks"  # chunks that did not decode
KEY_DETECTOR_WARNING = "detector_warning"  # the detector's latest warning ('' when none)
KEY_UNUSABLE_S = "unusable_s"  # sound without usable samples (NaN, constant), not scored [s]
KEY_BACKGROUND = "background_hz"  # the tones learned while the drive rested [Hz], ', '-joined
KEY_DRIVE_ORDERS = "drive_ratios"  # the speed ratios the drive was heard at, ', '-joined

#: How a chunk's payload becomes samples: (samples in full scale, sample rate [Hz] or None for
#: `ListenSettings.sample_rate_hz`); ValueError when it is malformed.
Decoder = Callable[[bytes], tuple[np.ndarray, "float | None"]]


SPEED_HISTORY = 4096  # speed inputs kept for the detector (4 s at 1 kHz)
#: The sound's own pace is judged over this much arrival time [s] (arrival jitter of tens of
#: ms is then under 1 %) ...
RATE_CHECK_S = 4.0
#: ... and a pace this far off the analysed sample rate is a mismatch: 48 kHz analysed as
#: 44.1 kHz is 8.8 % off, audio replayed at another speed more.
RATE_TOLERANCE = 0.03


class _Chunk(NamedTuple):
    arrival: float  # monotonic time the callback got it [s]
    payload: bytes
    decode: Decoder
    dropped_before: int  # chunks dropped before this one was queued


class Heard(NamedTuple):
    """What the detector heard at the latest frame of one analysed chunk.

    Attributes
    ----------
    time_s : float
        Centre of the chunk's latest frame, on the node's monotonic clock [s].
    duration_s : float
        The chunk's duration [s]: the sound this entry stands for.
    heard : bool
        A squeak is heard (`StreamingDetector.heard_now`).
    frequency_hz : float
        Its frequency, nan when none [Hz].
    """

    time_s: float
    duration_s: float
    heard: bool
    frequency_hz: float


class Predicted(NamedTuple):
    """A prediction as the measurement compares it (in force from `time_s` on).

    Attributes
    ----------
    time_s : float
        When it was made, node monotonic clock [s].
    squeak : bool
        A mode squeaks at the nominal parameters (no prediction: False).
    probability : float or None
        P(squeak), None without a prediction.
    modes : tuple of (str, float)
        The squeaking modes: label and frequency [Hz].
    """

    time_s: float
    squeak: bool
    probability: float | None
    modes: tuple[tuple[str, float], ...]


class Listener:
    """The microphone analysis of the node: a bounded queue, a worker thread with a
    `StreamingDetector`, and the measurement verdict (see the module notes).

    Parameters
    ----------
    settings : ListenSettings
        Sample rate, window, calibration and queue length.
    detector : DetectorSettings
        The detector's settings.

    Raises
    ------
    model.acoustics.AudioError
        An invalid sample rate or scale.

    Attributes
    ----------
    speed_rad_s : float or None
        The latest motor speed [rad/s] (`note_speed`); the speed of a chunk when no history is
        noted.
    received, dropped, malformed, analysed : int
        Chunks received, dropped because the queue was full, that did not decode, and
        analysed.
    heard : bool
        The heard state after the latest `collect`.
    frequency_hz : float
        Its frequency, nan when nothing is heard [Hz].
    """

    def __init__(self, settings: ListenSettings, detector: DetectorSettings = DetectorSettings()):
        self.settings, self.detector_settings = settings, detector
        self._detector = StreamingDetector(
            detector, settings.sample_rate_hz, settings.scale_pa or None
        )
        self._queue: queue.Queue[_Chunk] = queue.Queue(maxsize=settings.queue_chunks)
        self.speed_rad_s: float | None = None
        # (monotonic time, speed) of the recent speed inputs: the detector interpolates them at
        # its frames, so that a motor order stays an order while the speed ramps
        self._speeds: deque[tuple[float, float]] = deque(maxlen=SPEED_HISTORY)
        self.received = self.dropped = self.malformed = self.analysed = 0
        self.last_arrival: float | None = None
        self._last_drop = self._last_malformed = self._last_unusable = -math.inf
        # worker: (arrival [s], samples) of the recent chunks, and the pace found off the rate
        self._paces: deque[tuple[float, int]] = deque()
        self.pace: tuple[float, float, float] | None = None  # (samples/s, rate, when) if off
        # worker -> status: what the detector learned of the room and the drive (replaced whole)
        self.background_hz: tuple[float, ...] = ()
        self.drive_ratios: tuple[float, ...] = ()
        self.unusable_s = 0.0  # sound received that held nothing to analyse [s]
        self.error = ""  # why the latest malformed chunk was
        self.warning = ""  # the detector's latest warning
        # worker thread -> collect (deque appends and pops are atomic)
        self._analysed: deque[Heard] = deque()
        self._audio_end: float | None = None  # worker: where the last chunk ended
        self._seen_dropped = 0
        self._chunk_s = 0.0  # worker: duration of the last chunk
        # collect and status (the node's executor thread)
        self._window: deque[tuple[Heard, bool]] = deque()
        self._predictions: deque[Predicted] = deque(maxlen=_MAX_PREDICTIONS)
        self.heard, self.frequency_hz = False, math.nan
        self._analysed_s = self._heard_s = self._predicted_s = self._agree_s = 0.0
        self._modes: dict[str, list[float]] = {}  # label ('' unmatched) -> [s, s * Hz]
        self._closed = False
        self._thread = threading.Thread(target=self._run, daemon=True, name="squeak listening")
        self._thread.start()

    @property
    def backlog(self) -> int:
        """Chunks received and not yet analysed (nor dropped or found malformed)."""
        return self.received - self.dropped - self.malformed - self.analysed

    @property
    def delay_s(self) -> float:
        """How long after a squeak begins the detector is expected to hear it [s]."""
        s = self.detector_settings
        return s.frame_s + s.min_duration_s + s.max_gap_s + self._chunk_s

    # ---------------------------------------------------------------- executor thread
    def offer(self, payload: bytes, now: float, decode: Decoder) -> None:
        """Queue a chunk for the analysis (the microphone callback); drop and count it when
        the queue is full. Never blocks.

        Parameters
        ----------
        payload : bytes
            The message as received (e.g. its CDR bytes).
        now : float
            Arrival time, node monotonic clock [s].
        decode : Decoder
            Turns `payload` into samples (called on the worker thread).
        """
        self.received += 1
        self.last_arrival = now
        try:
            self._queue.put_nowait(_Chunk(now, payload, decode, self.dropped))
        except queue.Full:
            self.dropped += 1
            self._last_drop = now

    def predicted(self, now: float, p: Prediction | None) -> None:
        """Record the prediction in force from `now` on.

        Parameters
        ----------
        now : float
            When it was made, node monotonic clock [s].
        p : Prediction or None
            The prediction; None: none (outside the model's validity, inputs missing).
        """
        if p is None:
            self._predictions.append(Predicted(now, False, None, ()))
        else:
            self._predictions.append(
                Predicted(
                    now,
                    bool(p.squeak_modes),
                    p.probability,
                    tuple((m.label, m.frequency_hz) for m in p.squeak_modes),
                )
            )

    def take_over(self, old: Listener) -> None:
        """Continue from another listener (closed, e.g. for new settings).

        Parameters
        ----------
        old : Listener
            Its latest speed and the predictions it kept are taken; its sound and totals
            are not.
        """
        self.speed_rad_s = old.speed_rad_s
        self._speeds.extend(old._speeds)
        self._predictions.extend(old._predictions)

    def note_speed(self, now: float, speed_rad_s: float | None) -> None:
        """A motor speed input at the node's monotonic time `now` (the clock chunks are placed
        on).

        Parameters
        ----------
        now : float
            Monotonic time of the input [s].
        speed_rad_s : float or None
            The accepted motor speed [rad/s] (None before one).
        """
        self.speed_rad_s = speed_rad_s
        if speed_rad_s is not None:
            self._speeds.append((now, float(speed_rad_s)))

    def collect(self) -> bool:
        """Take what the worker analysed: heard state, totals, window.

        Returns
        -------
        bool
            The heard state changed (squeak/heard, or its frequency to 0.1 Hz).
        """
        before = (self.heard, _rounded(self.frequency_hz))
        while self._analysed:
            h = self._analysed.popleft()
            p = self._prediction_at(h.time_s)
            squeak = p is not None and p.squeak
            self._analysed_s += h.duration_s
            self._heard_s += h.duration_s * h.heard
            self._predicted_s += h.duration_s * squeak
            self._agree_s += h.duration_s * (h.heard == squeak)
            if h.heard:
                label = _matched_label(h.frequency_hz, p.modes if p is not None else ())
                acc = self._modes.setdefault(label, [0.0, 0.0])
                acc[0] += h.duration_s
                acc[1] += h.duration_s * h.frequency_hz
            self._window.append((h, squeak))
            self.heard, self.frequency_hz = h.heard, h.frequency_hz
        if self._window:
            end = self._window[-1][0].time_s
            start = end - self.settings.window_s - self.delay_s
            while self._window[0][0].time_s < start:
                self._window.popleft()
            while len(self._predictions) > 1 and self._predictions[1].time_s <= start:
                self._predictions.popleft()
        return (self.heard, _rounded(self.frequency_hz)) != before

    def _prediction_at(self, t: float) -> Predicted | None:
        """The prediction in force at `t` (the latest at or before it), None before any."""
        for p in reversed(self._predictions):
            if p.time_s <= t:
                return p
        return None

    def _predicted_during(self, lo: float, hi: float) -> list[Predicted]:
        """The squeak predictions in force at some time in [lo, hi]."""
        out = []
        for p in reversed(self._predictions):
            if p.time_s <= hi and p.squeak:
                out.append(p)
            if p.time_s <= lo:
                break
        return out

    def status(self, now: float) -> Status:
        """The measurement verdict (module notes) with its key-values.

        Parameters
        ----------
        now : float
            Node monotonic time [s].

        Returns
        -------
        Status
        """
        w = self.settings.window_s
        end = self._window[-1][0].time_s if self._window else math.inf
        window = [(h, squeak) for h, squeak in self._window if h.time_s >= end - w]
        values = {
            KEY_HEARD: str(self.heard).lower(),
            KEY_HEARD_FREQUENCY: value_text(self.frequency_hz if self.heard else None),
            KEY_PREDICTED: str(bool(window and window[-1][1])).lower(),
            KEY_WINDOW_AGREEMENT: value_text(
                _share(
                    sum(h.duration_s for h, s in window if h.heard == s),
                    sum(h.duration_s for h, _ in window),
                )
            ),
            KEY_HEARD_S: f"{self._heard_s:.3f}",
            KEY_PREDICTED_S: f"{self._predicted_s:.3f}",
            KEY_AGREEMENT: value_text(_share(self._agree_s, self._analysed_s)),
            KEY_ANALYSED_S: f"{self._analysed_s:.3f}",
            KEY_HEARD_MODES: self.heard_modes(),
            KEY_CHUNKS: str(self.received),
            KEY_DROPPED: str(self.dropped),
            KEY_MALFORMED: str(self.malformed),
            KEY_DETECTOR_WARNING: self.warning,
            KEY_UNUSABLE_S: f"{self.unusable_s:.3f}",
            KEY_BACKGROUND: ", ".join(f"{f:.0f}" for f in self.background_hz),
            KEY_DRIVE_ORDERS: ", ".join(f"{r:.4g}" for r in self.drive_ratios),
        }
        if self.last_arrival is None:
            level, message = Level.STALE, "no sound received yet"
        elif now - self.last_arrival > w:
            level, message = Level.STALE, f"no sound for {now - self.last_arrival:.1f} s"
        elif not window:
            level, message = Level.STALE, "no sound analysed yet"
        else:
            level, message = self._verdict(window)
        notes = []
        if now - self._last_drop <= w:
            notes.append(f"{self.dropped} chunk(s) dropped in all: the analysis cannot keep up")
        if now - self._last_malformed <= w:
            notes.append(f"{self.malformed} malformed chunk(s) in all ({self.error})")
        if self.pace is not None and now - self.pace[2] <= w:
            pace, rate, _ = self.pace
            notes.append(
                f"the sound arrives at {pace:.0f} samples/s but is analysed at {rate:.0f} Hz "
                "(a wrong listen.sample_rate_hz, or audio replayed at another speed): its "
                "frequencies and times are wrong"
            )
        if now - self._last_unusable <= w:
            notes.append(
                f"no usable sound ({self.unusable_s:.1f} s in all: NaN samples, or a constant "
                "or silent signal, a muted microphone?): not scored"
            )
        if notes:
            level, message = max(level, Level.WARN), "; ".join([message, *notes])
        return Status(level, message, values)

    def _verdict(self, window: list[tuple[Heard, bool]]) -> tuple[Level, str]:
        end, w, d = window[-1][0].time_s, self.settings.window_s, self.delay_s
        heard = [h for h, _ in window if h.heard]
        if heard:
            f = heard[-1].frequency_hz
            early = self._predicted_during(end - w - d, end)
            if not early:
                return Level.WARN, f"heard squeak at {f:.0f} Hz, none predicted"
            modes = [m for p in early for m in p.modes]
            label = _matched_label(f, modes)
            match = [m for m in modes if m[0] == label]
            what = f" ({label} {match[0][1]:.0f} Hz)" if match else ""
            return Level.OK, f"heard squeak at {f:.0f} Hz, predicted{what}"
        late = self._predicted_during(end - w, end - d)
        if late:
            p = max((q.probability for q in late if q.probability is not None), default=None)
            shown = "" if p is None else f" (P {p:.2f})"
            return Level.WARN, f"predicted squeak{shown}, none heard"
        return Level.OK, "no squeak heard, none predicted"

    def heard_modes(self) -> str:
        """The squeak heard since the start, by predicted mode.

        Returns
        -------
        str
            Longest first, e.g. 'T1 2653 Hz 4.50 s' ('unpredicted' for a frequency that no
            predicted mode matched within `agreement.MATCH_TOLERANCE`); '' when nothing was
            heard.
        """
        parts = [
            f"{label or 'unpredicted'} {hz_s / s:.0f} Hz {s:.2f} s"
            for label, (s, hz_s) in sorted(self._modes.items(), key=lambda kv: -kv[1][0])
        ]
        return ", ".join(parts)

    def close(self, timeout: float = 2.0) -> None:
        """Stop the worker thread; what is still queued is not analysed.

        Parameters
        ----------
        timeout : float
            Longest wait for the thread to end [s] (a chunk being analysed finishes first).
        """
        self._closed = True
        while True:  # make room for the wake-up
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break
        try:
            self._queue.put_nowait(None)  # type: ignore[arg-type]
        except queue.Full:
            pass
        self._thread.join(timeout)

    # ---------------------------------------------------------------- worker thread
    def _run(self) -> None:
        while not self._closed:
            chunk = self._queue.get()
            if chunk is None or self._closed:
                return
            self._analyse(chunk)

    def _analyse(self, chunk: _Chunk) -> None:
        det = self._detector
        try:
            samples, rate = chunk.decode(chunk.payload)
            rate = det.sample_rate_hz if rate is None else float(rate)
            n = int(np.shape(samples)[0]) if np.ndim(samples) else 0
            if n == 0:
                raise ValueError("no samples")
            duration = n / rate
            start = chunk.arrival - duration
            if (
                self._audio_end is None
                or chunk.dropped_before != self._seen_dropped
                or not -AHEAD_S <= start - self._audio_end <= RESYNC_S
            ):
                t0 = start
            else:
                t0 = self._audio_end
            speeds = list(self._speeds)  # a snapshot: the node appends from its own thread
            if speeds:
                times, values = np.array(speeds).T
                closed = det.push(samples, t0, values, speed_times_s=times, sample_rate_hz=rate)
                det.learn_held(closed, times, values)  # the drive's tones heard only held
            else:
                det.push(samples, t0, self.speed_rad_s, sample_rate_hz=rate)
        except ValueError as exc:  # malformed payload, or a sample rate refused
            self.malformed += 1
            self.error = str(exc)
            self._last_malformed = chunk.arrival
            return
        self._check_pace(chunk, n, rate)
        self.background_hz = tuple(t.frequency_hz for t in det.background.tones())
        self.drive_ratios = tuple(o.ratio for o in det.drive_orders)
        self._seen_dropped = chunk.dropped_before
        self._audio_end, self._chunk_s = t0 + duration, duration
        if det.warnings:
            self.warning = det.warnings[-1]
        if det.frames_done and not det.usable_now:  # NaN or a muted microphone: not scored
            self.unusable_s += duration
            self._last_unusable = chunk.arrival
        elif det.frames_done:
            latest = float(det.frame_time(det.frames_done - 1))
            self._analysed.append(Heard(latest, duration, det.heard_now, det.frequency_now_hz))
        self.analysed += 1

    def _check_pace(self, chunk: _Chunk, n: int, rate: float) -> None:
        """Compare the samples arriving per second with the rate they are analysed at, over
        the last `RATE_CHECK_S` of arrivals without a dropped chunk (worker thread)."""
        if chunk.dropped_before != self._seen_dropped:
            self._paces.clear()
        paces = self._paces
        paces.append((chunk.arrival, n))
        while paces[0][0] < chunk.arrival - RATE_CHECK_S:
            paces.popleft()
        span = paces[-1][0] - paces[0][0]
        if span < 0.75 * RATE_CHECK_S:
            return
        pace = sum(k for _, k in list(paces)[1:]) / span  # samples after the first arrival
        if abs(pace / rate - 1.0) > RATE_TOLERANCE:
            self.pace = (pace, rate, chunk.arrival)


def _rounded(f: float) -> float | None:
    return None if math.isnan(f) else round(f, 1)


def _share(part: float, whole: float) -> float | None:
    return part / whole if whole > 0 else None


def _matched_label(f: float, modes: Sequence[tuple[str, float]]) -> str:
    """Label of the mode nearest to `f` if it matches (`agreement.nearest_mode`), '' if none."""
    best = nearest_mode(f, modes)
    return best[0] if best is not None and abs(best[1] - f) <= MATCH_TOLERANCE * f else ""
