# SPDX-License-Identifier: Apache-2.0
"""Commands for a running squeak_node, where pip gives no `ros2` command line: `watch` (a live
view of its inputs, outputs and diagnostics), `record on|off|status` (its `~/record` service)
and `params [list] | get NAME | set NAME VALUE` (its parameters, through the standard
parameter services). The work is done in `ros.watch` and `ros.remote`; here the options are
parsed and the results printed."""

from __future__ import annotations

import argparse
from typing import Any

from .args import CliError, Parser, finite, import_ros

NAMESPACE_HELP = "the node's namespace (default /, as squeak_node started without -r __ns:=...)"


def _remote(command: str) -> Any:
    return import_ros(command, "remote")


def cmd_watch(args: argparse.Namespace) -> int:
    """`watch`: the live view; exit status (2 when no node was found with --once/--timeout)."""
    if args.timeout is not None and args.timeout <= 0:
        raise CliError(f"argument --timeout: must be > 0 s, got {args.timeout:g}")
    watch = import_ros("watch", "watch")
    try:
        return watch.run_watch(args.namespace, once=args.once, timeout_s=args.timeout)
    except (ValueError, RuntimeError) as exc:  # NodeNotFound, a bad namespace
        raise CliError(str(exc)) from None


def cmd_record(args: argparse.Namespace) -> int:
    """`record on|off|status`: one line, the state and the file."""
    remote = _remote("record")
    try:
        with remote.Remote(args.namespace) as node:
            if args.action == "status":
                print(f"{node.target} recording {node.recording().text()}")
                return 0
            success, message = node.record(args.action == "on")
    except (ValueError, RuntimeError) as exc:  # NodeNotFound, no answer
        raise CliError(str(exc)) from None
    if not success:
        raise CliError(f"record {args.action}: {node.target} says: {message}")
    state = f"on: {message}" if args.action == "on" else f"off ({message})"
    print(f"{node.target} recording {state}")
    return 0


def cmd_params(args: argparse.Namespace) -> int:
    """`params [list]`, `params get NAME`, `params set NAME VALUE`."""
    action, operands = args.action, args.operands
    wanted = {"list": 0, "get": 1, "set": 2}[action]
    if len(operands) != wanted:
        usage = {"list": "params [list]", "get": "params get NAME", "set": "params set NAME VALUE"}
        raise CliError(f"usage: {usage[action]} (got {len(operands)} operand(s))")
    remote = _remote("params")
    try:
        with remote.Remote(args.namespace) as node:
            if action == "list":
                for parameter in node.parameters():
                    print(parameter.line())
            elif action == "get":
                [parameter] = node.parameters(operands)
                print(parameter.line())
            else:
                before, after = node.set(*operands)
                print(
                    f"{after.name} = {remote.format_value(after.value)} "
                    f"(was {remote.format_value(before.value)})"
                )
    except (ValueError, RuntimeError) as exc:  # no node, unknown name, bad value, refused
        raise CliError(str(exc)) from None
    return 0


def _namespace_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--namespace", default="/", metavar="NS", help=NAMESPACE_HELP)


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `watch`, `record` and `params` to `sub` (they take no model options)."""
    p = sub.add_parser(
        "watch",
        help="a live view of a running squeak_node: inputs, P(squeak), unstable modes, "
        "safe speed, diagnostics, recording, listening (redrawn in place on a terminal)",
        description="A live view of a running squeak_node on this ROS_DOMAIN_ID: redrawn "
        "twice a second on a terminal, appended as plain text when it changes otherwise. "
        "Says after 2 s when no node is found, and how to start one. Ctrl-C stops (exit 130).",
    )
    _namespace_option(p)
    p.add_argument(
        "--once",
        action="store_true",
        help="print the view once, when the node's latest outputs are in, and exit "
        "(exit 2 when no node is found within 2 s, or --timeout)",
    )
    p.add_argument(
        "--timeout",
        type=finite,
        metavar="S",
        help="stop after S seconds (exit 2 if no node was found by then); with --once, how "
        "long to wait for the node",
    )
    p.set_defaults(run=cmd_watch)

    p = sub.add_parser(
        "record",
        help="start or stop a running squeak_node's recording (its ~/record service), or "
        "say what it records",
    )
    p.add_argument("action", choices=("on", "off", "status"))
    _namespace_option(p)
    p.set_defaults(run=cmd_record)

    p = sub.add_parser(
        "params",
        help="a running squeak_node's parameters: list them (values, units, ranges), get "
        "one, set one (refused values: exit 2 with the node's reason)",
        usage="%(prog)s [-h] [--namespace NS] [list | get NAME | set NAME VALUE]",
    )
    p.add_argument("action", nargs="?", default="list", choices=("list", "get", "set"))
    p.add_argument("operands", nargs="*", help=argparse.SUPPRESS)
    _namespace_option(p)
    p.set_defaults(run=cmd_params)
