# SPDX-License-Identifier: Apache-2.0
"""The ROS 2 commands: `demo` (predictor node driven by the actuator simulator, one process)
and `simulate` (the simulator alone), and the `squeak_node` and `squeak_guard` executables.
rclpy is imported only when one of them runs (`args.import_ros`: without ROS 2, one line says
what to install)."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from .args import ROS_ARGS_HELP, CliError, Parser, finite, import_ros, output_directory

if TYPE_CHECKING:
    from ..live.profile import StrokeProfile


def _stroke(duration_s: float | None) -> StrokeProfile:
    """The simulator's stroke profile of `--duration` (a bad duration is a CliError)."""
    from ..live.profile import ProfileError, StrokeProfile

    try:
        return StrokeProfile() if duration_s is None else StrokeProfile(duration_s=duration_s)
    except ProfileError as exc:
        raise CliError(f"argument --duration: {exc}") from None


def cmd_demo(args: argparse.Namespace) -> int:
    """`demo`: run the node against a simulated stroke; exit status."""
    profile = _stroke(args.duration)
    record_dir = None if args.no_record else output_directory(args.record_dir, "--record-dir")
    demo = import_ros("demo", "demo")
    try:
        if args.guard:
            if args.microphone:
                raise CliError("argument --guard: not with --microphone")
            out_dir = output_directory(args.record_dir, "--record-dir")
            return demo.run_guard_demo(profile.duration_s, out_dir=out_dir)
        return demo.run_demo(profile.duration_s, record_dir=record_dir, microphone=args.microphone)
    except RuntimeError as exc:  # e.g. rclpy could not start, no subscription
        raise CliError(str(exc)) from None


def cmd_simulate(args: argparse.Namespace) -> int:
    """`simulate`: publish a simulated stroke as actuator inputs; exit status."""
    profile = _stroke(args.duration)
    simulator = import_ros("simulate", "simulator")
    MAX_RATE_HZ, run_simulator = simulator.MAX_RATE_HZ, simulator.run_simulator
    if not 0 < args.rate <= MAX_RATE_HZ:
        raise CliError(f"argument --rate: must be in (0, {MAX_RATE_HZ:g}] Hz, got {args.rate:g}")
    try:
        return run_simulator(
            profile,
            rate_hz=args.rate,
            loop=args.loop,
            joint_name=args.joint_name,
            wait_for_subscriber=not args.no_wait,
            ros_args=args.ros_args,
        )
    except (ValueError, RuntimeError) as exc:  # bad --ros-args; rclpy could not start
        raise CliError(str(exc)) from None


def squeak_node() -> int:
    """The `squeak_node` executable (`ros.node.main`); without ROS 2 one line
    `squeak_node: error: 'squeak_node' needs ROS 2 (rclpy): pip install ...`, exit 2."""
    try:
        node = import_ros("squeak_node", "node")
    except CliError as exc:
        print(f"squeak_node: error: {exc}", file=sys.stderr)
        return 2
    return node.main()


def squeak_guard() -> int:
    """The `squeak_guard` executable (`ros.guard_node.main`); without ROS 2 one line
    `squeak_guard: error: ...`, exit 2."""
    try:
        node = import_ros("squeak_guard", "guard_node")
    except CliError as exc:
        print(f"squeak_guard: error: {exc}", file=sys.stderr)
        return 2
    return node.main()


def _duration_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--duration",
        type=finite,
        metavar="S",
        help="stroke duration [s] (default 12; at most about 13, or the nut would leave the screw)",
    )


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `demo` and `simulate` to `sub` (neither takes the model options `common`)."""
    p = sub.add_parser(
        "demo",
        help="the ROS 2 predictor node driven by the actuator simulator "
        "(one process, loopback, private ROS_DOMAIN_ID)",
    )
    _duration_option(p)
    p.add_argument(
        "--record-dir",
        default="squeak_demo",
        metavar="DIR",
        help="the predictor records inputs and outputs into a bag in DIR (created; "
        "default ./squeak_demo)",
    )
    p.add_argument("--no-record", action="store_true", help="do not record")
    p.add_argument(
        "--microphone",
        action="store_true",
        help="the simulator also publishes a simulated microphone (a squeak tone "
        "where the model squeaks) and the predictor listens to it; the summary "
        "says heard against predicted",
    )
    p.add_argument(
        "--guard",
        action="store_true",
        help="run the stroke twice, without and then with the squeak guard node (the motor "
        "following speed_command_guarded): time in squeak, peak P and stroke time side by side, "
        "and guard_demo.png / guard_demo.csv in the --record-dir directory (no bag)",
    )
    p.set_defaults(run=cmd_demo)

    p = sub.add_parser(
        "simulate",
        help="publish a simulated power-seat stroke for a separately "
        "started squeak_node (same ROS_DOMAIN_ID)",
        usage="%(prog)s [options] [--ros-args ...]",
        epilog=ROS_ARGS_HELP + "; e.g. --ros-args -r __ns:=/seat_left publishes "
        "/seat_left/motor_speed, ...",
    )
    _duration_option(p)
    p.add_argument(
        "--rate",
        type=finite,
        default=100.0,
        metavar="HZ",
        help="publishing rate [Hz] (default 100)",
    )
    p.add_argument(
        "--loop", action="store_true", help="repeat the stroke, back and forth, until Ctrl-C"
    )
    p.add_argument(
        "--joint-name",
        default="",
        metavar="NAME",
        help="also publish joint_states with this joint (screw angle, speed)",
    )
    p.add_argument(
        "--no-wait",
        action="store_true",
        help="start the stroke at once instead of when something subscribes to motor_speed",
    )
    p.set_defaults(run=cmd_simulate)
