# SPDX-License-Identifier: Apache-2.0
"""The MCAP log commands: `replay` (offline recomputation of the node's predictions and the
report, or playback to ROS 2 topics with --publish), `recover` and `info`."""

from __future__ import annotations

import argparse
from dataclasses import fields
from pathlib import Path
from typing import Any

from ..bag.livelock import LIVE
from ..bag.logfile import (
    LogInfo,
    bag_of,
    cut_off_bags,
    live_recordings,
    metadata_problem,
    recover,
    recover_bag,
)
from ..bag.logsource import DB3, LogSource, open_log
from ..live.settings import InputField, JointSettings, LiveSettings
from ..model.acoustics.settings import DetectorSettings
from ..model.physics.metadata import help_text
from ..review.listen import SoundSettings
from ..review.replay import ReplaySettings
from ..review.timeline import FIELD_SETTINGS, InputSettings, input_parameters
from .args import (
    PROG,
    ROS_ARGS_HELP,
    CliError,
    Parser,
    build_model,
    finite,
    import_ros,
    output_directory,
    output_file,
    print_json,
    yaml_parameters,
)

# = option dests, node parameters (`inputs.<input>.field`, `.scale` for `<input>_field`, ...)
REPLAY_INPUTS = [f.name for f in fields(InputSettings)]
# The node's settings that replay options mirror: their metadata gives the help and the range
REPLAY_SETTINGS = {
    f.name: f
    for cls in (LiveSettings, JointSettings)
    for f in fields(cls)
    if f.name in REPLAY_INPUTS
}
LIVE_OPTIONS = ("rate", "loop", "start_offset", "topics", "remap", "no_wait", "ros_args")
# option dest -> SoundSettings field (the audio options of replay and review)
AUDIO_OPTIONS = {
    "audio_topic": "topic",
    "audio_info_topic": "info_topic",
    "audio_channel": "channel",
    "audio_rate": "rate_hz",
    "audio": "file",
    "audio_start": "start_s",
    "audio_scale": "scale_pa",
    "background": "background",
    "compare_formulations": "compare_formulations",
}
LISTEN_SETTINGS = {f.name: f for f in fields(SoundSettings)}
# The detector's settings: the node's `listen.<name>` parameters, offline as live
DETECTOR_SETTINGS = {f.name: f for f in fields(DetectorSettings)}
LISTEN_PREFIX = "listen."


def _detector_value(name: str, value: Any, where: str) -> Any:
    """A detector setting's value from a parameters file or `--listen-param` text, of the
    field's type (a whole number for a float setting is that float, as the node takes it)."""
    default = DETECTOR_SETTINGS[name].default
    if isinstance(default, str):
        return str(value)
    kind: type = int if isinstance(default, int) else float
    if isinstance(value, str):
        try:
            return kind(value.strip())
        except ValueError:
            raise CliError(
                f"{where} {name}: {value!r} is not {'an integer' if kind is int else 'a number'}"
            ) from None
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def detector_settings(args: argparse.Namespace) -> DetectorSettings:
    """DetectorSettings: defaults <- the `listen.*` detector parameters of --params-file (as
    the node reads them) <- --listen-param NAME=VALUE (repeatable; `listen.` optional) <-
    --drive-ratio R (repeatable: `drive_ratios`).

    Raises
    ------
    CliError
        An unknown name, a value of the wrong type or out of range (one line).
    """
    values: dict[str, Any] = {}
    if getattr(args, "params_file", None):
        for key, value in yaml_parameters(args.params_file).items():
            name = key.removeprefix(LISTEN_PREFIX)
            if key.startswith(LISTEN_PREFIX) and name in DETECTOR_SETTINGS:
                values[name] = _detector_value(name, value, "--params-file listen.")
    for item in getattr(args, "listen_param", None) or []:
        name, sep, text = (part.strip() for part in item.partition("="))
        name = name.removeprefix(LISTEN_PREFIX)
        if not sep or not name:
            raise CliError(f"--listen-param: expected NAME=VALUE, got {item!r}")
        if name not in DETECTOR_SETTINGS:
            raise CliError(
                f"--listen-param: {name!r} is not a detector setting; known: "
                + ", ".join(DETECTOR_SETTINGS)
            )
        values[name] = _detector_value(name, text, "--listen-param")
    ratios = getattr(args, "drive_ratio", None) or []
    if ratios:
        values["drive_ratios"] = ", ".join(f"{r:g}" for r in ratios)
    try:
        return DetectorSettings(**values)
    except (TypeError, ValueError) as exc:
        raise CliError(f"listen.{' '.join(str(exc).split())}") from None


def _topic(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def _setting_help(name: str, description: str | None = None) -> str:
    """argparse help of the replay option that sets node setting `name` (from its metadata;
    `description` replaces the node's)."""
    return help_text(REPLAY_SETTINGS[name], description).replace("%", "%%")


def _field_help(name: str, description: str) -> str:
    """argparse help of a --<input>-field / --<input>-scale option (node parameter
    `inputs.<input>.<name>`: its metadata gives the default and range)."""
    f = next(f for f in fields(InputField) if f.name == name)
    return help_text(f, description).replace("%", "%%")


def replay_inputs(args: argparse.Namespace) -> InputSettings:
    """InputSettings: defaults <- node parameters of --params-file (`inputs.<input>.field`
    and `.scale` too) <- options. Topic names stay as given: relative ones resolve in the
    input namespace (--namespace, or the log's)."""
    values = input_parameters(yaml_parameters(args.params_file) if args.params_file else {})
    values.update(
        {name: getattr(args, name) for name in REPLAY_INPUTS if getattr(args, name) is not None}
    )
    try:
        return InputSettings(**values)
    except (TypeError, ValueError) as exc:
        text = str(exc)
        for name in FIELD_SETTINGS:  # 'speed_field: ...' -> '--speed-field: ...'
            if text.startswith(name):
                raise CliError("--" + name.replace("_", "-") + text[len(name) :]) from None
        raise CliError(f"replay inputs: {text}") from None


def _parse_remap(items: list[str]) -> dict[str, str]:
    remap = {}
    for item in items:
        old, sep, new = item.partition(":=")
        if not sep or not old or not new:
            raise CliError(f"argument --remap: expected OLD:=NEW, got {item!r}")
        remap[_topic(old)] = new
    return remap


OFFLINE_OPTIONS = (
    "out",
    "no_report",
    "namespace",
    "out_namespace",
    "nominal_load_n",
    "warn_probability",
    "error_probability",
    "no_audio",
    *AUDIO_OPTIONS,
)


def listen_settings(args: argparse.Namespace, wav_must_exist: bool = True) -> SoundSettings:
    """SoundSettings of the audio options (`add_audio_options`); CliError for options that
    exclude each other or values out of range (and, with `wav_must_exist`, a missing WAV)."""
    given = {
        dest: getattr(args, dest)
        for dest in AUDIO_OPTIONS
        if getattr(args, dest) not in (None, False)
    }
    option = {dest: "--" + dest.replace("_", "-") for dest in AUDIO_OPTIONS}
    if args.no_audio and given:
        raise CliError(f"{option[next(iter(given))]} and --no-audio exclude each other")
    if "audio" in given:
        for dest in ("audio_topic", "audio_info_topic", "audio_rate"):
            if dest in given:
                raise CliError(
                    f"{option[dest]} is for the log's audio topics, not --audio FILE.wav"
                )
        if wav_must_exist and Path(args.audio).is_dir():
            raise CliError(f"--audio {args.audio}: a directory, not a WAV file")
        if wav_must_exist and not Path(args.audio).is_file():
            raise CliError(f"--audio {args.audio}: no such file")
    elif "audio_start" in given:
        raise CliError("--audio-start needs --audio FILE.wav")
    if "background" in given:
        given["background"] = background_path(args.background)
    detector = detector_settings(args)
    if "audio_scale" not in given and getattr(args, "params_file", None):
        scale = yaml_parameters(args.params_file).get(LISTEN_PREFIX + "scale_pa")
        if isinstance(scale, (int, float)) and not isinstance(scale, bool) and scale > 0:
            given["audio_scale"] = float(scale)  # the node's calibration, offline too
    try:
        return SoundSettings(
            enabled=not args.no_audio,
            detector=detector,
            **{AUDIO_OPTIONS[dest]: v for dest, v in given.items()},
        )
    except ValueError as exc:
        text = str(exc)
        for dest, name in AUDIO_OPTIONS.items():
            text = (
                text.replace(f"{name} = ", f"{option[dest]} = ", 1)
                if text.startswith(f"{name} = ")
                else text
            )
        raise CliError(f"argument {text}") from None


def background_path(path: str) -> str:
    """The absolute path of a --background recording (a WAV file or a log), checked before
    any work: it exists.

    Raises
    ------
    CliError
        No such file or directory.
    """
    if not Path(path).exists():
        raise CliError(f"--background {path}: no such file or directory")
    return str(Path(path).resolve())


def _publish(args: argparse.Namespace) -> int:
    given = [o for o in OFFLINE_OPTIONS if getattr(args, o) not in (None, False)]
    if given:
        option = {"nominal_load_n": "load"}.get(given[0], given[0])
        raise CliError(
            f"--{option.replace('_', '-')} is for the offline replay, not --publish "
            f"(the namespace of --publish is --ros-args -r __ns:=NS)"
        )
    live = import_ros("replay --publish", "replay_live")
    publish_log, wait_s = live.publish_log, live.WAIT_FOR_SUBSCRIBER_S
    try:
        publish_log(
            open_log(args.log).files,
            rate=1.0 if args.rate is None else args.rate,
            loop=args.loop,
            start_offset_s=0.0 if args.start_offset is None else args.start_offset,
            topics=[_topic(t) for t in args.topics] if args.topics else None,
            remap=_parse_remap(args.remap),
            progress=not args.quiet,
            wait_for_subscriber_s=0.0 if args.no_wait else wait_s,
            ros_args=args.ros_args,
        )
    except (ValueError, RuntimeError) as exc:  # bad arguments; rclpy could not start
        raise CliError(str(exc)) from None
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    """`replay`: replay a log through the model (or publish it live); exit status."""
    if args.publish:
        return _publish(args)
    given = [o for o in LIVE_OPTIONS if getattr(args, o) not in (None, False, [])]
    if given:
        raise CliError(f"--{given[0].replace('_', '-')} needs --publish")
    if args.episodes < 0:
        raise CliError("argument --episodes: must be >= 0")
    model = build_model(args)
    inputs = replay_inputs(args)
    from ..review.replay import log_name, replay

    try:
        settings = ReplaySettings(
            inputs,
            namespace=args.namespace and _topic(args.namespace),
            out_namespace=args.out_namespace and _topic(args.out_namespace),
            workers=args.workers,
            progress=not args.quiet,
            listen=listen_settings(args),
        )
    except ValueError as exc:
        raise CliError(str(exc)) from None
    out = output_directory(args.out or f"{log_name(Path(args.log))}_replay")
    _check_audio_topics(args)
    result = replay(args.log, model, out, settings)
    if not args.no_report:
        from ..review.report import write_report

        result.outputs += write_report(result, model, out)
    if not args.quiet:
        print(result.summary_text())
        for e in result.episodes[: args.episodes]:
            print(
                f"  squeak {e.start_s:10.2f} - {e.end_s:10.2f} s  peak P(squeak) "
                f"{e.probability.peak:.3f}  peak growth {e.peak_growth_rate:7.1f} 1/s  "
                + ", ".join(
                    f"{m} {f:.0f} Hz" for m, f in zip(e.modes, e.frequencies_hz, strict=True)
                )
            )
        if result.episode_count > args.episodes:
            print(f"  ... {result.episode_count - args.episodes} more in episodes.json")
        print("wrote: " + ", ".join(str(p) for p in result.outputs))
    return 0


def _check_audio_topics(args: argparse.Namespace) -> None:
    """A named audio source that is not there ends the replay before any work, the log's
    topic as the WAV file (`listen_settings`): one rule for what the user named."""
    if not (args.audio_topic or args.audio_info_topic):
        return
    from ..bag.audio import AudioError, audio_topics

    try:
        audio_topics(args.log, args.audio_topic or None, args.audio_info_topic or None)
    except AudioError as exc:
        raise CliError(" ".join(str(exc).split())) from None


def _span(info: LogInfo) -> str:
    if info.start_ns is None:
        return "no messages"
    assert info.end_ns is not None  # set with start_ns
    return (
        f"{(info.end_ns - info.start_ns) / 1e9:.3f} s ({_utc(info.start_ns)} to "
        f"{_utc(info.end_ns)})"
    )


def _utc(ns: int) -> str:
    import datetime

    return datetime.datetime.fromtimestamp(ns / 1e9, datetime.timezone.utc).isoformat(
        timespec="milliseconds"
    )


def _topic_lines(info: LogInfo) -> list[str]:
    return [f"  {t.name:<32} {t.type_name:<36} {n:>10}" for t, n in info.type_counts()]


def _record_directory(path: Path) -> bool:
    """A directory of recordings (bag directories, loose files) rather than one bag: it has no
    metadata.yaml and holds no .mcap file or a subdirectory with one."""
    return (
        path.is_dir()
        and not (path / "metadata.yaml").exists()
        and (not any(path.glob("*.mcap")) or any(path.glob("*/*.mcap")))
    )


def _metadata_problem(path: Path, infos: list[LogInfo]) -> str:
    """`metadata_problem` of the bag of `path` (a bag directory's metadata.yaml against its
    files as read into `infos`; a file's bag: the metadata alone); '' for a loose file or one
    still being recorded."""
    bag = path if path.is_dir() else bag_of(path)
    if bag is None or any(i.live for i in infos):
        return ""
    return metadata_problem(bag, infos if bag == path else None)


def _sqlite_log(path: Path) -> LogSource | None:
    """The rosbag2 sqlite3 log at `path` (a .db3 file or a bag directory of them), or None."""
    if (path.is_file() and path.suffix == DB3) or (path.is_dir() and any(path.glob("*" + DB3))):
        source = open_log(path)
        return source if source.sqlite else None
    return None


def _recover_sqlite(source: LogSource, output: str | None) -> int:
    """`recover` of a .db3 log: nothing to do, SQLite's transactions keep it consistent."""
    what = f"{source.path} is a rosbag2 sqlite3 (.db3) log"
    if output:
        raise CliError(f"{what}: nothing to recover into {output} (SQLite keeps it consistent)")
    infos = source.inspect()
    problem = _metadata_problem(source.path, infos)
    print(
        f"nothing to recover: {what}, which SQLite keeps consistent "
        f"({sum(i.messages for i in infos)} messages readable)"
        + (f"; {problem}" if problem else "")
    )
    return 0


def cmd_recover(args: argparse.Namespace) -> int:
    """`recover`: repair a cut-off log or bag; exit status."""
    src = Path(args.log)
    sqlite = _sqlite_log(src)
    if sqlite is not None:
        return _recover_sqlite(sqlite, args.output)
    if args.output:  # a copy elsewhere; the input stays as it is
        if src.is_dir():
            raise CliError("-o/--output is for one file; a bag directory is recovered in place")
        dst = output_file(args.output, "-o/--output", ("mcap",), makes_directory=True)
        assert dst is not None  # args.output is given
        info = recover(src, dst)
        print(
            f"recovered {info.messages} messages on {len(info.topics)} topics from {src} "
            f"into {args.output}"
        )
        print(f"time span: {_span(info)}")
        print("damage: " + (info.damage or "none (the file was complete)"))
        print("\n".join(_topic_lines(info)))
        return 0
    if _record_directory(src):
        targets = cut_off_bags(src)
        for live in live_recordings(src):  # never touched: a recorder still writes them
            print(f"{live}: skipped, {LIVE}")
        if not targets:
            print(f"nothing to recover: no cut-off recording in {src}")
            return 0
    else:
        targets = [src]
    for target in targets:
        result = recover_bag(target)
        for f in result.files:
            print(f.line())
        print(result.summary())
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    """`info`: print what a log contains; exit status."""
    path = Path(args.log)
    infos = open_log(path).inspect()
    problem = _metadata_problem(path, infos)
    bag = path if path.is_dir() else bag_of(path)
    if args.json:
        print_json(
            [
                {
                    "file": str(i.path),
                    "storage": i.storage,
                    "complete": i.complete,
                    "damage": i.damage,
                    "live": i.live,
                    "profile": i.profile,
                    "library": i.library,
                    "messages": i.messages,
                    "start_ns": i.start_ns,
                    "end_ns": i.end_ns,
                    "metadata_problem": problem,
                    "topics": [
                        {"name": t.name, "type": t.type_name, "count": n}
                        for t, n in i.type_counts()
                    ],
                }
                for i in infos
            ]
        )
        return 0
    for i in infos:
        if i.storage != "mcap":
            print(f"{i.path}: rosbag2 {i.storage} storage")
            print(f"  {i.messages} messages, {_span(i)}")
            print("\n".join(_topic_lines(i)))
            continue
        if i.complete:
            state = "complete"
        elif i.live:  # not cut off: the rest is still to come
            state = f"{LIVE}: read up to now; its footer comes when the recording stops"
        else:
            state = (
                f"TRUNCATED: {i.damage}; recover with `{PROG} recover {bag_of(i.path) or i.path}`"
            )
        print(f"{i.path}: {state}")
        print(
            f"  {i.messages} messages, {_span(i)}; profile {i.profile!r}, "
            f"written by {i.library or 'unknown'}"
        )
        print("\n".join(_topic_lines(i)))
    if problem:
        print(f"{bag}: {problem}")
    return 0


def add_input_options(p: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """The input-topic, deadband, P(squeak)-threshold and namespace options of the offline
    replay (also `review`'s; the dests of the first ones are the `InputSettings` fields, see
    `replay_inputs`); returns the group 'offline replay' for a command's own options."""
    g = p.add_argument_group(
        "inputs (defaults: the node's topics, relative names in the input "
        "namespace; node parameters from --params-file)"
    )
    for name, what, default, scale in (
        ("speed", "speed [rad/s]", "motor_speed", "rpm to rad/s: 0.10472; a gear ratio"),
        ("load", "axial load [N]", "axial_load", "kN to N: 1000"),
        ("nut", "nut position [m]", "nut_position", "mm to m: 0.001"),
    ):
        g.add_argument(
            f"--{name}-topic",
            metavar="TOPIC",
            help=f"{what}: std_msgs/Float64, or any type with --{name}-field (default {default})",
        )
        g.add_argument(
            f"--{name}-field",
            metavar="PATH",
            help=_field_help(
                "field",
                f"path of the number in the messages of --{name}-topic, any type the log has a "
                f"definition for: data (std_msgs numbers), twist.twist.angular.z "
                f"(nav_msgs/Odometry), velocity[2] (an array element); a header stamp orders "
                f"the messages"
                if name == "speed"
                else f"path of the number in the messages of --{name}-topic (as --speed-field)",
            ),
        )
        g.add_argument(
            f"--{name}-scale",
            type=finite,
            metavar="X",
            help=_field_help(
                "scale", f"the {what} is this times the field ({scale}; negative reverses)"
            ),
        )
    g.add_argument(
        "--joint-states-topic",
        metavar="TOPIC",
        help="sensor_msgs/JointState (default joint_states)",
    )
    g.add_argument("--joint-name", metavar="NAME", help=_setting_help("joint_name"))
    g.add_argument(
        "--nut-position-at-zero-angle",
        dest="nut_position_at_zero_angle_m",
        type=finite,
        metavar="M",
        help=_setting_help("nut_position_at_zero_angle_m"),
    )
    g.add_argument(
        "--speed-deadband",
        dest="speed_deadband_rad_s",
        type=finite,
        metavar="RAD_S",
        help=_setting_help("speed_deadband_rad_s"),
    )
    g.add_argument(
        "--load-deadband",
        dest="load_deadband_n",
        type=finite,
        metavar="N",
        help=_setting_help("load_deadband_n"),
    )
    g.add_argument(
        "--nut-deadband",
        dest="nut_deadband_m",
        type=finite,
        metavar="M",
        help=_setting_help("nut_deadband_m"),
    )
    g = p.add_argument_group(
        "P(squeak) thresholds (the node's; summary, episodes and report "
        "give the time at or above them)"
    )
    g.add_argument(
        "--warn-probability",
        dest="warn_probability",
        type=finite,
        metavar="P",
        help=_setting_help(
            "warn_probability",
            "time at or above this P(squeak) is counted as WARN (the node's diagnostic WARN)",
        ),
    )
    g.add_argument(
        "--error-probability",
        dest="error_probability",
        type=finite,
        metavar="P",
        help=_setting_help(
            "error_probability",
            "time at or above this P(squeak) is counted as ERROR (the node's diagnostic ERROR)",
        ),
    )
    g = p.add_argument_group("offline replay")
    g.add_argument(
        "--namespace",
        metavar="NS",
        help="namespace of the input topics, as a node's __ns (default: the one "
        "namespace of the log that has predictor inputs)",
    )
    g.add_argument(
        "--out-namespace",
        metavar="NS",
        help="namespace of the prediction topics in the annotated log (default "
        "/replay + the input namespace: /replay/squeak/risk, ...)",
    )
    g.add_argument(
        "--load",
        dest="nominal_load_n",
        type=finite,
        metavar="N",
        help="nominal axial load [N] from the start, for a log without load topic "
        "(a load topic in the log overrides it)",
    )
    g.add_argument("--no-report", action="store_true", help="skip the PNG report")
    add_audio_options(p)
    return g


def _listen_help(name: str, description: str | None = None) -> str:
    """argparse help of the audio option that sets SoundSettings field `name`."""
    f = LISTEN_SETTINGS[name]
    text = (
        (description or f.metadata["description"])
        if isinstance(f.default, str)
        else help_text(f, description)
    )
    return text.replace("%", "%%")


def add_audio_options(p: argparse.ArgumentParser) -> None:
    """The audio options of the offline replay and the review (`listen_settings`): where the
    sound of the drive is, its scale, the comparison of the formulations."""
    g = p.add_argument_group("heard vs predicted (the log's microphone; summary.json heard)")
    g.add_argument(
        "--audio-topic",
        metavar="TOPIC",
        help=_listen_help(
            "topic",
            "audio topic: ros-drivers AudioDataStamped, mgonzs13 AudioStamped or "
            "std_msgs/Float32MultiArray (default: the log's only audio-typed topic; "
            "several are listed in the summary's warnings)",
        ),
    )
    g.add_argument(
        "--audio-info-topic",
        metavar="TOPIC",
        help=_listen_help(
            "info_topic",
            "ros-drivers AudioInfo topic (default <audio topic>_info, else the "
            "log's only AudioInfo topic)",
        ),
    )
    g.add_argument("--audio-channel", type=int, metavar="K", help=_listen_help("channel"))
    g.add_argument(
        "--audio-rate",
        type=finite,
        metavar="HZ",
        help=_listen_help(
            "rate_hz", "sample rate of std_msgs/Float32MultiArray audio, which carries none"
        ),
    )
    g.add_argument(
        "--audio",
        metavar="FILE.wav",
        help=_listen_help(
            "file",
            "a WAV file recorded beside the log, read instead of its audio topics "
            "(review: a relative path is taken beside each log)",
        ),
    )
    g.add_argument(
        "--audio-start",
        type=finite,
        metavar="S",
        help=_listen_help(
            "start_s", "with --audio: its first sample's time after the log's first message"
        ),
    )
    g.add_argument("--audio-scale", type=finite, metavar="PA", help=_listen_help("scale_pa"))
    add_detector_options(g)
    g.add_argument(
        "--no-audio", action="store_true", help="ignore the log's sound (no heard vs predicted)"
    )
    g.add_argument(
        "--compare-formulations",
        action="store_true",
        help=_listen_help(
            "compare_formulations",
            "also predict the log with the other friction formulation "
            "(paper, consistent): agreement_by_formulation in summary.json, "
            "which describes the drive better in summary.txt",
        ),
    )


def add_detector_options(g: Any) -> None:
    """The detector's options of every command that listens (`detector_settings`): its
    settings, the drive's known ratios, a background recording."""
    g.add_argument(
        "--background",
        metavar="FILE.wav|LOG",
        help=_listen_help("background")
        + " (default: the motor-off stretches, else steady tones inferred)",
    )
    g.add_argument(
        "--listen-param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a squeak detector setting, as the node's listen.NAME parameter (repeatable; "
        "also read from --params-file): "
        + ", ".join(DETECTOR_SETTINGS)
        + " (doc: Reference, parameters)",
    )
    g.add_argument(
        "--drive-ratio",
        type=finite,
        action="append",
        default=[],
        metavar="R",
        help="a known ratio of drive noise (motor, gear, commutator) to the screw's rotation "
        "frequency (repeatable; listen.drive_ratios): for logs too short to learn them",
    )


def add_parsers(sub: argparse._SubParsersAction, common: list[Parser]) -> None:
    """Add `replay` (with the model options `common`), `recover` and `info` to `sub`."""
    p = sub.add_parser(
        "replay",
        parents=common,
        help="recompute the node's predictions for an MCAP log (offline, into "
        "--out), or play the log to ROS 2 topics (--publish)",
    )
    p.add_argument(
        "log",
        metavar="LOG",
        help="MCAP or rosbag2 sqlite3 (.db3) file, or a bag directory of split files",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        help="output directory (default ./<log name>_replay): "
        "<log name>.annotated.mcap, episodes.json, summary.json/.txt, PNG report",
    )
    g = add_input_options(p)
    g.add_argument(
        "--workers",
        type=int,
        default=ReplaySettings.workers,
        metavar="N",
        help="prediction processes for long logs (default %(default)s; 0: one process)",
    )
    g.add_argument(
        "--episodes",
        type=int,
        default=10,
        metavar="N",
        help="squeak episodes listed on stdout (default 10)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress and no summary")
    g = p.add_argument_group("playback to ROS 2 topics")
    g.add_argument(
        "--publish", action="store_true", help="publish the log's messages in real time instead"
    )
    g.add_argument("--rate", type=finite, metavar="R", help="speed factor (default 1)")
    g.add_argument("--loop", action="store_true", help="repeat until Ctrl-C")
    g.add_argument("--start-offset", type=finite, metavar="S", help="skip this much of the log [s]")
    g.add_argument(
        "--topics",
        nargs="+",
        metavar="T",
        help="publish exactly these topics (default: the predictor's inputs)",
    )
    g.add_argument(
        "--remap",
        action="append",
        default=[],
        metavar="OLD:=NEW",
        help="publish log topic OLD on NEW (repeatable; a relative NEW is in the node's namespace)",
    )
    g.add_argument(
        "--no-wait",
        action="store_true",
        help="start at once instead of waiting (up to 5 s) for a subscriber",
    )
    p.epilog = (
        ROS_ARGS_HELP + " (with --publish; in a namespace other than / the log's inputs "
        "are published in it: --ros-args -r __ns:=/seat_right)"
    )
    p.set_defaults(run=cmd_replay)

    p = sub.add_parser(
        "recover",
        help="make a recording cut off by a crash readable by every tool: each cut-off "
        "file rewritten complete in place (the original kept as "
        "<name>.mcap.broken until the rewrite reads back), the bag's "
        "metadata.yaml regenerated; a second run changes nothing",
    )
    p.add_argument(
        "log",
        metavar="BAGDIR|FILE",
        help="bag directory, one .mcap file (its bag's metadata.yaml is regenerated "
        "too), or a record directory (every cut-off bag in it); a .db3 log needs no "
        "recovery (SQLite keeps it consistent): one line says so",
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="OUT.mcap",
        help="write the recovered messages of one FILE to OUT.mcap instead, leaving "
        "the input untouched",
    )
    p.set_defaults(run=cmd_recover)

    p = sub.add_parser(
        "info",
        help="topics, types, counts, time span of a log (MCAP or .db3); complete or truncated",
    )
    p.add_argument(
        "log",
        metavar="LOG",
        help="MCAP or rosbag2 sqlite3 (.db3) file, or a bag directory of split files",
    )
    p.add_argument("--json", action="store_true", help="print JSON (one object per file)")
    p.set_defaults(run=cmd_info)
