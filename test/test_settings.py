# SPDX-License-Identifier: Apache-2.0
"""Settings are declared once, in the dataclasses' field metadata: the node's parameter
descriptors, the settings' validation, the replay's --help and the documentation's tables
(rendered at build time by tools/param_tables.py) come from there (config/leadscrew.yaml:
test_config.py; `squeak_node --help`: test_node_seats.py)."""

import importlib.util
import math
import os
import re
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from leadscrew_ros.bag.recorder import RecordSettings
from leadscrew_ros.model.physics.metadata import default_text, range_text
from leadscrew_ros.ros.parameters import (
    GROUPS,
    PARAMETERS,
    NodeSettings,
    RecordingControl,
    build,
    descriptor,
    yaml_value,
)

ROOT = Path(__file__).resolve().parents[1]
SPECS = {s.name: s for s in PARAMETERS}


def _tool(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "tools" / f"{name}.py")
    module = sys.modules[name] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ----------------------------------------------------------------------------- metadata
@pytest.mark.parametrize("cls", [g.cls for g in GROUPS])
def test_every_field_has_complete_metadata(cls):
    for f in fields(cls):
        md = f.metadata
        assert type(f.default).__name__ in ("float", "int", "str", "bool"), f.name
        assert md["description"] and md["description"] == md["description"].strip(), f.name
        assert (md["lo"] is None) == (md["hi"] is None), f.name
        if md["lo"] is not None:
            assert md["lo"] < md["hi"] and not isinstance(f.default, (str, bool)), f.name
        assert not (md["choices"] and md["lo"] is not None), f.name
    cls()  # the defaults are valid


def test_record_settings_limits_mean_what_the_descriptions_say():
    md = {f.name: f.metadata for f in fields(RecordSettings)}
    assert md["split_size_mb"]["lo"] == md["split_duration_s"]["lo"] == 0.0  # 0: never
    assert RecordSettings(split_size_mb=0.0, split_duration_s=0.0)
    assert md["flush_period_s"]["lo"] > 0.0  # a flush period of 0 would flush forever


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(directory=""), "directory must not be empty"),
        (
            dict(compression="gzip"),
            "compression = 'gzip' is not allowed; choose one of zstd, lz4, none",
        ),
        (dict(queue_depth=0), "queue_depth = 0 is out of range, allowed [1, 1000000]"),
        (dict(queue_depth=1_000_001), "queue_depth = 1000001 is out of range"),
        (dict(queue_depth=5.0), "queue_depth = 5.0 must be an int"),
        (dict(flush_period_s=0.0), "flush_period_s = 0 is out of range, allowed [0.05, 10] s"),
        (dict(split_size_mb=math.inf), "split_size_mb = inf must be finite"),
        (dict(split_duration_s=-1.0), "split_duration_s = -1 is out of range"),
        (dict(directory=3), "directory = 3 must be text"),
    ],
)
def test_record_settings_reject_with_the_reason(kwargs, message):
    with pytest.raises(ValueError) as exc:
        RecordSettings(**kwargs)
    assert str(exc.value).startswith(message), exc.value


@pytest.mark.parametrize(
    "cls, kwargs, message",
    [
        (NodeSettings, dict(input_queue_depth=0), "input_queue_depth = 0 is out of range"),
        (NodeSettings, dict(diagnostics_period_s=0.01), "diagnostics_period_s = 0.01 is out"),
        (NodeSettings, dict(hardware_id=None), "hardware_id = None must be text"),
        (RecordingControl, dict(enabled=1), "enabled = 1 must be true or false"),
    ],
)
def test_node_settings_reject_with_the_reason(cls, kwargs, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        cls(**kwargs)


def test_build_names_the_parameter_with_its_prefix():
    values = {s.name: s.default for s in PARAMETERS}
    assert build(RecordSettings, values) == RecordSettings()
    with pytest.raises(ValueError, match=re.escape("record.split_size_mb = -1 is out of range")):
        build(RecordSettings, {**values, "record.split_size_mb": -1.0})
    with pytest.raises(ValueError, match="directory must not be empty"):
        build(RecordSettings, {**values, "record.directory": ""})


@pytest.mark.parametrize(
    "parameter, reason",
    [
        ("formulation:=foo", "formulation = 'foo' is not allowed; choose one of paper, consistent"),
        ("record.compression:=gzip", "record.compression = 'gzip' is not allowed"),
        ("record.directory:=''", "directory must not be empty"),
    ],
)
def test_node_refuses_to_start_with_a_bad_parameter(parameter, reason):
    """Exit 2 with the reason on one line (no traceback), whichever settings class says no."""
    from harness.processes import node_command

    proc = subprocess.run(
        [*node_command(), "--ros-args", "-p", parameter],
        capture_output=True,
        text=True,
        timeout=120,
        env=dict(os.environ),
    )
    assert proc.returncode == 2, proc.stderr
    [line] = proc.stderr.strip().splitlines()
    assert line.startswith(f"squeak_node: error: {reason}"), line


# ----------------------------------------------------------------------------- ROS descriptors
def test_descriptors_carry_the_metadata():
    for spec in PARAMETERS:
        d, md = descriptor(spec), spec.md
        assert d.name == spec.name and d.read_only == md["read_only"]
        assert d.description.startswith(md["description"])
        if md["unit"]:
            assert d.description.endswith(f"[{md['unit']}]")
        ranges = [(r.from_value, r.to_value) for r in (*d.floating_point_range, *d.integer_range)]
        assert ranges == ([] if md["lo"] is None else [(md["lo"], md["hi"])]), spec.name
        if isinstance(spec.default, int) and md["lo"] is not None:
            assert len(d.integer_range) == 1 and not isinstance(spec.default, float)
    assert [s.name for s in PARAMETERS if s.md["read_only"]] == [
        "hardware_id",
        "unit_id",
        "input_queue_depth",
        "inputs.speed.type",
        "inputs.load.type",
        "inputs.nut.type",
        "record.auto_recover",
        "listen.enabled",
    ]
    assert descriptor(SPECS["record.compression"]).additional_constraints == (
        "one of: zstd, lz4, none"
    )
    assert descriptor(SPECS["helix_angle_rad"]).additional_constraints == (
        f"allowed {range_text(SPECS['helix_angle_rad'].md)}"
    )  # open at both ends


# ----------------------------------------------------------------------------- replay --help
REPLAY_OPTIONS = {
    "--speed-deadband": "speed_deadband_rad_s",
    "--load-deadband": "load_deadband_n",
    "--nut-deadband": "nut_deadband_m",
    "--joint-name": "joint_name",
    "--nut-position-at-zero-angle": "nut_position_at_zero_angle_m",
    "--warn-probability": "warn_probability",
    "--error-probability": "error_probability",
}


def test_replay_help_shows_the_settings_defaults_and_ranges():
    out = subprocess.run(
        [sys.executable, "-m", "leadscrew_ros.cli", "replay", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout
    text = " ".join(out.split())
    entries = {e.split()[0]: e for e in re.split(r" (?=--[a-z])", text)}
    for option, name in REPLAY_OPTIONS.items():
        spec, entry = SPECS[name], entries[option]
        assert f"(default {default_text(spec.field)}" in entry, entry
        if spec.md["lo"] is not None:
            assert f"allowed {range_text({**spec.md, 'unit': ''})})" in entry, entry
        if spec.md["unit"] not in ("", "1"):
            assert f"[{spec.md['unit']}]" in entry, entry
    assert "(default 0.1, allowed [0, 1000])" in entries["--speed-deadband"]  # the numbers


# ----------------------------------------------------------------------------- doc tables
param_tables = _tool("param_tables")
DOC = ROOT / "doc"


def test_the_doc_build_writes_every_table(tmp_path):
    """doc/conf.py calls `write` on builder-inited: one file per table, each the rendered table;
    an unchanged table is not rewritten."""
    paths = param_tables.write(tmp_path / "_generated")
    names = [*param_tables.TABLES, *param_tables.OPTION_TABLES, param_tables.TOPIC_TABLE]
    assert [p.name for p in paths] == [f"{n}.md" for n in names]
    for name, path in zip(names, paths, strict=True):
        rendered = (
            param_tables.topic_table()
            if name == param_tables.TOPIC_TABLE
            else param_tables.table(name)
        )
        assert path.read_text(encoding="utf-8").endswith("\n\n" + rendered + "\n")
    before = [p.stat().st_mtime_ns for p in paths]
    os.utime(paths[0], ns=(1, 1))
    param_tables.write(tmp_path / "_generated")
    assert (
        paths[0].stat().st_mtime_ns == 1 and [p.stat().st_mtime_ns for p in paths[1:]] == before[1:]
    )
    conf = (DOC / "conf.py").read_text(encoding="utf-8")
    assert "builder-inited" in conf and '"reference" / "_generated"' in conf


@pytest.mark.parametrize(
    "name", [*param_tables.TABLES, *param_tables.OPTION_TABLES, param_tables.TOPIC_TABLE]
)
def test_the_reference_pages_include_every_table(name):
    include = "```{include} _generated/" + name + ".md\n```"
    pages = "\n".join(p.read_text(encoding="utf-8") for p in (DOC / "reference").glob("*.md"))
    assert include in pages, f"no page of doc/reference/ includes _generated/{name}.md"


def test_tables_list_every_node_setting_once():
    listed = [
        line.split("`")[1]
        for name in param_tables.NODE_TABLES
        for line in param_tables.table(name).splitlines()[2:]
    ]
    own = [
        s.name
        for s in PARAMETERS
        if s.group.cls.__module__ != "leadscrew_ros.model.physics.parameters"
    ]
    assert listed == own
    model = [line.split("`")[1] for line in param_tables.table("model").splitlines()[2:]]
    assert model == [s.name for s in PARAMETERS if s.group.cls is GROUPS[0].cls]
    assert param_tables.main(["bogus"]) == 2


def test_topic_table_names_every_topic_of_the_node_with_its_type():
    from leadscrew_ros.bag import messages
    from leadscrew_ros.ros.node import AUDIO_COMMON_TOPICS, INPUTS, SOUND_INPUTS

    rows = param_tables.topic_table().splitlines()[2:]
    topics = [r.split("`")[1] for r in rows]
    assert topics == list(param_tables.TOPICS)
    assert set(topics) == (
        set(INPUTS)
        | set(messages.OUTPUT_TYPES)
        | set(SOUND_INPUTS)
        | set(AUDIO_COMMON_TOPICS)
        | set(messages.LISTEN_TYPES)
        | {"/diagnostics"}
        | set(messages.GUARD_TYPES)
    )
    assert "| `microphone` (in, with `listen.enabled`) | std_msgs/Float32MultiArray |" in "\n".join(
        rows
    )
    assert "| `squeak/risk` | std_msgs/Float64 |" in rows[4]
    diagnostics = rows[topics.index("/diagnostics")]
    assert "key-values speed_rad_s, load_n," in diagnostics
    assert "bag, files, messages, lost" in diagnostics
    assert "| `guard/reason` (recorded, from `squeak_guard`) | std_msgs/String |" in rows[-1]


@pytest.mark.parametrize("value", [1e-05, 2.5e-07, 1e20, 0.1, 207e9, -3.0, 0.0])
def test_yaml_floats_read_back_as_the_same_float(value):
    """PyYAML (YAML 1.1) reads '1e-05' as text: the generated file writes '1.0e-05'."""
    text = yaml_value(value)
    assert "." in text.partition("e")[0]
    read = yaml.safe_load(f"x: {text}")["x"]
    assert isinstance(read, float) and read == value, text
