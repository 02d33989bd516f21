# SPDX-License-Identifier: Apache-2.0
"""What each log says for calibration: its detector frames, heard or not, at the operating
points the node would have predicted for (`model.calibration.Observations`).

An input is a log (file, bag directory) or the output of an earlier replay (its directory or
its summary.json, e.g. of `replay` or of `review`'s per-log folders): a log is first replayed
with its sound, as `replay` does (`replay.replay`, the prior's nominal parameters without
scatter, into `<out>/replays/<name>/`; the clips are left in the annotated log only), so that
every input ends as a replay output, which is read the same way:

- the heard episodes from summary.json's `heard` (a replay without sound, or whose audio could
  not be read, gives the reason instead);
- one pass over the annotated log (which holds every input message as recorded): the operating
  point of every recompute, with the replay's own input settings and namespace (its
  `leadscrew_ros.replay` record; `timeline.Timeline`, the node's deadbands), and the first
  detector frame (`squeak/heard` is published at it);
- the detector frames, every `DetectorSettings.hop_s` from the first, for the audio's duration,
  heard where an episode covers them (`detection.frames_heard`, the episode's frequency);
- each frame takes the operating point in force (the latest recompute at or before it, as the
  node publishes), and counts as the replay's agreement counts it: inside the span of both
  the sound and the predictions, not within `listen.COLLAR_S` of a heard edge, and where the
  model is valid at that point (moving, below the critical speed);
- `thin` bins the frames to distinct operating points.

The unit is the log's `unit_id` (its `leadscrew_ros` metadata record, which the annotated log
carries), else the log's name; `by_unit` merges the logs of a unit. Everything that goes wrong
with one input is its reason (`Gathered.reason`), never an exception, never a number.
Per-input work runs as one Dask task each (`gather`), as `review` runs its logs.
"""

from __future__ import annotations

import glob
import json
import math
import shutil
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...bag import logmeta
from ...bag.logfile import LogError
from ...bag.logsource import open_log, topic_types
from ...model import ScrewParameters, SqueakModel, Validity
from ...model.acoustics.detection import Episode, frames_heard
from ...model.acoustics.settings import DetectorSettings
from ...model.calibration import Observations, ThinSettings, merge, thin
from ...model.uncertainty.scatter import Scatter
from ..fleet import find_logs, output_names
from ..listen import CLIPS_DIR, COLLAR_S, HEARD, SoundSettings, heard_status
from ..replay import ReplaySettings, log_name, replay
from ..timeline import InputSettings, Timeline

SUMMARY = "summary.json"
REPLAYS_DIR = "replays"  # in the calibration's output: one replay output per log
_ANNOTATED = "*.annotated.mcap"
# A squeak rings down at its mode's damping once the drive stops (zeta omega ~ 10 1/s at
# Table 1's first bending modes: 60 dB in ~0.7 s): motor-off frames count as the detector's
# false alarms only this long after the drive stopped [s].
RING_DOWN_S = 1.0


@dataclass(frozen=True)
class GatherSettings:
    """How the logs are replayed before they are read (replay outputs are read as they are).

    Attributes
    ----------
    params : ScrewParameters
        The replay's model (the prior's nominal parameters; no scatter: the replay is only
        the way to the heard frames).
    inputs : InputSettings
        Input topics and the node's deadbands.
    namespace : str or None
        Of the inputs; None: the log's one input namespace.
    listen : SoundSettings
        Where each log's sound is (a relative WAV file beside each log) and its scale.
    thin : ThinSettings
        The bins of distinct operating points.
    """

    params: ScrewParameters = field(default_factory=ScrewParameters)
    inputs: InputSettings = field(default_factory=InputSettings)
    namespace: str | None = None
    listen: SoundSettings = field(default_factory=SoundSettings)
    thin: ThinSettings = field(default_factory=ThinSettings)

    def __post_init__(self) -> None:
        ReplaySettings(self.inputs, self.namespace)  # checks the namespace


@dataclass
class Gathered:
    """One input, read: its observations, or why it has none.

    Attributes
    ----------
    source : str
        The input as found (log, or replay output directory).
    name : str
        Its output name (`<out>/replays/<name>/` for a log).
    log : str
        The log the observations come from.
    unit_id : str
        The unit ('' when the input could not be read far enough to know).
    observations : Observations or None
        Frames at distinct operating points; None when `reason`.
    reason : str
        Why there are no observations ('' when there are).
    heard_s : float
        Heard squeak in the frames counted [s].
    episodes : int
        Heard episodes of the replay.
    sound_share : float or None
        How much of the log was heard (`listen.Heard.sound_share`; None: no sound).
    """

    source: str
    name: str
    log: str
    unit_id: str
    observations: Observations | None
    reason: str = ""
    heard_s: float = 0.0
    episodes: int = 0
    sound_share: float | None = None


# ---------------------------------------------------------------------- finding the inputs
def is_replay_output(path: Path) -> bool:
    """A replay's output directory (it has summary.json) or its summary.json."""
    return (path.is_file() and path.name == SUMMARY) or (path / SUMMARY).is_file()


def find_inputs(paths: Iterable[str], skip: Path | str | None = None) -> list[tuple[Path, bool]]:
    """The inputs named by `paths`: (path, is a replay output) each once, in input order.

    Parameters
    ----------
    paths : iterable of str
        Logs, bag directories, folders, glob patterns, as `fleet.find_logs` takes them; and
        replay outputs (a directory with summary.json, or the file itself). In a folder, every
        directory with a summary.json is a replay output (its annotated log is not a log
        input) and every other log is a log.
    skip : path, optional
        A folder left out (the calibration's own output).

    Returns
    -------
    list of (Path, bool)
        Absolute paths (a replay output by its directory).

    Raises
    ------
    LogError
        A path that does not exist, a pattern that matches nothing.
    """
    skipped = Path(skip).resolve() if skip is not None else None
    found: dict[Path, bool] = {}
    for text in paths:
        matches = sorted(glob.glob(text, recursive=True)) if glob.has_magic(text) else [text]
        for p in map(Path, matches):
            if is_replay_output(p):
                found.setdefault((p.parent if p.is_file() else p).resolve(), True)
                continue
            outputs = ({s.parent.resolve() for s in p.rglob(SUMMARY)} if p.is_dir() else set()) - (
                {skipped} if skipped else set()
            )
            outputs = {o for o in outputs if skipped is None or not o.is_relative_to(skipped)}
            for log in find_logs([str(p)], skip):
                if not any(log.is_relative_to(o) for o in outputs):
                    found.setdefault(log, False)
            for o in sorted(outputs):
                found.setdefault(o, True)
    return list(found.items())


# ---------------------------------------------------------------------- one input
def _episodes(heard: dict[str, Any]) -> list[Episode]:
    """The heard episodes of summary.json (their frequency for every frame they cover), each
    from where the tracker took it (`Episode.tracked_start_s`): the hearing model's threshold
    is crossed by one rule at both ends. Started where the tone alone first stood the gate
    (the reported onset) but ended where the tracker lost it, the paper bench's reported
    damping intervals covered 11 of 16 units instead of 13."""
    return [
        Episode(
            e["start_s"] if e.get("tracked_start_s") is None else e["tracked_start_s"],
            e["end_s"],
            e["frequency_hz"],
            math.nan,
            math.nan,
            -math.inf,
        )
        for e in heard["episodes"]
    ]


def _rested(frame_t: np.ndarray, stands: np.ndarray) -> np.ndarray:
    """Frames where the drive stands and has stood for `RING_DOWN_S` (a squeak rings down at
    its mode's damping after the drive stops: there it is not the detector's false alarm)."""
    moving = np.where(~stands, frame_t, -np.inf)
    last = np.maximum.accumulate(moving) if moving.size else moving
    return stands & (frame_t - last >= RING_DOWN_S)


def _onsets(heard: dict[str, Any]) -> list[tuple[float, float, float]]:
    """(time [s], growth rate, its SE [1/s]) of the heard episodes whose onset growth was
    measured (summary.json's `growth_rate_per_s`, `growth_rate_se`), at the middle of the
    window it was fitted over: the rate is sigma's mean there, and sigma still rises at the
    detected onset, a few frames later."""
    out = []
    for e in heard["episodes"]:
        rate, se = e.get("growth_rate_per_s"), e.get("growth_rate_se")
        if rate is not None and se is not None:
            window = e.get("growth_window_s") or (e["start_s"], e["start_s"])
            out.append((0.5 * (float(window[0]) + float(window[1])), float(rate), float(se)))
    return out


def _detector(heard: dict[str, Any]) -> DetectorSettings:
    """The detector settings a replay heard with (its `heard.detector`; the defaults for a
    replay written before they were recorded)."""
    return DetectorSettings(**heard.get("detector", {}))


def _frame_times(first_s: float, heard: dict[str, Any]) -> np.ndarray:
    """The detector's frame centres [s]: from the first, every hop, for the audio's
    duration (`StreamingDetector`'s frame and hop in samples)."""
    d, rate = _detector(heard), float(heard["sample_rate_hz"])
    frame, hop = max(int(round(d.frame_s * rate)), 8), max(int(round(d.hop_s * rate)), 1)
    n = (int(round(heard["duration_s"] * rate)) - frame) // hop + 1
    return first_s + np.arange(max(n, 0)) * hop / rate


def counted(
    frame_t: np.ndarray, recompute_t: np.ndarray, end_s: float, episodes: list[Episode]
) -> np.ndarray:
    """Frames the replay's agreement counts: inside the span of the sound and of the
    predictions (first recompute to the end of the log), not within `COLLAR_S` of a heard
    episode's start or end."""
    if not frame_t.size or not recompute_t.size:
        return np.zeros(frame_t.shape, bool)
    ok = (frame_t >= recompute_t[0]) & (frame_t <= end_s)
    edges = np.sort([x for e in episodes for x in (e.start_s, e.end_s)])
    if edges.size:
        k = np.searchsorted(edges, frame_t)
        near = np.minimum(
            np.abs(frame_t - edges[np.maximum(k - 1, 0)]),
            np.abs(frame_t - edges[np.minimum(k, edges.size - 1)]),
        )
        ok &= near >= COLLAR_S
    return ok


def _pass(
    annotated: Path, params: ScrewParameters, inputs: InputSettings, heard_topic: str
) -> tuple[np.ndarray, float | None]:
    """One pass over the annotated log: the recomputes (time [s], speed, load, the nut the
    contact is integrated at) and the time of the first heard-flag message [s]."""
    source = open_log(annotated)
    timeline = Timeline(params, inputs, topic_types(source))
    rows: list[tuple[float, float, float, float]] = []
    first_heard: float | None = None
    for _, m in source.messages():
        job = timeline.feed(m, 0)
        if job is not None:
            rows.append(
                (timeline.seconds(job.clock_ns), job.speed_rad_s, job.load_n, job.model_nut_m)
            )
        elif first_heard is None and m.topic.name == heard_topic:
            first_heard = timeline.seconds(m.log_time_ns)
    return np.array(rows, float).reshape(-1, 4), first_heard


def observe_replay(
    directory: Path, name: str | None = None, settings: ThinSettings | None = None
) -> Gathered:
    """The observations of one replay output (the module's steps).

    Parameters
    ----------
    directory : Path
        A replay's output directory (summary.json and the annotated log).
    name : str, optional
        The input's name (default: the directory's).
    settings : ThinSettings, optional
        The bins of distinct operating points (default: their defaults).

    Returns
    -------
    Gathered
        With `observations`, or `reason` (no sound, audio not read, nothing counted, a file
        missing or unreadable).
    """
    directory = Path(directory)
    name = name or directory.name
    try:
        summary = json.loads((directory / SUMMARY).read_text(encoding="utf-8"))
        log = str(summary["log"])
        heard = summary["heard"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return Gathered(str(directory), name, str(directory), "", None, f"{SUMMARY}: {exc}")
    fallback = log_name(Path(log))
    if heard is None:
        status = heard_status(summary)
        why = " (no audio topic or WAV file)" if status == "no sound" else f": {status}"
        return Gathered(str(directory), name, log, fallback, None, f"no sound{why}")
    found = sorted(directory.glob(_ANNOTATED))
    if not found:
        return Gathered(
            str(directory), name, log, fallback, None, "no annotated log beside summary.json"
        )
    annotated = found[0]
    try:
        own = logmeta.read(annotated, logmeta.REPLAY_RECORD_NAME)
        recorded = logmeta.read(annotated)
        if own is None:
            raise ValueError(f"{annotated.name} has no '{logmeta.REPLAY_RECORD_NAME}' record")
        unit_id = (recorded.unit_id if recorded else "") or fallback
        params = own.screw_parameters()
        known = set(InputSettings.__dataclass_fields__)
        inputs = InputSettings(**{k: v for k, v in own.node.items() if k in known})
        points, first_s = _pass(
            annotated, params, inputs, f"{summary['out_namespace'].rstrip('/')}/{HEARD}"
        )
        episodes = _episodes(heard)
        frame_t = _frame_times(first_s if first_s is not None else 0.0, heard)
        use = counted(frame_t, points[:, 0], float(summary["duration_s"]), episodes)
        ok_sound = np.ones(frame_t.shape, bool)
        for a, b in heard.get("unusable_spans", []):  # no sound there: not an observation
            ok_sound &= (frame_t < a) | (frame_t > b)
        use &= ok_sound
        j = np.searchsorted(points[:, 0], frame_t, side="right") - 1
        at = points[np.maximum(j, 0)]
        model = SqueakModel(params, Scatter({}))
        code = model.validity_code(at[:, 1], at[:, 2])
        valid = (code == Validity.OK) & (j >= 0)
        use &= valid
        span = (j >= 0) & (frame_t <= float(summary["duration_s"]))
        flags, hz = frames_heard(frame_t, episodes)
        share = heard.get("sound_share")
        if not use.any():
            return Gathered(
                str(directory),
                name,
                log,
                unit_id,
                None,
                "no usable sound (NaN samples, gaps, a constant or silent microphone)"
                if share == 0
                else "no detector frame at a valid operating point (the drive never moved "
                "within the model's validity while the sound was recorded)",
                episodes=len(episodes),
                sound_share=share,
            )
        obs = thin(
            unit_id,
            (log,),
            frame_t[span],
            at[span, 1],
            at[span, 2],
            at[span, 3],
            flags[span],
            hz[span],
            _detector(heard).hop_s,
            settings,
            counted=use[span],
            valid=valid[span],
            onsets=_onsets(heard),
            motor_off=_rested(frame_t, code == Validity.BELOW_MIN_SPEED)[span] & ok_sound[span],
        )
    except (OSError, ValueError, LogError) as exc:
        return Gathered(str(directory), name, log, fallback, None, " ".join(str(exc).split()))
    hop = _detector(heard).hop_s
    return Gathered(
        str(directory),
        name,
        log,
        unit_id,
        obs,
        "",
        float(flags[use].sum() * hop),
        len(episodes),
        share,
    )


def gather_one(
    source: str, replayed: bool, out_dir: str, name: str, settings: GatherSettings
) -> Gathered:
    """One input (the body of a Dask task): a log is replayed with its sound into
    `<out_dir>/replays/<name>/` first; then `observe_replay`.

    Parameters
    ----------
    source : str
        The log, or a replay output directory (`replayed`).
    replayed : bool
        `source` is a replay output.
    out_dir : str
        The calibration's output directory.
    name : str
        The input's output name (`fleet.output_names`).
    settings : GatherSettings
        How a log is replayed.

    Returns
    -------
    Gathered
        Never an exception: what went wrong is its `reason`.
    """
    if replayed:
        return observe_replay(Path(source), name, settings.thin)
    log, out = Path(source), Path(out_dir) / REPLAYS_DIR / name
    try:
        shutil.rmtree(out, ignore_errors=True)
        replay(
            log,
            SqueakModel(settings.params, Scatter({})),
            out,
            ReplaySettings(
                settings.inputs,
                settings.namespace,
                workers=0,
                progress=False,
                listen=settings.listen.beside(log),
            ),
        )
        shutil.rmtree(out / CLIPS_DIR, ignore_errors=True)  # attachments of the annotated log
    except Exception as exc:  # any failure of this log is its reason
        return Gathered(source, name, source, "", None, " ".join(str(exc).split()))
    gathered = observe_replay(out, name, settings.thin)
    gathered.source = source
    return gathered


def gather(
    inputs: list[tuple[Path, bool]], out_dir: Path, settings: GatherSettings, client: Any
) -> list[Gathered]:
    """Every input, one Dask task each on the cluster of `client`, in input order.

    Parameters
    ----------
    inputs : list of (Path, bool)
        `find_inputs`.
    out_dir : Path
        The calibration's output directory.
    settings : GatherSettings
        How the logs are replayed.
    client : distributed.Client
        Of the cluster (`fleet.cluster`).

    Returns
    -------
    list of Gathered
    """
    names = output_names([p for p, _ in inputs])
    futures = [
        client.submit(gather_one, str(p), replayed, str(out_dir), n, settings, pure=False)
        for (p, replayed), n in zip(inputs, names, strict=True)
    ]
    out = []
    try:
        for (p, _), n, fut in zip(inputs, names, futures, strict=True):
            try:
                out.append(fut.result())
            except Exception as exc:  # the task did not finish (its workers died)
                out.append(Gathered(str(p), n, str(p), "", None, f"{type(exc).__name__}: {exc}"))
    except KeyboardInterrupt:  # nothing is kept between runs: a rerun starts over
        done = sum(f.done() for f in futures)
        raise KeyboardInterrupt(
            f"{done} of {len(inputs)} inputs gathered, nothing calibrated; a rerun starts over"
        ) from None
    return out


def by_unit(
    gathered: list[Gathered], settings: ThinSettings | None = None
) -> dict[str, tuple[list[Gathered], Observations | None, str]]:
    """The inputs grouped by unit (an input without a unit is its own, by name): per unit its
    inputs, the merged observations of those that have any (None if none has; `settings`: the
    bins they were thinned with) and the reasons of those that have none ('; '-joined), in
    order of first appearance."""
    units: dict[str, list[Gathered]] = {}
    for g in gathered:
        units.setdefault(g.unit_id or g.name, []).append(g)
    out = {}
    for unit, items in units.items():
        obs = [g.observations for g in items if g.observations is not None]
        reasons = "; ".join(f"{Path(g.log).name}: {g.reason}" for g in items if g.reason)
        out[unit] = (items, merge(obs, settings) if obs else None, reasons)
    return out
