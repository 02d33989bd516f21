# SPDX-License-Identifier: Apache-2.0
"""config/leadscrew.yaml holds every parameter of the predictor node (the fields of the settings
dataclasses in ros.parameters.GROUPS) and of the guard node (GUARD_GROUPS: the model's, the
node's own and guard.*) with its default, typed for ROS; it is the text that
tools/gen_config.py generates from the field metadata."""

import math
from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from leadscrew_ros.model.physics.parameters import ScrewParameters, field_names
from leadscrew_ros.ros.parameters import (
    GROUPS,
    GUARD_PARAMETER_NAMES,
    GUARD_PARAMETERS,
    PARAMETER_NAMES,
    PARAMETERS,
    config_yaml,
)

CONFIG = Path(__file__).resolve().parents[1] / "config" / "leadscrew.yaml"
KEY = "/**"
FIELDS = {f.name: f for f in fields(ScrewParameters)}
# name -> (default, type name) for every parameter the predictor node declares
DEFAULTS = {s.name: (s.default, type(s.default).__name__) for s in PARAMETERS}
# and for every entry of the file: the guard node's too
ENTRIES = {**DEFAULTS, **{s.name: (s.default, type(s.default).__name__) for s in GUARD_PARAMETERS}}


def _flat(tree: dict, prefix: str = "") -> dict:
    """ROS parameter names of a nested ros__parameters mapping ({'record': {'enabled': x}} ->
    'record.enabled')."""
    out = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _params(path: Path = CONFIG) -> dict:
    doc = yaml.safe_load(path.read_text())
    assert list(doc) == [KEY]  # any namespace, any node name
    assert list(doc[KEY]) == ["ros__parameters"]
    return _flat(doc[KEY]["ros__parameters"])


def _same(value, default, typ: str) -> bool:
    if typ == "float":
        return math.isclose(value, default, rel_tol=1e-12, abs_tol=0.0)
    return value == default


def test_file_is_the_generated_text():
    assert CONFIG.read_text() == config_yaml(), "run tools/gen_config.py"


def test_generator_tool_checks_and_writes(tmp_path, monkeypatch):
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "gen_config", Path(__file__).resolve().parents[1] / "tools" / "gen_config.py"
    )
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    assert tool.main(["--check"]) == 0
    monkeypatch.setattr(tool, "CONFIG", tmp_path / "leadscrew.yaml")
    assert tool.main(["--check"]) == 1  # missing
    assert tool.main([]) == 0
    assert tool.CONFIG.read_text() == config_yaml()
    tool.CONFIG.write_text(config_yaml().replace("0.005", "0.006", 1))
    assert tool.main(["--check"]) == 1  # edited by hand


def test_every_settings_field_is_a_parameter():
    assert PARAMETER_NAMES == [g.prefix + f.name for g in GROUPS for f in fields(g.cls)]


def test_node_parameter_types_are_plain():
    assert len(set(PARAMETER_NAMES)) == len(PARAMETER_NAMES)
    assert {t for _, t in DEFAULTS.values()} <= {"float", "int", "str", "bool"}


def test_keys_are_the_dataclass_fields_and_the_node_parameters():
    assert set(_params()) == set(PARAMETER_NAMES) | set(GUARD_PARAMETER_NAMES)
    assert set(PARAMETER_NAMES) >= set(field_names())
    assert set(GUARD_PARAMETER_NAMES) >= set(field_names()) | {"guard.p_max", "scatter.samples"}


@pytest.mark.parametrize("name", list(ENTRIES))
def test_value_is_the_default_with_the_right_type(name):
    value, (default, typ) = _params()[name], ENTRIES[name]
    # float, never int: ROS rejects an integer YAML value for a double parameter
    assert type(value).__name__ == typ, f"{name}: {value!r} must be written as a {typ}"
    assert _same(value, default, typ), f"{name}: {value!r} != default {default!r}"


def test_every_entry_has_a_unit_comment():
    lines = [
        ln
        for ln in CONFIG.read_text().splitlines()
        if ln.startswith("    ")
        and not ln.lstrip().startswith("#")
        and not ln.rstrip().endswith(":")
    ]  # nested-name headers
    assert len(lines) == len(ENTRIES)
    for ln in lines:
        assert "# [" in ln and "]" in ln.split("# [", 1)[1], ln


def test_defaults_build_valid_parameters():
    screw = {k: v for k, v in _params().items() if k in FIELDS}
    assert ScrewParameters(**screw) == ScrewParameters()


ROS_TYPES = {"float": "DOUBLE", "int": "INTEGER", "str": "STRING", "bool": "BOOL"}


def test_ros_reads_the_types_we_mean():
    """rcl's own YAML parser (not PyYAML) gives double / integer / string parameters."""
    from rclpy.parameter import Parameter

    from harness.ros import RosWorld

    with RosWorld(args=["--ros-args", "--params-file", str(CONFIG)]) as world:
        node = world.make_node(
            "squeak_predictor", namespace="/", automatically_declare_parameters_from_overrides=True
        )
        assert set(ENTRIES) <= {p for p in node._parameters}
        for name, (default, typ) in ENTRIES.items():
            p = node.get_parameter(name)
            assert p.type_ == Parameter.Type[ROS_TYPES[typ]], name
            assert _same(p.value, default, typ), name


def _node_with_params_file(path: Path) -> dict:
    """Start SqueakPredictorNode with `--ros-args --params-file path`; its parameter values."""
    from harness.ros import RosWorld
    from leadscrew_ros.ros.node import SqueakPredictorNode

    with RosWorld(args=["--ros-args", "--params-file", str(path)]) as world:
        node = world.add(SqueakPredictorNode(context=world.ctx))
        return {name: node.get_parameter(name).value for name in DEFAULTS}


def test_node_started_with_the_file_has_every_value():
    values, expected = _node_with_params_file(CONFIG), _params()
    for name, (_, typ) in DEFAULTS.items():
        assert type(values[name]).__name__ == typ, name
        assert _same(values[name], expected[name], typ), name


def test_node_takes_every_value_from_the_file(tmp_path):
    """A file differing from the defaults in every kind of entry (model, node, read-only)
    really overrides them."""
    changed = {
        "radius_m": 0.006,
        "n_bending": 5,
        "formulation": "consistent",
        "max_rate_hz": 50.0,
        "stale_timeout_s": 2.5,
        "joint_name": "screw_joint",
        "hardware_id": "screw_7",
        "input_queue_depth": 7,
        "record.split_duration_s": 30.0,
        "record.compression": "lz4",
    }
    doc = {KEY: {"ros__parameters": {**_params(), **changed}}}
    path = tmp_path / "changed.yaml"
    path.write_text(yaml.safe_dump(doc))
    values = _node_with_params_file(path)
    for name, (default, typ) in DEFAULTS.items():
        assert _same(values[name], changed.get(name, default), typ), name


def test_guard_node_takes_its_values_from_the_same_file(tmp_path):
    """The predictor's params file configures the guard node: the model's and guard.* values."""
    from harness.ros import RosWorld
    from leadscrew_ros.ros.guard_node import SqueakGuardNode

    changed = {"radius_m": 0.006, "scatter.samples": 64, "guard.p_max": 0.2, "max_rate_hz": 50.0}
    doc = {KEY: {"ros__parameters": {**_params(), **changed}}}
    path = tmp_path / "changed.yaml"
    path.write_text(yaml.safe_dump(doc))
    with RosWorld(args=["--ros-args", "--params-file", str(path)]) as world:
        node = world.add(SqueakGuardNode(autostart=False, context=world.ctx))
        values = {name: node.get_parameter(name).value for name in GUARD_PARAMETER_NAMES}
        assert not node.has_parameter("max_rate_hz")  # the predictor's alone
    for name in GUARD_PARAMETER_NAMES:
        default, typ = ENTRIES[name]
        assert _same(values[name], changed.get(name, default), typ), name
