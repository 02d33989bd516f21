# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak`: squeak predictions, sweeps, stability maps and the paper's figures; the
ROS 2 demo (`demo`: predictor node + actuator simulator) and the simulator alone (`simulate`);
the nonlinear time-domain simulation (`transient`); MCAP logs: offline replay (`replay`),
playback (`replay --publish`), `recover` and `info`; many logs on a Dask cluster (`review`);
each unit's friction and the fleet's population from heard squeak (`calibrate`); squeak heard
in a recording without a log (`listen`); recordings of simulated units with a microphone
(`bench`); a running node watched and steered without the
`ros2` command line (`watch`, `record`, `params`).

One module per command group holds its commands and adds their parsers: `model` (modes,
predict, sweep, map), `transient` (the nonlinear time-domain simulation), `figures`, `ros`
(demo, simulate), `remote` (watch, record, params), `logs` (replay, recover, info),
`recording` (listen), `fleet`
(review), `guard` (the squeak guard offline), `calibrate`, `bench`; `args`
holds what they share. Heavy or ROS modules are imported only by the command that needs them.

Every error a user can cause (bad option, invalid parameter or operating point, unreadable
file) is reported as one line `leadscrew-squeak: error: <message>` with exit code 2
(`review` returns 10 + the number of failed logs when some logs fail: `fleet.exit_status`;
`calibrate` 3 or 4 when it wrote a calibration that did not fully converge or that some inputs
could not take part in: `calibrate.exit_status`).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence

from ..bag.logfile import LogError
from ..model.physics.parameters import ParameterError
from ..model.squeak_model import OperatingPointError
from .args import PROG, CliError, Parser, common_parser

__all__ = ["CliError", "build_parser", "main", "split_ros_args"]

ROS_COMMANDS = ("simulate", "replay")  # the ones that start a ROS node (replay: --publish)


def build_parser() -> Parser:
    """The `leadscrew-squeak` parser: every command group adds its subcommands, in the order
    of the help text.

    Returns
    -------
    Parser
        Its parsed namespace has `run`, the command's function.
    """
    # the command groups here, not at import: a spawned worker re-runs the console script,
    # which imports this package, and needs none of them
    from . import (
        bench,
        calibrate,
        figures,
        fleet,
        guard,
        logs,
        model,
        recording,
        remote,
        ros,
        transient,
    )

    common = [common_parser()]
    parser = Parser(
        prog=PROG,
        description="Predict friction-induced squeak of a lead screw "
        "(continuous model, eigenvalues of eq. 27).",
    )
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=Parser
    )
    for group in (
        model,
        transient,
        figures,
        ros,
        remote,
        logs,
        recording,
        guard,
        fleet,
        calibrate,
        bench,
    ):
        group.add_parsers(sub, common)
    return parser


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """Split the command line as rcl delimits the ROS arguments: every `--ros-args` section up
    to `--` or the end (the `--` itself belongs to neither).

    Parameters
    ----------
    argv : sequence of str
        The command line without the program name.

    Returns
    -------
    tuple of (list of str, list of str)
        (the program's arguments, the ROS arguments).
    """
    ours: list[str] = []
    ros_args: list[str] = []
    inside = False
    for arg in argv:
        if arg == "--ros-args":
            inside = True
            ros_args.append(arg)
        elif inside and arg == "--":
            inside = False
        else:
            (ros_args if inside else ours).append(arg)
    return ours, ros_args


def _one_line(message: object) -> str:
    return " ".join(str(message).split())


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI.

    Parameters
    ----------
    argv : sequence of str, optional
        The command line without the program name; default: `sys.argv[1:]`.

    Returns
    -------
    int
        The exit code: 0 ok, 2 bad input, 130 interrupted, 141 closed pipe (`review`: 10 + the
        number of failed logs when some fail; `calibrate`: 3 not converged, 4 some inputs
        unusable). The long-running ROS commands (demo, simulate,
        replay --publish) return 0 when stopped by SIGINT/SIGTERM
        (`ros_env.StopSignals.exit_status`); 130 is Ctrl-C of the others or a second Ctrl-C.
    """
    try:
        ours, ros_args = split_ros_args(sys.argv[1:] if argv is None else list(argv))
        args = build_parser().parse_args(ours)
        args.ros_args = ros_args
        if ros_args and args.command not in ROS_COMMANDS:
            raise CliError(
                f"{args.command} takes no --ros-args (only "
                f"{' and '.join(ROS_COMMANDS)} --publish do)"
            )
        run: Callable[[argparse.Namespace], int] = args.run
        return run(args)
    except BrokenPipeError:  # `... | head`: the reader left; stay quiet like other tools
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except (CliError, ParameterError, OperatingPointError, LogError, OSError) as exc:
        # OSError: unwritable --out / --plot and the like.
        print(f"{PROG}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return exc.code if isinstance(exc.code, int) else 0
    except MemoryError:  # beyond the up-front estimates: still one line, no traceback
        print(f"{PROG}: error: out of memory; use fewer points", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # with what was done when a command says (`review`)
        print(f"{PROG}: interrupted" + (f": {exc}" if exc.args else ""), file=sys.stderr)
        return 130
