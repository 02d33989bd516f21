# SPDX-License-Identifier: Apache-2.0
"""Fleet review: many logs, each replayed offline as one Dask task, into one report.

logs (files, bag directories, folders searched recursively, globs: `find_logs`) -> unique,
deterministic output names (`output_names`) -> the resume index of the output directory skips
the logs reviewed before with the same content and parameters -> one task per log on a Dask
cluster (`cluster`: a `distributed.LocalCluster` on 127.0.0.1, one thread per worker process, or
a running scheduler): `review_one` opens the log inside the task and runs the same
`replay.replay` as the `replay` command (and its report) into `<out>/<name>/` -> results
gathered as they finish with a bounded number in flight (the client's memory does not grow with
the number of logs) -> `fleetreport`: fleet.csv, fleet.json, fleet.png.

Failure isolation: every exception of a log's review is its error row (one line); a worker that
dies takes its tasks with it, the scheduler runs them on another worker (up to its
`distributed.scheduler.allowed-failures`), after that the log is an error row too and is
reviewed again by the next run into the same directory.

Resume: `<out>/review-index.jsonl` holds one line per reviewed log (appended as each finishes,
so an interrupted review keeps what it did): its path, output name, files' sizes and
modification times, content hash (BLAKE2b of the files' bytes), parameters hash and its row.
A log whose files' sizes and times are unchanged, whose parameters hash is the same and whose
summary is still there is skipped without reading; one whose files changed in size or time is
hashed in its task and skipped there if the content is the same.
"""

from __future__ import annotations

import asyncio
import contextlib
import glob
import hashlib
import json
import logging
import math
import re
import shutil
import signal
import statistics
import threading
import time
import uuid
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..bag import logmeta
from ..bag.logfile import LogError, is_complete, recover
from ..bag.logsource import DB3, open_log, sidecars
from ..model import ScrewParameters, SqueakModel
from ..model.physics.metadata import check, setting
from ..model.uncertainty.scatter import LIVE_SAMPLES, Scatter
from .decimation import Reservoir
from .jsonsafe import json_safe
from .listen import CLIPS_DIR, SoundSettings, heard_status
from .progress import progress_bar
from .replay import ReplayResult, ReplaySettings, log_name, replay
from .timeline import InputSettings, input_parameters

INDEX_FILE = "review-index.jsonl"
RECOVERED_DIR = "recovered"  # in a log's outputs: the readable copy of a cut-off recording
POINTS_PER_LOG = 64  # squeak points (speed, load, frequency) a log adds to fleet.png
IN_FLIGHT_PER_THREAD = 2  # tasks submitted per worker thread ahead of the results
MIN_IN_FLIGHT = 4
_SUFFIXES = (".mcap", DB3)
_GLOB = re.compile(r"[*?[]")
_HASH_BLOCK = 1 << 20


@dataclass(frozen=True)
class FleetSettings:
    """What every log of a review is replayed with.

    Attributes
    ----------
    params : ScrewParameters
        Model parameters for every log (unless `use_log_params`).
    scatter : dict
        Scattered parameter -> relative SD behind P(squeak).
    samples : int
        Scatter samples of P(squeak).
    inputs : InputSettings
        Input topics, deadbands and P(squeak) thresholds for every log.
    input_options : dict
        The `InputSettings` fields given on the command line: with `use_log_params` they
        override the log's recorded node parameters.
    namespace : str or None
        Namespace of the inputs (None: each log's own).
    out_namespace : str or None
        Namespace of the predictions in the annotated logs.
    use_log_params : bool
        Each log with the model parameters, scatter and input settings of its `leadscrew_ros`
        metadata record; a log without one is an error row.
    report : bool
        Write each log's PNG report.
    summary_only : bool
        Keep only summary.json and summary.txt of each log.
    listen : SoundSettings
        Where each log's sound is (a relative WAV file beside each log) and its scale.
    """

    params: ScrewParameters = field(default_factory=ScrewParameters)
    scatter: dict[str, float] = field(default_factory=lambda: dict(Scatter().sd))
    samples: int = LIVE_SAMPLES
    inputs: InputSettings = field(default_factory=InputSettings)
    input_options: dict[str, Any] = field(default_factory=dict)
    namespace: str | None = None
    out_namespace: str | None = None
    use_log_params: bool = False
    report: bool = True
    summary_only: bool = False
    listen: SoundSettings = field(default_factory=SoundSettings)

    def __post_init__(self) -> None:
        ReplaySettings(self.inputs, self.namespace, self.out_namespace)  # checks the names
        Scatter(self.scatter)

    def as_dict(self) -> dict[str, Any]:
        """Everything the results depend on (the run's parameters in fleet.json).

        Returns
        -------
        dict
            JSON-ready.
        """
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["params"] = self.params.as_dict()
        out["inputs"] = asdict(self.inputs)
        out["listen"] = asdict(self.listen)
        out["package_version"] = __version__
        return json_safe(out)

    def digest(self) -> str:
        """Hash of `as_dict`: a review with another digest is not skipped.

        Returns
        -------
        str
            32 hex digits.
        """
        text = json.dumps(self.as_dict(), sort_keys=True, allow_nan=False)
        return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()

    def model_for(
        self, meta: logmeta.LogMetadata | None, log: Path
    ) -> tuple[SqueakModel, InputSettings]:
        """The model and input settings of one log (its own with `use_log_params`).

        Parameters
        ----------
        meta : LogMetadata or None
            The log's `leadscrew_ros` metadata record, if it has one.
        log : Path
            The log (for the error).

        Returns
        -------
        tuple of (SqueakModel, InputSettings)
            What the log is replayed with.

        Raises
        ------
        LogError
            `use_log_params` and the log has no usable record.
        """
        if not self.use_log_params:
            return SqueakModel(self.params, Scatter(self.scatter), self.samples), self.inputs
        if meta is None:
            raise LogError(
                log,
                f"no '{logmeta.RECORD_NAME}' metadata record, so no recorded "
                f"parameters (review it without --use-log-params)",
            )
        scatter = dict(meta.scatter)
        samples = int(scatter.pop("samples", self.samples))
        recorded = input_parameters(meta.node)
        try:
            inputs = InputSettings(**{**recorded, **self.input_options})
        except (TypeError, ValueError) as exc:
            raise LogError(log, f"recorded input settings: {exc}") from None
        return SqueakModel(meta.screw_parameters(), Scatter(scatter), samples), inputs


# ---------------------------------------------------------------------- finding the logs
def _is_bag(directory: Path) -> bool:
    """A rosbag2-style bag: metadata.yaml, or log files all named `<directory>_<n>`."""
    if (directory / "metadata.yaml").exists():
        return True
    files = [p for p in directory.iterdir() if p.suffix in _SUFFIXES and p.is_file()]
    split = re.compile(re.escape(directory.name) + r"_\d+$")
    return bool(files) and all(split.fullmatch(p.stem) for p in files)


def _walk(directory: Path, skip: Path | None) -> Iterator[Path]:
    if skip is not None and directory.resolve() == skip:
        return
    if _is_bag(directory):
        yield directory
        return
    for p in sorted(directory.iterdir()):
        if p.is_dir():
            yield from _walk(p, skip)
        elif p.suffix in _SUFFIXES:
            yield p


def find_logs(inputs: Iterable[str], skip: Path | str | None = None) -> list[Path]:
    """The logs named by `inputs`.

    Parameters
    ----------
    inputs : iterable of str
        Log files (.mcap, .db3; a split file of a bag directory stands for its bag), bag
        directories, folders (searched recursively: each bag directory and each loose .mcap
        or .db3 file in them is one log) and glob patterns (``**`` matches folders at any
        depth).
    skip : path, optional
        A folder whose logs are left out (the review's output directory: its annotated logs
        are not reviewed again).

    Returns
    -------
    list of Path
        Absolute paths, each log once, in input order.

    Raises
    ------
    LogError
        An input that does not exist, a pattern that matches nothing.
    """
    skip = Path(skip).resolve() if skip is not None else None
    found: dict[Path, None] = {}
    for text in inputs:
        if _GLOB.search(text) and not Path(text).exists():
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise LogError(text, "no file or folder matches this pattern")
        else:
            matches = [text]
        for m in map(Path, matches):
            if not m.exists():
                raise LogError(m, "no such file or directory")
            # a split file stands for its bag: the splits are one log
            logs = _walk(m, skip) if m.is_dir() else [m.parent if _is_bag(m.parent) else m]
            found.update(
                dict.fromkeys(
                    p.resolve()
                    for p in logs
                    if skip is None or not p.resolve().is_relative_to(skip)
                )
            )
    return list(found)


def output_names(logs: list[Path], known: dict[str, str] | None = None) -> list[str]:
    """Output directory name of each log: the name it had in an earlier review into the same
    directory (`known`: path -> name), else its `log_name`; a name that another log has (in
    this run or in `known`) gets the first 8 hex digits of a hash of the log's path appended
    (the same in every run)."""
    known = known or {}
    names = [known.get(str(p)) or log_name(p).strip(".") or "log" for p in logs]
    this = {str(p) for p in logs}
    counts = Counter(names) + Counter(n for path, n in known.items() if path not in this)
    return [
        n
        if counts[n] == 1 or str(p) in known
        else f"{n}-{hashlib.blake2b(str(p).encode(), digest_size=4).hexdigest()}"
        for p, n in zip(logs, names, strict=True)
    ]


# ---------------------------------------------------------------------- one log: one task
def log_files(log: Path) -> list[Path]:
    """The files of a log (its split files for a bag directory), as the replay reads them."""
    return open_log(log).files


def _content_files(log: Path) -> list[Path]:
    """The log's files and, after a .db3 file, its WAL or journal (`logsource.sidecars`): the
    newest messages of a WAL-mode .db3 are there."""
    return [g for f in log_files(log) for g in [f, *(sidecars(f) if f.suffix == DB3 else [])]]


def stat_key(log: Path) -> list[list]:
    """(name, size, modification time in ns) of each of the log's files (`_content_files`): a
    quick change check."""
    out = []
    for f in _content_files(log):
        s = f.stat()
        out.append([f.name, s.st_size, s.st_mtime_ns])
    return out


def content_hash(log: Path) -> str:
    """BLAKE2b (128 bit) of the bytes of the log's files (`_content_files`) in split order, with
    their names."""
    h = hashlib.blake2b(digest_size=16)
    for f in _content_files(log):
        h.update(f.name.encode() + b"\0")
        with open(f, "rb") as fh:
            while block := fh.read(_HASH_BLOCK):
                h.update(block)
    return h.hexdigest()


def _metadata(log: Path) -> logmeta.LogMetadata | None:
    """The log's `leadscrew_ros` record (of its first MCAP file), None without one."""
    first = log_files(log)[0]
    return logmeta.read(first) if first.suffix == ".mcap" else None


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if isinstance(exc, LogError) else f"{type(exc).__name__}: {text}"


def _episodes(result: ReplayResult) -> list[dict[str, Any]]:
    """Every episode of a replay (the kept ones, or episodes.json when there are more)."""
    if result.episode_count <= len(result.episodes):
        return [e.as_dict() for e in result.episodes]
    with open(result.out_dir / "episodes.json", encoding="utf-8") as fh:
        return json.load(fh)


def squeak_frequencies(episodes: list[dict[str, Any]]) -> list[float]:
    """The log's distinct squeak frequencies [Hz]: per mode, the median of its episodes'
    frequencies; ascending."""
    by_mode: dict[str, list[float]] = {}
    for e in episodes:
        for mode, hz in zip(e["modes"], e["frequencies_hz"], strict=True):
            by_mode.setdefault(mode, []).append(hz)
    return sorted(statistics.median(v) for v in by_mode.values())


def error_row(log: Path, name: str, error: str, unit_id: str | None = None) -> dict[str, Any]:
    """The row of a log that could not be reviewed."""
    return {
        "log": str(log),
        "name": name,
        "unit_id": unit_id or name,
        "status": "error",
        "error": error,
    }


def heard_columns(summary: dict[str, Any]) -> dict[str, Any]:
    """The fleet row's heard-vs-predicted columns from a replay's summary: heard squeak time
    [s] (in the span the agreement counts), recall, precision, Brier score and the distinct
    heard frequencies [Hz] (each episode's, within 3 % of a lower one dropped); None
    without sound; `heard_status` (`listen.heard_status`: analysed, no sound, or why not) and
    `sound_share` (`listen.Heard.sound_share`: how much of the log was heard)."""
    heard = summary["heard"]
    status = {"heard_status": heard_status(summary)}
    if heard is None:
        return {
            **dict.fromkeys(
                ("heard_s", "recall", "precision", "brier", "heard_frequencies_hz", "sound_share")
            ),
            **status,
        }
    a = heard["agreement"]
    freqs: list[float] = []
    for f in sorted(e["frequency_hz"] for e in heard["episodes"]):
        if not freqs or f > freqs[-1] * 1.03:
            freqs.append(f)
    return {
        "heard_s": a["both_s"] + a["heard_only_s"],
        "recall": a["recall"],
        "precision": a["precision"],
        "brier": a["brier"],
        "heard_frequencies_hz": freqs,
        "sound_share": heard.get("sound_share"),
        **status,
    }


def _row(
    log: Path, name: str, unit_id: str, model: SqueakModel, result: ReplayResult
) -> dict[str, Any]:
    s = result.summary()
    episodes = _episodes(result)
    growth = [
        e["peak_growth_rate"]
        for e in episodes
        if e["peak_growth_rate"] is not None and math.isfinite(e["peak_growth_rate"])
    ]
    return {
        "log": str(log),
        "name": name,
        "unit_id": unit_id,
        "status": "ok",
        "error": "",
        "duration_s": s["duration_s"],
        "time_in_squeak_s": s["time_in_squeak_s"],
        "squeak_share": s["squeak_share"],
        "episodes": s["episodes"],
        "peak_growth_rate": max(growth) if growth else None,
        "squeak_frequencies_hz": squeak_frequencies(episodes),
        "peak_probability": s["peak_probability"],
        "time_above_warn_s": s["time_above_warn_s"],
        "time_above_error_s": s["time_above_error_s"],
        "messages": s["messages"],
        "predictions": s["predictions"],
        **heard_columns(s),
        "formulation": model.params.formulation,
        "wall_s": s["wall_s"],
    }


def recovered(log: Path, scratch: Path) -> tuple[Path, str]:
    """The log to replay and a note: `log` itself when its MCAP files are whole; for a
    recording cut off by a crash (no footer: the node or the machine died), a copy in
    `scratch` with every cut-off file rewritten up to its last whole record, as `recover` does
    (the input is never touched), and a note saying what was lost. Raises LogError when a
    file holds nothing readable.

    Parameters
    ----------
    log : Path
        An MCAP or .db3 file, or a bag directory.
    scratch : Path
        Where the copy goes (created when needed).

    Returns
    -------
    tuple of (Path, str)
        The log to replay and '' or the note for the fleet row.
    """
    files = log_files(log)
    cut = [f for f in files if f.suffix != DB3 and not is_complete(f)]
    if not cut:
        return log, ""
    target = scratch / log.name
    target.parent.mkdir(parents=True, exist_ok=True)
    if log.is_dir():
        target.mkdir()
    infos = []
    for f in files:
        dst = target if log.is_file() else target / f.name
        if f in cut:
            infos.append(recover(f, dst))
        else:
            shutil.copyfile(f, dst)
    lost = "; ".join(f"{i.path.name}: {i.damage or 'no footer'}" for i in infos)
    return target, (
        f"cut off ({lost}): reviewed the {sum(i.messages for i in infos)} whole "
        f"messages before the cut; `leadscrew-squeak recover` mends the file"
    )


def _points(result: ReplayResult) -> list[list[float]]:
    """At most POINTS_PER_LOG squeak points (speed [rad/s], load [N], frequency [Hz]), evenly
    from the replay's sample, 4 significant digits."""
    sample = result.plot_data.squeak.sample()
    if not len(sample):
        return []
    pick = np.unique(np.linspace(0, len(sample) - 1, POINTS_PER_LOG).round().astype(int))
    return [[float(f"{v:.4g}") for v in (row[0], row[1], row[3])] for row in sample[pick]]


def review_one(
    log: str, out_dir: str, name: str, settings: FleetSettings, known_hash: str | None = None
) -> dict[str, Any]:
    """Review one log (the body of a Dask task): the same replay as the `replay` command.

    Parameters
    ----------
    log : str
        The log (file or bag directory), opened here, on the worker.
    out_dir : str
        The review's output directory: the log's outputs go to `<out_dir>/<name>/`.
    name : str
        The log's output name (`output_names`).
    settings : FleetSettings
        Parameters and options of the review.
    known_hash : str, optional
        Content hash of the log in an earlier review with the same parameters: if the log
        still has it, nothing is replayed.

    Returns
    -------
    dict
        ``content``: the content hash; ``unchanged``: True when skipped; ``row``: the log's
        row in fleet.csv (status ``ok`` or ``error``, never an exception); ``points``: its
        squeak points for fleet.png.
    """
    path, out = Path(log), Path(out_dir) / name
    content, unit_id = None, None
    try:
        content = content_hash(path)
        if known_hash == content:
            return {"content": content, "unchanged": True}
        meta = None
        try:
            meta = _metadata(path)
        except ValueError:
            if settings.use_log_params:
                raise
        unit_id = (meta.unit_id if meta is not None else "") or name
        model, inputs = settings.model_for(meta, path)
        shutil.rmtree(out, ignore_errors=True)  # outputs of an earlier review
        whole, note = recovered(path, out / RECOVERED_DIR)
        result = replay(
            whole,
            model,
            out,
            ReplaySettings(
                inputs,
                settings.namespace,
                settings.out_namespace,
                workers=0,
                progress=False,
                listen=settings.listen.beside(path),
            ),
        )
        note = "; ".join(n for n in (note, result.metadata_problem) if n)
        row = {**_row(path, name, unit_id, model, result), "note": note}
        if settings.summary_only:
            for p in result.outputs[:2]:
                p.unlink(missing_ok=True)
            for d in (RECOVERED_DIR, CLIPS_DIR):
                shutil.rmtree(out / d, ignore_errors=True)
        elif settings.report:
            from .report import write_report

            write_report(result, model, out)
        return {"content": content, "row": row, "points": _points(result)}
    except Exception as exc:  # any failure of this log is its error row
        if out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        return {
            "content": content,
            "row": error_row(path, name, _one_line(exc), unit_id),
            "points": [],
        }


# ---------------------------------------------------------------------- the cluster
class ClusterError(ValueError):
    """No Dask scheduler to use: a malformed address, or none answered in time."""


@dataclass(frozen=True)
class ClusterSettings:
    """How `review` reaches a running scheduler (`--scheduler`) or sizes a local cluster."""

    connect_timeout_s: float = setting(
        5.0, "s", "how long to wait for the scheduler to answer", 0.0, 3600.0, lo_open=True
    )
    worker_memory_gb: float = setting(
        1.0,
        "GB",
        "memory each worker process of a local cluster is counted at: no more workers start "
        "than the machine's available memory holds (a worker that has reviewed a log holds "
        "less than half of it, test_fleet.py)",
        0.01,
        1e4,
    )

    def __post_init__(self) -> None:
        check(self, ClusterError)


@dataclass(frozen=True)
class Machine:
    """What this machine can run: its usable cores and available memory [bytes]."""

    cores: int
    memory_bytes: int

    @classmethod
    def now(cls) -> Machine:
        """Dask's count of the cores this process may use (CPU affinity and cgroup quota) and
        the memory available now (no more than Dask's memory limit: cgroup, RLIMIT_RSS)."""
        import psutil
        from dask.system import cpu_count
        from distributed.system import MEMORY_LIMIT

        return cls(cpu_count(), min(psutil.virtual_memory().available, MEMORY_LIMIT))


def local_workers(
    requested: int | None,
    settings: ClusterSettings = ClusterSettings(),
    machine: Machine | None = None,
) -> tuple[int, str]:
    """Worker processes of a local cluster: `requested` (None: as many as the machine runs), at
    most one per usable core and as many as the available memory holds at
    `settings.worker_memory_gb` each (at least one): more only wait for a core and keep a
    review from starting. Returns the count and, when `requested` was cut, why ('' if not)."""
    m = machine or Machine.now()
    by_memory = max(1, int(m.memory_bytes // (settings.worker_memory_gb * 1e9)))
    limit = max(1, min(m.cores, by_memory))
    if requested is None or requested <= limit:
        return requested or limit, ""
    if m.cores <= by_memory:
        return limit, "this machine's cores"
    return limit, (
        f"what this machine's available memory holds ({m.memory_bytes / 1e9:.1f} GB at "
        f"{settings.worker_memory_gb:g} GB a worker)"
    )


@contextlib.contextmanager
def _ctrl_c_held() -> Iterator[None]:
    """A Ctrl-C (SIGINT) meanwhile is held and raised (KeyboardInterrupt) once this ends, so
    that Dask's start and close are never cut in the middle (a cluster half started or half
    closed prints tracebacks). Only the main thread gets signals: elsewhere, nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt


def _workers_ignore_ctrl_c() -> None:
    """Make the worker processes of a local cluster ignore SIGINT, which a terminal's Ctrl-C
    sends to the whole process group: the client stops them (a worker interrupted on its own
    prints tracebacks). They fork from multiprocessing's fork server, which gives every child
    the SIGINT handling it started with; started here with SIGINT ignored (a process started
    so keeps ignoring it), every worker, a restarted one too, ignores it. The fork server
    starts in milliseconds: a Ctrl-C within them is lost."""
    import multiprocessing.forkserver

    from distributed.utils import get_mp_context

    get_mp_context()  # Dask's preload of the fork server (distributed and its dependencies)
    if threading.current_thread() is not threading.main_thread():
        multiprocessing.forkserver.ensure_running()
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        multiprocessing.forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, previous)


async def _probe(address: str, timeout_s: float) -> None:
    """Open and close one connection to `address` (ValueError: not an address; OSError: no
    answer within `timeout_s`, Dask retrying a refused connection until then)."""
    from distributed.comm import connect

    comm = await connect(address, timeout=timeout_s)
    await comm.close()


@contextlib.contextmanager
def cluster(
    workers: int | None = None,
    scheduler: str | None = None,
    settings: ClusterSettings = ClusterSettings(),
) -> Iterator[Any]:
    """A Dask client: of a new `distributed.LocalCluster` (`workers` processes, default
    `local_workers`, one thread each, everything on 127.0.0.1, no dashboard, its HTTP routes
    on a free port; the workers ignore SIGINT, `_workers_ignore_ctrl_c`; a Ctrl-C while it
    starts or closes takes effect after, `_ctrl_c_held`), closed on the way out, or
    connected to the running scheduler at `scheduler` (``tcp://HOST:PORT``) within
    `settings.connect_timeout_s`.

    Raises
    ------
    ClusterError
        `scheduler` is not an address Dask takes, or nothing answered there in time (raised
        before the client is yielded: never for a failure of the work done with it).
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        timeout = settings.connect_timeout_s
        try:  # a probe first: a Client that failed to connect hangs in __del__ at exit
            asyncio.run(_probe(scheduler, timeout))
        except ValueError as exc:  # 'missing port number', 'unknown scheme'
            raise ClusterError(f"--scheduler {scheduler!r}: {exc}") from None
        except OSError:  # refused, unknown host, no answer
            raise ClusterError(
                f"--scheduler {scheduler}: no Dask scheduler answered; timed "
                f"out after {timeout:g} s (--connect-timeout)"
            ) from None
        with Client(scheduler, timeout=timeout) as client:
            yield client
        return
    if workers is None:
        workers, _ = local_workers(None, settings)
    local = client = None
    stopped = True  # by an exception (Ctrl-C) while tasks may run
    try:
        with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
            _workers_ignore_ctrl_c()
            with _ctrl_c_held():
                local = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address=None,
                    # the scheduler serves its HTTP routes even without a dashboard, by default on
                    # 8787 (taken by any other Dask: a warning): a free port of 127.0.0.1 instead
                    scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                )
                client = Client(local)
            yield client
        stopped = False
    finally:
        with _ctrl_c_held():
            _close(client, local, quietly=stopped)


def _quiet_dask() -> None:
    """Dask's log lines off in this process (a worker's, by `Client.run`)."""
    logging.getLogger("distributed").setLevel(logging.CRITICAL)


def _close(client: Any, local: Any, quietly: bool) -> None:
    """Close the client, then the local cluster. `quietly`: tasks may still run (the review was
    interrupted or failed), and Dask logs their cancellation and kills (with a warning) the
    workers that do not stop within 4 s: expected here, so its log lines are off, in this
    process and in the workers."""
    dask_log = logging.getLogger("distributed")
    level = dask_log.level
    if quietly:
        dask_log.setLevel(logging.CRITICAL)
        if client is not None:
            with contextlib.suppress(Exception):  # a worker gone already: nothing to quieten
                client.run(_quiet_dask, on_error="ignore")
    try:
        if client is not None:
            client.close()
        if local is not None:
            local.close()
    finally:
        dask_log.setLevel(level)


# ---------------------------------------------------------------------- the index
def read_index(path: Path) -> dict[str, dict[str, Any]]:
    """Entries of a resume index by log path (the last line of a log wins; a torn last line
    of an interrupted run is ignored)."""
    entries: dict[str, dict[str, Any]] = {}
    if not path.exists():
        return entries
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            try:
                entry = json.loads(line)
                entries[entry["row"]["log"]] = entry
            except (ValueError, KeyError, TypeError):
                continue
    return entries


@dataclass
class FleetRun:
    """A finished review: the rows of the logs asked for and how they came about
    (`plots.plot_fleet` draws it).

    Attributes
    ----------
    rows : list of dict
        One per log (the columns of fleet.csv).
    points : list of list of float
        Squeak points (speed [rad/s], load [N], frequency [Hz]), a bounded sample.
    reviewed : int
        Logs replayed (or failed) in this run.
    skipped : int
        Unchanged since an earlier review: not replayed.
    wall_s : float
        Wall time of the review [s].
    """

    rows: list[dict[str, Any]]
    points: list[list[float]]
    reviewed: int
    skipped: int
    wall_s: float = math.nan

    @property
    def failed(self) -> int:
        """Logs with an error row."""
        return sum(r["status"] != "ok" for r in self.rows)


class _Points:
    """A uniform sample of at most `size` squeak points of the fleet (bounded memory)."""

    def __init__(self, size: int = 20_000):
        self.sample = Reservoir(3, size)

    def add(self, points: list[list[float]]) -> None:
        for p in points:
            self.sample.add(*p)

    def rows(self) -> list[list[float]]:
        return self.sample.sample().tolist()


def review_logs(
    logs: list[Path],
    out_dir: Path | str,
    settings: FleetSettings,
    client: Any,
    progress: bool = True,
) -> FleetRun:
    """Review `logs` into `out_dir` on the Dask cluster of `client`.

    Parameters
    ----------
    logs : list of Path
        Logs (`find_logs`).
    out_dir : path
        Output directory: `<name>/` per log and the resume index (fleet outputs: `fleetreport`).
    settings : FleetSettings
        Parameters and options for every log.
    client : distributed.Client
        Client of the cluster that runs the tasks (`cluster`).
    progress : bool
        A progress bar counting logs on stderr (a terminal only).

    Returns
    -------
    FleetRun
        One row per log, in the order of `logs`.
    """
    from distributed import as_completed

    t0 = time.perf_counter()
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    index_path = out / INDEX_FILE
    index = read_index(index_path)
    names = output_names(logs, {k: e["row"]["name"] for k, e in index.items()})
    digest, run_id = settings.digest(), uuid.uuid4().hex[:8]
    rows: dict[str, dict[str, Any]] = {}
    points = _Points()
    todo: list[tuple[Path, str, list | None, str | None]] = []
    for log, name in zip(logs, names, strict=True):
        entry = index.get(str(log))
        usable = (  # the entry, when it holds for this run
            entry
            if entry is not None
            and entry["params"] == digest
            and not entry["retry"]
            and (entry["row"]["status"] != "ok" or (out / name / "summary.json").exists())
            else None
        )
        stat = _stat_or_none(log)
        if usable is not None and stat is not None and usable["stat"] == stat:
            rows[str(log)] = usable["row"]
            points.add(usable["points"])
        else:
            todo.append((log, name, stat, usable["content"] if usable is not None else None))
    skipped = len(logs) - len(todo)
    threads = max(sum(client.nthreads().values()), 1)
    in_flight = max(IN_FLIGHT_PER_THREAD * threads, MIN_IN_FLIGHT)
    pending = iter(todo)
    by_future: dict[Any, tuple[Path, str, list | None, str | None]] = {}

    def submit(job: tuple[Path, str, list | None, str | None]) -> Any:
        log, name, _, known = job
        fut = client.submit(
            review_one,
            str(log),
            str(out),
            name,
            settings,
            known,
            key=f"review-{name}-{run_id}",
            pure=False,
        )
        by_future[fut] = job
        return fut

    def record(fut: Any, index_file: Any) -> None:
        """A finished task's row into `rows` and a line of the index."""
        nonlocal skipped
        log, name, stat, known = by_future.pop(fut)
        retry = False
        try:
            res = fut.result()
        except Exception as exc:  # the task did not finish: workers died under it
            res = {"content": known, "row": error_row(log, name, _one_line(exc)), "points": []}
            retry = True
        fut.release()
        if res.get("unchanged"):
            res = {**index[str(log)], "content": res["content"]}
            skipped += 1
        row = res["row"]
        rows[str(log)] = row
        points.add(res["points"])
        index_file.write(
            json.dumps(
                json_safe(
                    {
                        "params": digest,
                        "stat": stat,
                        "content": res["content"],
                        "retry": retry,
                        "row": row,
                        "points": res["points"],
                    }
                ),
                allow_nan=False,
            )
            + "\n"
        )
        index_file.flush()

    bar_or_none = (
        progress_bar(len(todo), "review", unit="log") if progress else contextlib.nullcontext()
    )
    try:
        with open(index_path, "a", encoding="utf-8") as index_file, bar_or_none as bar:
            ac = as_completed([submit(j) for j in _take(pending, in_flight)])
            for fut in ac:
                record(fut, index_file)
                if bar is not None:
                    bar(1)
                for job in _take(pending, 1):
                    ac.add(submit(job))
    except KeyboardInterrupt:  # the index holds every log finished: a rerun resumes there
        raise KeyboardInterrupt(
            f"{len(rows)} of {len(logs)} logs reviewed, rerun to resume"
        ) from None
    _compact(index_path)
    return FleetRun(
        [rows[str(log)] for log in logs],
        points.rows(),
        len(logs) - skipped,
        skipped,
        time.perf_counter() - t0,
    )


def _take(it: Iterator, n: int) -> list:
    return [x for _, x in zip(range(n), it, strict=False)]


def _stat_or_none(log: Path) -> list | None:
    try:
        return stat_key(log)
    except (OSError, LogError):
        return None


def _compact(path: Path) -> None:
    """Rewrite the index with one line per log."""
    entries = read_index(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        for entry in entries.values():
            fh.write(json.dumps(entry, allow_nan=False) + "\n")
    tmp.replace(path)
