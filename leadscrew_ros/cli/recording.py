# SPDX-License-Identifier: Apache-2.0
"""The recording command: `listen` (the squeak detector on a WAV file without a log;
`review.recording`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .args import CliError, Parser, finite, output_directory, print_json, read_params_file
from .logs import add_detector_options, background_path, detector_settings


def cmd_listen(args: argparse.Namespace) -> int:
    """`listen`: detect, write heard.json, summary.txt and spectrogram.png; exit status."""
    from ..review.listen import SoundSettings
    from ..review.recording import RecordingError, listen_recording, write_listened

    wav = Path(args.wav)
    if wav.is_dir():
        raise CliError(f"{args.wav}: a directory, not a WAV file")
    if not wav.is_file():
        raise CliError(f"{args.wav}: no such file")
    if args.speed_csv is not None and not Path(args.speed_csv).is_file():
        raise CliError(f"--speed-csv {args.speed_csv}: no such file")
    if args.params_file:
        read_params_file(args.params_file)  # a readable parameter file, or one line
    out = output_directory(args.out)
    try:
        settings = SoundSettings(
            channel=args.channel,
            scale_pa=args.audio_scale or 0.0,
            background=background_path(args.background) if args.background else "",
            detector=detector_settings(args),
        )
    except ValueError as exc:
        raise CliError(" ".join(str(exc).split())) from None
    try:
        listened = listen_recording(wav, settings, args.speed_csv)
    except RecordingError as exc:
        raise CliError(str(exc)) from None
    paths = write_listened(listened, out)
    if args.json:
        print_json(listened.as_dict())
    else:
        print("\n".join(listened.text()))
        print("wrote: " + ", ".join(str(p) for p in paths))
    return 0


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `listen` to `sub` (no model: `common` is not used)."""
    p = sub.add_parser(
        "listen",
        help="hear squeak in a recording without a log (a WAV file): squeak episodes, the "
        "background and its source, the drive orders with a speed; heard.json, "
        "summary.txt, spectrogram.png",
    )
    p.add_argument(
        "wav",
        metavar="FILE.wav",
        help="the recording: 8/16/24/32-bit integer or float WAV, mono or several channels "
        "(--channel)",
    )
    p.add_argument(
        "--out", required=True, metavar="DIR", help="output directory (created when missing)"
    )
    p.add_argument(
        "--speed-csv",
        metavar="FILE",
        help="the screw's speed: a CSV with the header time_s,speed_rad_s (times from the "
        "WAV's first sample): motor-off stretches learn the background, tones moving with "
        "the speed are drive orders; without it nothing moves (a steady tone is background)",
    )
    p.add_argument(
        "--channel",
        type=int,
        default=0,
        metavar="K",
        help="channel of a multichannel WAV (0, the first, by default)",
    )
    p.add_argument(
        "--audio-scale",
        type=finite,
        metavar="PA",
        help="pascal per full-scale unit: levels in dB SPL (default: dB re full scale)",
    )
    p.add_argument(
        "--params-file",
        metavar="FILE.yaml",
        help="ROS parameter file: its listen.* detector parameters are used, as the node's",
    )
    p.add_argument(
        "--json", action="store_true", help="print heard.json to stdout instead of the summary"
    )
    add_detector_options(p.add_argument_group("detector"))
    p.set_defaults(run=cmd_listen)
