# SPDX-License-Identifier: Apache-2.0
"""The virtual bench command: `bench` (recordings of simulated units with a microphone, the
hidden truth in DIR/truth.json; `bag.virtual_bench`)."""

from __future__ import annotations

import argparse
import shutil
import time
from dataclasses import fields
from pathlib import Path
from typing import Any

from ..model.physics.metadata import help_text
from .args import (
    CliError,
    Parser,
    add_settings_options,
    finite,
    finite_float,
    output_directory,
    print_json,
    settings_from,
)

_OPTIONS = ("units", "formulation", "seed", "duration_s")
_POPULATION = ("population", "population_scatter")  # NAME=VALUE options, repeatable


def name_values(items: list[str], option: str) -> dict[str, float]:
    """`NAME=VALUE` items of a repeatable option -> {name: finite value} (the later wins)."""
    out = {}
    for item in items:
        name, sep, text = (part.strip() for part in item.partition("="))
        if not sep or not name:
            raise CliError(f"{option}: expected NAME=VALUE, got {item!r}")
        out[name] = finite_float(text, f"{option} {name}")
    return out


def empty_output(path: str, force: bool) -> None:
    """Make `--out` an empty (or new) directory: a bench written over another would leave the
    old logs beside a new truth.json under the same unit ids. A non-empty directory is refused
    unless `force`, which empties it (never the working directory, home or a parent of them).

    Raises
    ------
    CliError
        `path` is a file, or a non-empty directory without `force`, or one `force` may not empty.
    """
    out = output_directory(path)
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not force:
        raise CliError(
            f"--out {path} is not empty: its logs would mix with the new bench's "
            "(give an empty directory, or --force to empty it)"
        )
    resolved = out.resolve()
    protected = {Path.home().resolve(), *Path.cwd().resolve().parents, Path.cwd().resolve()}
    if resolved in protected:
        raise CliError(f"--out {path}: --force does not empty the working or home directory")
    for entry in resolved.iterdir():
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()


def cmd_bench(args: argparse.Namespace) -> int:
    """`bench`: simulate and record the units; prints one line per unit and a JSON summary."""
    from ..bag.virtual_bench import TRUTH, BenchSettings, Unit, run
    from ..model.acoustics.bench_sound import BenchSound

    values: dict[str, Any] = {
        name: getattr(args, name) for name in _OPTIONS if getattr(args, name) is not None
    }
    for name in _POPULATION:
        values[name] = name_values(getattr(args, name), "--" + name.replace("_", "-"))
    parts = [f.name for f in fields(BenchSound) if getattr(args, f.name) is not None]
    if parts and not args.realistic:
        raise CliError(
            f"--{parts[0].replace('_', '-')} sets a part of the realistic bench: add --realistic"
        )
    settings = BenchSettings(
        **values, realistic=args.realistic, sound=settings_from(args, BenchSound)
    )
    empty_output(args.out, args.force)
    start = time.perf_counter()

    def progress(k: int, unit: Unit, bag: Path) -> None:
        if not args.quiet:
            squeak_s = unit.squeaks.sum() / settings.input_rate_hz
            print(
                f"{unit.unit_id}: {bag.name}  squeaks {squeak_s:5.2f} s of "
                f"{settings.duration_s:g} s",
                flush=True,
            )

    truth = run(settings, args.out, progress)
    if not args.quiet:
        print_json(
            {
                "out": args.out,
                "truth": str(Path(args.out) / TRUTH),
                "units": len(truth["units"]),
                "formulation": settings.formulation,
                "seed": settings.seed,
                "run_time_s": round(time.perf_counter() - start, 3),
            }
        )
    return 0


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `bench` to `sub` (no model options: every unit has its own drawn parameters)."""
    from ..bag.virtual_bench import BenchSettings
    from ..model.acoustics.bench_sound import BenchSound

    spec = {f.name: f for f in fields(BenchSettings)}
    p = sub.add_parser(
        "bench",
        help="virtual bench: N recordings of simulated units (a stroke "
        "each, with a 48 kHz microphone on /microphone), in the "
        "node's format, the hidden truth in DIR/truth.json",
    )
    p.add_argument("--units", type=int, metavar="N", help=help_text(spec["units"]))
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output directory: one bag per unit and truth.json",
    )
    p.add_argument(
        "--formulation", choices=("paper", "consistent"), help=help_text(spec["formulation"])
    )
    p.add_argument("--seed", type=int, metavar="S", help=help_text(spec["seed"]))
    p.add_argument(
        "--duration",
        dest="duration_s",
        type=finite,
        metavar="S",
        help=help_text(spec["duration_s"]),
    )
    for name, metavar in zip(_POPULATION, ("NAME=VALUE", "NAME=SD"), strict=True):
        p.add_argument(
            "--" + name.replace("_", "-"),
            action="append",
            default=[],
            metavar=metavar,
            help=spec[name].metadata["help"] + " (repeatable; the logs still carry the "
            "package's nominal parameters and default scatter, the prior; truth.json has both)",
        )
    p.add_argument("--realistic", action="store_true", help=help_text(spec["realistic"]))
    add_settings_options(
        p.add_argument_group("the realistic bench's sound (with --realistic; levels dBFS)"),
        BenchSound,
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="empty a non-empty --out first (without it such a directory is refused)",
    )
    p.add_argument("--quiet", action="store_true", help="print nothing")
    p.set_defaults(run=cmd_bench)
