# SPDX-License-Identifier: Apache-2.0
"""The calibration command: `calibrate` (each unit's friction and damping from what was heard,
the fleet's population, the held-out check; `review.calibration`).

Exit status: 0 every unit calibrated (or keeping the prior, with nothing to learn) and every
sampler converged (with both formulations: those of the supported one; the other's are
reported); 2 a bad command line or input (a parameter without a prior scatter, an --out that
cannot be written or that another run holds), or no input with observations (nothing
written); NOT_CONVERGED (3) written, but a unit's or the population's sampler did not converge
or there is no population (then no calibrated.yaml): the numbers are not to be trusted as they
are; UNUSABLE (4) written and converged, but some inputs gave no observations (no sound,
unreadable: their reasons in calibration.json). 3 wins over 4.

The output directory is held for the run (`review.outlock`, its lock file `LOCK_FILE`): a
second run into it exits 2 naming the run (pid, start time) that holds it.
"""

from __future__ import annotations

import argparse
from contextlib import ExitStack
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from .args import (
    CliError,
    Parser,
    add_settings_options,
    build_model,
    common_parser,
    make_output_directory,
    output_directory,
    settings_from,
)
from .fleet import CLUSTER_BUSY, add_cluster_options, cluster_options, cluster_text
from .logs import _topic, add_input_options, listen_settings, replay_inputs

if TYPE_CHECKING:
    from ..model import SqueakModel
    from ..review.calibration.gather import GatherSettings
    from ..review.calibration.run import CalibrationResult
    from ..review.calibration.settings import CalibrationSettings
    from ..review.fleet import ClusterSettings

NOT_CONVERGED, UNUSABLE = 3, 4
LOCK_FILE = ".calibrate.lock"  # in --out while a run writes there


def exit_status(result: CalibrationResult) -> int:
    """The module's exit status of a written calibration."""
    if not result.converged:
        return NOT_CONVERGED
    return UNUSABLE if result.unusable else 0


def cmd_calibrate(args: argparse.Namespace) -> int:
    """`calibrate`: gather, calibrate, write; exit status."""
    from ..model.calibration import DetectionErrors, HearingPrior, Prior, ThinSettings
    from ..model.physics.parameters import ParameterError
    from ..review.calibration.sampling import SamplerSettings
    from ..review.calibration.settings import BOTH, DEFAULT_NAMES, CalibrationSettings

    workers, reach = cluster_options(args)
    settings = settings_from(
        args,
        CalibrationSettings,
        names=tuple(args.calibrate) or DEFAULT_NAMES,
        errors=settings_from(args, DetectionErrors),
        hearing=settings_from(args, HearingPrior),
        sampler=settings_from(args, SamplerSettings),
    )
    # the prior: the model options; with both formulations each gets the prior's values
    prior = build_model(
        argparse.Namespace(**{**vars(args), "formulation": None})
        if settings.formulation == BOTH
        else args
    )
    try:  # every name needs a prior scatter: refused here, not per unit after the gathering
        Prior(prior.params, prior.scatter, settings.names)
    except ParameterError as exc:
        can = ", ".join(prior.scatter.names) or "none"
        raise CliError(
            f"--calibrate: {exc}; the parameters that can be calibrated with this prior's "
            f"scatter: {can}"
        ) from None
    from ..review.calibration.gather import GatherSettings, find_inputs
    from ..review.outlock import DirectoryBusy, locked

    try:
        gathering = GatherSettings(
            prior.params,
            replay_inputs(args),
            args.namespace and _topic(args.namespace),
            listen_settings(args, wav_must_exist=False),
            settings_from(args, ThinSettings),
        )
    except ValueError as exc:
        raise CliError(str(exc)) from None
    out = output_directory(args.out)
    inputs = find_inputs(args.paths, skip=out)
    if not inputs:
        raise CliError(
            f"no logs (.mcap, .db3, bag directories) or replay outputs (summary.json) in "
            f"{' '.join(args.paths)}"
        )
    make_output_directory(out)
    with ExitStack() as held:
        try:
            note = held.enter_context(locked(out, LOCK_FILE))
        except DirectoryBusy as exc:
            raise CliError(f"--out: {out} {exc}") from None
        except OSError as exc:  # the lock file: a directory that cannot be written
            raise CliError(f"--out: {out} cannot be written: {exc.strerror or exc}") from None
        if note and not args.quiet:
            print(f"--out {out}: {note}")
        return _calibrate(args, out, inputs, prior, settings, gathering, (workers, reach))


def _calibrate(
    args: argparse.Namespace,
    out: Path,
    inputs: list[tuple[Path, bool]],
    prior: SqueakModel,
    settings: CalibrationSettings,
    gathering: GatherSettings,
    cluster_of: tuple[int | None, ClusterSettings],
) -> int:
    """`cmd_calibrate`'s work, `out` held: gather, calibrate, write; exit status."""
    from ..model.calibration import CalibrationError
    from ..review.calibration.gather import gather
    from ..review.calibration.output import text, write
    from ..review.calibration.run import calibrate
    from ..review.fleet import ClusterError, cluster

    workers, reach = cluster_of
    try:
        with cluster(workers, args.scheduler, reach) as client:
            gathered = gather(inputs, out.resolve(), gathering, client)
            try:
                result = calibrate(gathered, prior, settings, client, gathering.thin)
            except KeyboardInterrupt:
                raise KeyboardInterrupt(
                    f"all {len(gathered)} inputs gathered, calibrating: nothing written; "
                    "a rerun starts over"
                ) from None
    except ClusterError as exc:  # raised before any work
        raise CliError(str(exc)) from None
    except KeyboardInterrupt as exc:  # gather and calibrate say how far it got
        raise (
            exc if exc.args else KeyboardInterrupt(f"{CLUSTER_BUSY}; a rerun starts over")
        ) from None
    except CalibrationError as exc:
        raise CliError(str(exc)) from None
    context = {
        "inputs": args.paths,
        "prior": {
            "params": prior.params.as_dict(),
            "scatter": dict(prior.scatter.sd),
            "samples": prior.sample_count,
        },
        "replay": {
            "inputs": asdict(gathering.inputs),
            "namespace": gathering.namespace,
            "listen": asdict(gathering.listen),
            "thin": asdict(gathering.thin),
        },
        "run": {"out": str(out.resolve()), "cluster": cluster_text(args, workers)},
    }
    write(result, out, context, plot=not args.no_report)
    if not args.quiet:
        print(text(result, out))
    return exit_status(result)


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `calibrate` to `sub`, with the model options (the prior) of a `common_parser` of its
    own whose --formulation also takes 'both' (so `common` is not used)."""
    from ..model.calibration import DetectionErrors, HearingPrior, ThinSettings
    from ..review.calibration.sampling import SamplerSettings
    from ..review.calibration.settings import BOTH, DEFAULT_NAMES, CalibrationSettings

    spec = CalibrationSettings.__dataclass_fields__
    both = spec["formulation"].metadata["description"].partition("both: ")[2]
    p = sub.add_parser(
        "calibrate",
        # the model options with a --formulation that also takes 'both' (`common` has none)
        parents=[common_parser({BOTH: both})],
        help="calibrate each unit's friction and damping from the heard squeak of its logs, "
        "the fleet's population (DIR/calibrated.yaml, a params file for the node and every "
        "command), a held-out check: calibration.json, .txt, .png",
    )
    p.add_argument(
        "paths",
        nargs="+",
        metavar="PATH",
        help="logs with sound (.mcap, .db3, bag directories, folders, glob patterns, as "
        "review takes them) or replay outputs (a directory with summary.json from replay or "
        "review, or the file); the logs of one unit_id are one unit",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output directory: calibration.json, calibration.txt, calibration.png, "
        "calibrated.yaml and replays/<log name>/ (the replay of each log, with its heard "
        "episodes: an input of a later calibrate)",
    )
    add_cluster_options(p)
    g = p.add_argument_group("calibration")
    g.add_argument(
        "--calibrate",
        action="append",
        default=[],
        metavar="NAME",
        help=f"{spec['names'].metadata['help']} (repeatable; default {', '.join(DEFAULT_NAMES)})",
    )
    add_settings_options(g, CalibrationSettings, skip=("formulation",))
    add_settings_options(
        p.add_argument_group("detection errors (the likelihood's model of the detector)"),
        DetectionErrors,
    )
    add_settings_options(
        p.add_argument_group(
            "hearing (the observation model's prior of the bench's detection threshold and "
            "floor depth, and of the onset growth rates)"
        ),
        HearingPrior,
    )
    add_settings_options(p.add_argument_group("sampler (emcee)"), SamplerSettings)
    add_settings_options(
        p.add_argument_group("distinct operating points (the bins frames are thinned to)"),
        ThinSettings,
    )
    add_input_options(p)
    p.add_argument("--quiet", action="store_true", help="no summary")
    p.epilog = (
        "The model options are the prior (--formulation both: each formulation with the "
        "prior's values). Exit status: 0 calibrated and converged (with both: the supported "
        "formulation; the other's non-convergence is reported); 2 bad command line or "
        "input (a --calibrate NAME without a prior scatter, an --out that cannot be written "
        f"or that another run holds), nothing to calibrate from; {NOT_CONVERGED} written, "
        "but some sampler did not converge or there is no population (no calibrated.yaml); "
        f"{UNUSABLE} written and converged, but some inputs gave no observations "
        f"(no sound, unreadable). {NOT_CONVERGED} wins over {UNUSABLE}."
    )
    p.set_defaults(run=cmd_calibrate)
