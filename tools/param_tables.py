# SPDX-License-Identifier: Apache-2.0
"""The documentation's parameter and topic tables, rendered from the settings' field metadata.

    .venv/bin/python tools/param_tables.py            # prints every table
    .venv/bin/python tools/param_tables.py record     # prints one
    .venv/bin/python tools/param_tables.py --write doc/reference/_generated  # as doc/conf.py

One markdown table per entry of `TABLES` (parameter, unit, default, allowed values, meaning),
one per entry of `OPTION_TABLES` (a command's options made from settings metadata by
`cli.args.add_settings_options`: option, unit, default, allowed values, meaning), and the node's
topic table (`topic_table`: names and types from the code, QoS and meaning from
`TOPICS`, the diagnostic key-values from the `KEY_*` constants). Nothing is pasted: the Sphinx
build (doc/conf.py, on `builder-inited`) writes each table with `write` into
doc/reference/_generated/<name>.md (git-ignored), which the pages include; test/test_settings.py
checks that every table is rendered and included.
"""

from __future__ import annotations

import sys
from dataclasses import fields
from pathlib import Path

from leadscrew_ros.bag import messages
from leadscrew_ros.bag.msgdefs import type_name
from leadscrew_ros.bag.recorder import RecordSettings
from leadscrew_ros.live import listen, status
from leadscrew_ros.live.guard import GuardSettings
from leadscrew_ros.live.settings import (
    INPUT_FIELDS,
    JointSettings,
    ListenSettings,
    LiveSettings,
)
from leadscrew_ros.model.acoustics.bench_sound import BenchSound
from leadscrew_ros.model.acoustics.settings import DetectorSettings
from leadscrew_ros.model.calibration import DetectionErrors, ThinSettings
from leadscrew_ros.model.physics.metadata import default_text, range_text
from leadscrew_ros.model.physics.parameters import ScrewParameters
from leadscrew_ros.model.uncertainty.scatter import ScatterSettings
from leadscrew_ros.review.calibration import CalibrationSettings, SamplerSettings
from leadscrew_ros.ros import diagnostics
from leadscrew_ros.ros.node import AUDIO_COMMON_TOPICS, INPUTS, SOUND_INPUTS
from leadscrew_ros.ros.parameters import (
    ALL_GROUPS,
    READ_ONLY_NOTE,
    NodeSettings,
    RecordingControl,
    Spec,
    specs,
)

# table name -> the settings dataclasses it lists, in the node's parameter order
TABLES = {
    "node": (LiveSettings, JointSettings, NodeSettings),
    "inputs": tuple(INPUT_FIELDS.values()),
    "scatter": (ScatterSettings,),
    "record": (RecordingControl, RecordSettings),
    "listen": (ListenSettings, DetectorSettings),
    "model": (ScrewParameters,),
    "guard": (GuardSettings,),  # the squeak_guard node's guard.* (it takes model and scatter too)
}
NODE_TABLES = (
    "node",
    "inputs",
    "scatter",
    "record",
    "listen",
)  # the node's own parameters, not the model's
# table name -> the settings dataclasses whose `setting` fields are a command's options
OPTION_TABLES = {
    "calibrate": (CalibrationSettings, DetectionErrors, SamplerSettings, ThinSettings),
    "bench": (BenchSound,),
}
HEADER = ["| parameter | unit | default | allowed | meaning |", "|---|---|---|---|---|"]
TOPIC_TABLE = "topics"  # file name of `topic_table` in `write`

SENSOR, LATCHED = "sensor data (best effort)", "reliable, transient local, depth 1"
_PREDICTION = (
    f"`/squeak_predictor: {diagnostics.PREDICTION_TASK}`: OK (P(squeak) < `warn_probability`) / "
    "WARN (P >= `warn_probability`, default 0.1; or no prediction: outside the "
    "model's validity) / ERROR (P >= `error_probability`, default 0.5, or a "
    "divergence predicted, or invalid input) / STALE (speed or load older than "
    "`stale_timeout_s`); the message gives P(squeak) and the modes that squeak at "
    "the nominal parameters, e.g. `squeak predicted: P(squeak) 1 (B1y 224 Hz, B2y "
    "898 Hz)`, `squeak possible: P(squeak) 0.12 >= 0.1`, `no squeak: P(squeak) 0 < "
    "0.1` (P is never rounded across a threshold); key-values {keys} (constants "
    "`leadscrew_ros.live.status.KEY_*`; `validity` is the `Validity` name of the "
    "latest point, `probability_stderr` '' when not sampled); while the node is inactive "
    "(lifecycle) STALE with the message `" + status.INACTIVE + "`, the last values and "
    "`lifecycle_state` `inactive`"
)
_RECORDING = (
    f"`/squeak_predictor: {diagnostics.RECORDING_TASK}`: OK (recording to PATH, or not "
    "recording) / WARN (input messages lost before recording, with the counts; bags "
    "of an earlier run cut off by a crash) / ERROR (the disk error, with the path), "
    "with key-values {keys}, `lost <topic>` (constants "
    "`leadscrew_ros.ros.diagnostics.KEY_*`)"
)
_MEASUREMENT = (
    f"with `listen.enabled` a third, `/squeak_predictor: {diagnostics.MEASUREMENT_TASK}`: "
    "heard against predicted over the last `listen.window_s` of analysed sound, "
    "allowing for the detector's delay: OK when both squeak or neither (e.g. "
    "`heard squeak at 2651 Hz, predicted (T1 2653 Hz)`, `no squeak heard, none "
    "predicted`) / WARN when they disagree, naming which way (`heard squeak at 2651 "
    "Hz, none predicted`, `predicted squeak (P 0.97), none heard`), or when chunks "
    "were dropped (the analysis could not keep up) or did not decode during the "
    "window / STALE when no sound arrived for `listen.window_s`; key-values {keys} "
    "(constants `leadscrew_ros.live.listen.KEY_*`; `heard_s`, `predicted_s`, "
    "`agreement`, `analysed_s` and `heard_modes` since the start)"
)
# topic (relative to the node's namespace, as the code names it) -> (direction, QoS, meaning)
TOPICS = {
    "motor_speed": (
        "in",
        SENSOR,
        "screw speed, rad/s, sign = direction; the type shown or any installed type with "
        "the speed at a field path (`inputs.speed.*`)",
    ),
    "axial_load": (
        "in",
        "sensor data",
        "axial load, N (sign = loaded flank); or any type (`inputs.load.*`)",
    ),
    "nut_position": (
        "in, optional",
        "sensor data",
        "nut position z_o along the screw, m; or any type (`inputs.nut.*`)",
    ),
    "joint_states": (
        "in, optional",
        "sensor data",
        "joint `joint_name` only (`''`, the "
        "default, ignores joint_states): velocity = speed, position (screw angle) "
        "moves the nut by R tan(beta) per rad from `nut_position_at_zero_angle_m`",
    ),
    messages.RISK: (
        "out",
        LATCHED,
        "P(squeak) in [0, 1]: the probability over the unit-to-unit "
        "scatter (`scatter.*`) that some oscillatory mode grows at this speed, load "
        "and nut position (`Prediction.probability`, the live first-order "
        "estimator); exactly 0 or 1 (the nominal verdict) without scatter",
    ),
    messages.MARGIN: (
        "out",
        "same",
        "the deterministic stability margin at the nominal "
        "parameters: least damping ratio -Re(lambda)/|lambda| of the oscillatory "
        "modes (`Prediction.margin`), negative when a mode squeaks, +inf without "
        "an oscillatory mode",
    ),
    messages.FREQUENCIES: ("out", "same", "squeak frequencies, Hz, most unstable first"),
    messages.ACTIVE: ("out", "same", "a squeak mode exists"),
    messages.MODES: (
        "out",
        "same",
        "rows = oscillatory modes (labels in `layout.dim[0].label`), "
        "columns " + ", ".join(messages.MODE_COLUMNS),
    ),
    messages.SAFE_SPEED: (
        "out",
        "same",
        "nearest speed in the same direction whose P(squeak) is "
        "below `safe_probability` (default 0.01), at the current load and nut "
        "position, rad/s (the current speed when its P is already below it; 0 "
        "if no valid such speed exists in that direction)",
    ),
    "microphone": (
        "in, with `listen.enabled`",
        "sensor data, depth `listen.queue_chunks`",
        "sound chunks, full scale -1..1, at `listen.sample_rate_hz` (a layout of two "
        "dimensions, the second of size > 1: interleaved channels, averaged); "
        "analysed on a thread of its own, never delaying a prediction",
    ),
    "audio_stamped": (
        "in, with `listen.enabled` where ros-drivers audio_common is installed",
        "sensor data, depth `listen.queue_chunks`",
        "sound chunks of audio_common's audio_capture node (PCM in the sample format of "
        "`audio_info`; the first channel analysed), as `microphone`",
    ),
    "audio_info": (
        "in, with `listen.enabled` where ros-drivers audio_common is installed",
        "sensor data",
        "channels, sample rate, sample format and coding of `audio_stamped` (a coding other "
        "than wave/PCM: its chunks are counted as malformed)",
    ),
    messages.HEARD: (
        "out, with `listen.enabled`",
        LATCHED,
        "a squeak is heard now: a prominent "
        "tone (ECMA-418-1) of at least `listen.min_duration_s` that does not follow "
        "the motor orders (`model.acoustics.StreamingDetector.heard_now`)",
    ),
    messages.HEARD_FREQUENCY: (
        "out, with `listen.enabled`",
        "same",
        "its frequency, Hz; 0 while nothing is heard",
    ),
    diagnostics.TOPIC: (
        "out",
        "same",
        "two statuses (three with `listen.enabled`), named by the "
        "node's fully qualified name. "
        "{prediction}; {recording}; {measurement}. They come from a small updater in "
        "diagnostic_updater's shape (`leadscrew_ros/ros/diagnostics.py`: an "
        "`Updater` owns the publisher, the period and the hardware id; tasks "
        "fill a status; `update()` on the period, `force_update()` on a change "
        "of verdict)",
    ),
    **{
        topic: (
            "recorded, from `squeak_guard`",
            "best effort, depth `record.queue_depth`, while recording",
            meaning,
        )
        for topic, meaning in (
            (messages.SPEED_COMMAND, "the speed command the guard takes in, rad/s"),
            (messages.SPEED_COMMAND_GUARDED, "the command the guard hands on, rad/s"),
            (messages.GUARD_ACTIVE, "the guard changes the command now"),
            (messages.GUARD_REASON, "why it changes it"),
        )
    },
}


def _cell(text: str) -> str:
    """Markdown table cell text: '|' would end the cell, '<' start an HTML tag (outside code
    spans; inside one a backslash would show)."""
    parts = text.replace("|", "\\|").split("`")
    return "`".join(p if i % 2 else p.replace("<", "\\<") for i, p in enumerate(parts))


def row(spec: Spec) -> str:
    """One table row of parameter `spec`."""
    return _row(f"`{spec.name}`", spec.field)


def _row(name: str, field) -> str:
    md, default = field.metadata, field.default
    shown = f"`{default}`" if isinstance(default, str) and default else default_text(field)
    allowed = (
        ", ".join(f"`{c}`" for c in md["choices"])
        if md["choices"]
        else range_text({**md, "unit": ""})
        if md["lo"] is not None
        else ""
    )
    meaning = md["description"] + (f" ({READ_ONLY_NOTE})" if md["read_only"] else "")
    cells = [name, md["unit"], shown, allowed, meaning]
    return "| " + " | ".join(_cell(c) for c in cells) + " |"


def table(name: str) -> str:
    """Markdown table `name` of `TABLES` or `OPTION_TABLES` (no trailing newline)."""
    if name in OPTION_TABLES:
        rows = [
            _row(f"`--{f.name.replace('_', '-')}`", f)
            for cls in OPTION_TABLES[name]
            for f in fields(cls)
            if "unit" in f.metadata
        ]
        return "\n".join(["| option" + HEADER[0][len("| parameter") :], HEADER[1], *rows])
    groups = tuple(g for cls in TABLES[name] for g in ALL_GROUPS if g.cls is cls)
    return "\n".join(HEADER + [row(s) for s in specs(groups)])


def _keys(module) -> str:
    """The diagnostic key names of `module`'s `KEY_*` constants, in their order."""
    return ", ".join(v for k, v in vars(module).items() if k.startswith("KEY_"))


def topic_types() -> dict[str, str]:
    """Topic -> 'pkg/Type' of every topic the node subscribes to or publishes, from the code."""
    named = {
        **{t: type_name(c) for t, c in INPUTS.items()},
        **messages.OUTPUT_TYPES,
        **{t: type_name(k.msg_type) for t, k in SOUND_INPUTS.items()},
        **AUDIO_COMMON_TOPICS,
        **messages.LISTEN_TYPES,
        diagnostics.TOPIC: "diagnostic_msgs/msg/DiagnosticArray",
        **messages.GUARD_TYPES,
    }
    return {t: n.replace("/msg/", "/") for t, n in named.items()}


def topic_table() -> str:
    """Markdown table of the node's topics (no trailing newline); every topic of the code needs
    an entry in `TOPICS`, and `TOPICS` names no other."""
    types = topic_types()
    if set(types) != set(TOPICS):
        raise ValueError(f"TOPICS and the node's topics differ: {sorted(set(types) ^ set(TOPICS))}")
    rows = ["| topic | type | QoS | meaning |", "|---|---|---|---|"]
    for topic, (direction, qos, meaning) in TOPICS.items():
        meaning = meaning.format(
            prediction=_PREDICTION.format(keys=_keys(status)),
            recording=_RECORDING.format(keys=_keys(diagnostics)),
            measurement=_MEASUREMENT.format(keys=_keys(listen)),
        )
        name = f"`{topic}`" + (f" ({direction})" if direction != "out" else "")
        rows.append("| " + " | ".join(_cell(c) for c in (name, types[topic], qos, meaning)) + " |")
    return "\n".join(rows)


def write(directory: Path | str) -> list[Path]:
    """Write every table as `directory/<name>.md` (and `topics.md`), creating `directory`;
    a file whose text is unchanged is not rewritten (so Sphinx does not rebuild its pages).
    Returns the paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    texts = {**{n: table(n) for n in (*TABLES, *OPTION_TABLES)}, TOPIC_TABLE: topic_table()}
    paths = []
    for name, text in texts.items():
        path = directory / f"{name}.md"
        text = (
            "<!-- generated by tools/param_tables.py from the settings' metadata: "
            "do not edit -->\n\n" + text + "\n"
        )
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
        paths.append(path)
    return paths


def main(argv: list[str] | None = None) -> int:
    names = sys.argv[1:] if argv is None else argv
    if names[:1] == ["--write"] and len(names) == 2:
        for path in write(names[1]):
            print(path)
        return 0
    if names == [TOPIC_TABLE]:
        print(topic_table())
        return 0
    known = (*TABLES, *OPTION_TABLES)
    unknown = set(names) - set(known)
    if unknown:
        print(
            f"unknown table(s) {', '.join(sorted(unknown))}; known: {', '.join(known)}",
            file=sys.stderr,
        )
        return 2
    print("\n\n".join(table(n) for n in names or known))
    return 0


if __name__ == "__main__":
    sys.exit(main())
