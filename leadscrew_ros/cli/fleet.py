# SPDX-License-Identifier: Apache-2.0
"""The fleet command: `review` (many logs, one offline replay each on a Dask cluster, one
report).

Exit status: 0 when every log was reviewed; 2 for a bad command line or input (nothing
reviewed); otherwise FAILED_BASE + the number of logs that failed, at most FAILED_BASE +
FAILED_CAP (11 = one failed log, ..., 110 = 100 or more): distinct from 2 and from the codes
that shells and signals use (126 and up).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING

from ..model.physics.metadata import help_text
from ..review.fleet import ClusterError, ClusterSettings, local_workers
from .args import PROG, CliError, Parser, build_model, finite, output_directory
from .logs import REPLAY_INPUTS, _topic, add_input_options, listen_settings, replay_inputs

if TYPE_CHECKING:
    from ..review.fleet import FleetSettings

FAILED_BASE = 10
FAILED_CAP = 100
_ERRORS_SHOWN = 10
_MODEL_OPTIONS = ("param", "params_file", "formulation", "scatter", "samples")
# a Ctrl-C while the cluster started or closed (`cluster` takes it after)
CLUSTER_BUSY = "while the Dask cluster started or closed"
_CONNECT_TIMEOUT = next(f for f in fields(ClusterSettings) if f.name == "connect_timeout_s")


def exit_status(failed: int) -> int:
    """The exit status of a review with `failed` error rows."""
    return FAILED_BASE + min(failed, FAILED_CAP) if failed else 0


def _settings(args: argparse.Namespace) -> FleetSettings:
    from ..review.fleet import FleetSettings

    options = {
        name: getattr(args, name) for name in REPLAY_INPUTS if getattr(args, name) is not None
    }
    if args.use_log_params:
        given = [o for o in _MODEL_OPTIONS if getattr(args, o) not in (None, [])]
        if given:
            raise CliError(
                f"--{given[0].replace('_', '-')} and --use-log-params exclude each "
                f"other (with it every log has its recorded parameters)"
            )
    model = build_model(args)
    try:
        return FleetSettings(
            model.params,
            dict(model.scatter.sd),
            model.sample_count,
            replay_inputs(args),
            options,
            args.namespace and _topic(args.namespace),
            args.out_namespace and _topic(args.out_namespace),
            use_log_params=args.use_log_params,
            report=not args.no_report,
            summary_only=args.summary_only,
            listen=listen_settings(args, wav_must_exist=False),
        )
    except ValueError as exc:
        raise CliError(str(exc)) from None


def cluster_options(args: argparse.Namespace) -> tuple[int | None, ClusterSettings]:
    """The worker count of a local cluster (None with --scheduler: `local_workers`, the line
    on stderr when it cuts --workers) and how to reach a running one, from the options of
    `add_cluster_options`, checked before any work."""
    if args.workers is not None and not 1 <= args.workers <= 1024:
        raise CliError(f"argument --workers: must be in [1, 1024], got {args.workers}")
    if args.connect_timeout is not None and not args.scheduler:
        raise CliError("--connect-timeout is for --scheduler")
    try:
        reach = ClusterSettings(
            **({} if args.connect_timeout is None else {"connect_timeout_s": args.connect_timeout})
        )
    except ClusterError as exc:
        raise CliError(f"--connect-timeout: {exc}") from None
    if args.scheduler:
        return None, reach
    workers, why = local_workers(args.workers, reach)
    if why:
        print(f"{PROG}: --workers {args.workers}: capped at {workers}, {why}", file=sys.stderr)
    return workers, reach


def cluster_text(args: argparse.Namespace, workers: int | None) -> str:
    """Where the work ran, for the summary line."""
    return args.scheduler or f"LocalCluster of {workers} worker(s) on 127.0.0.1"


def cmd_review(args: argparse.Namespace) -> int:
    """`review`: replay a fleet's logs and write the fleet report; exit status."""
    workers, reach = cluster_options(args)
    settings = _settings(args)
    from ..review.fleet import cluster, find_logs, review_logs
    from ..review.fleetreport import write_fleet
    from ..review.listen import FULL_SHARE, NOT_ANALYSED

    out = output_directory(args.out)
    logs = find_logs(args.paths, skip=out)
    # --out in (or equal to) an input folder: its annotated logs are no inputs; say so
    inside = [
        p
        for p in args.paths
        if Path(p).is_dir() and out.resolve().is_relative_to(Path(p).resolve())
    ]
    left_out = f" (the output folder {out} is left out of the inputs)" if inside else ""
    if not logs:
        raise CliError(
            f"no logs (.mcap, .db3, bag directories) in {' '.join(args.paths)}{left_out}"
        )
    if left_out and not args.quiet:
        print(f"review: the output folder {out} is inside {inside[0]}: left out of the inputs")
    try:
        with cluster(workers, args.scheduler, reach) as client:
            run = review_logs(logs, out, settings, client, progress=not args.quiet)
    except ClusterError as exc:  # raised before the review starts
        raise CliError(str(exc)) from None
    except KeyboardInterrupt as exc:  # review_logs says how far it got
        raise exc if exc.args else KeyboardInterrupt(f"{CLUSTER_BUSY}, rerun to resume") from None
    where = cluster_text(args, workers)
    paths = write_fleet(
        run,
        out,
        {"inputs": args.paths, "out": str(out.resolve()), "cluster": where, **settings.as_dict()},
    )
    if not args.quiet:
        print(
            f"review of {len(run.rows)} logs on {where}: {run.reviewed} reviewed, "
            f"{run.skipped} unchanged since the last review, {run.failed} failed "
            f"({run.wall_s:.1f} s)"
        )
        errors = [r for r in run.rows if r["status"] != "ok"]
        for r in errors[:_ERRORS_SHOWN]:
            print(f"  error: {r['error']}")
        if len(errors) > _ERRORS_SHOWN:
            print(f"  ... {len(errors) - _ERRORS_SHOWN} more in {paths[0]}")
        unheard = [r for r in run.rows if str(r.get("heard_status")).startswith(NOT_ANALYSED)]
        for r in unheard[:_ERRORS_SHOWN]:
            print(f"  {r['name']}: {r['heard_status']}")
        if len(unheard) > _ERRORS_SHOWN:
            print(f"  ... {len(unheard) - _ERRORS_SHOWN} more not heard, in {paths[0]}")
        part = [
            r
            for r in run.rows
            if (r.get("sound_share") is not None) and r["sound_share"] < FULL_SHARE
        ]
        for r in part[:_ERRORS_SHOWN]:
            print(f"  {r['name']}: heard only {100 * r['sound_share']:.0f} % of the log")
        if len(part) > _ERRORS_SHOWN:
            print(f"  ... {len(part) - _ERRORS_SHOWN} more heard in part, in {paths[0]}")
        print("wrote: " + ", ".join(str(p) for p in paths))
    return exit_status(run.failed)


def add_cluster_options(p: argparse.ArgumentParser) -> None:
    """--workers N | --scheduler ADDRESS, --connect-timeout S (`cluster_options`)."""
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="Dask worker processes of a local cluster on 127.0.0.1, one "
        "thread each (default and most: one per core, as the available memory allows)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler, tcp://HOST:PORT (`dask scheduler`, "
        "`dask worker`); its workers must see the logs and DIR at the same "
        "paths and have leadscrew_ros installed",
    )
    p.add_argument(
        "--connect-timeout",
        type=finite,
        metavar="S",
        help=help_text(_CONNECT_TIMEOUT, "with --scheduler: how long to wait for it to answer"),
    )


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `review` (with the model options `common`) to `sub`."""
    p = sub.add_parser(
        "review",
        parents=common,
        help="review many logs on a Dask cluster (one offline replay per log, as `replay`): "
        "per-log outputs in DIR/<log name>/, fleet.csv, fleet.json, fleet.png; a re-run "
        "skips unchanged logs",
    )
    p.add_argument(
        "paths",
        nargs="+",
        metavar="PATH",
        help="log files (.mcap, .db3), bag directories, folders (searched "
        "recursively) or glob patterns (quote them; ** for any depth)",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output directory: <log name>/ per log (the replay's outputs), "
        "fleet.csv, fleet.json, fleet.png and the resume index",
    )
    add_cluster_options(p)
    g = add_input_options(p)
    g.add_argument(
        "--summary-only",
        action="store_true",
        help="keep only summary.json and summary.txt of each log (no annotated "
        "MCAP, episodes.json or report)",
    )
    g.add_argument(
        "--use-log-params",
        action="store_true",
        help="each log with the model parameters, scatter and input settings of "
        "its leadscrew_ros metadata record (input options given here still "
        "apply); a log without the record is an error row",
    )
    p.add_argument("--quiet", action="store_true", help="no progress and no summary")
    p.epilog = (
        f"Exit status: 0 every log reviewed; 2 bad command line; {FAILED_BASE} + the "
        f"number of failed logs otherwise ({FAILED_BASE + FAILED_CAP}: "
        f"{FAILED_CAP} or more)."
    )
    p.set_defaults(run=cmd_review)
