# SPDX-License-Identifier: Apache-2.0
"""config/leadscrew.yaml holds every parameter of the node (ScrewParameters fields and
the live and joint settings, node.NODE_PARAMETERS) with its default, typed for ROS."""

import math
from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from leadscrew_ros.model.parameters import ScrewParameters, field_names
from leadscrew_ros.ros.node import PARAMETER_NAMES, parameter_specs

CONFIG = Path(__file__).resolve().parents[1] / "config" / "leadscrew.yaml"
KEY = "/**"
FIELDS = {f.name: f for f in fields(ScrewParameters)}
# name -> (default, type name) for every parameter the node declares
DEFAULTS = {name: (default, type(default).__name__) for name, default, *_ in parameter_specs()}


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
    assert list(doc) == [KEY]            # any namespace, any node name
    assert list(doc[KEY]) == ["ros__parameters"]
    return _flat(doc[KEY]["ros__parameters"])


def _same(value, default, typ: str) -> bool:
    if typ == "float":
        return math.isclose(value, default, rel_tol=1e-12, abs_tol=0.0)
    return value == default


def test_node_parameter_types_are_plain():
    assert len(set(PARAMETER_NAMES)) == len(PARAMETER_NAMES)
    assert {t for _, t in DEFAULTS.values()} <= {"float", "int", "str", "bool"}


def test_keys_are_the_dataclass_fields_and_the_node_parameters():
    assert set(_params()) == set(PARAMETER_NAMES) >= set(field_names())


@pytest.mark.parametrize("name", list(DEFAULTS))
def test_value_is_the_default_with_the_right_type(name):
    value, (default, typ) = _params()[name], DEFAULTS[name]
    # float, never int: ROS rejects an integer YAML value for a double parameter
    assert type(value).__name__ == typ, f"{name}: {value!r} must be written as a {typ}"
    assert _same(value, default, typ), f"{name}: {value!r} != default {default!r}"


def test_every_entry_has_a_unit_comment():
    lines = [ln for ln in CONFIG.read_text().splitlines()
             if ln.startswith("    ") and not ln.lstrip().startswith("#")
             and not ln.rstrip().endswith(":")]                 # nested-name headers
    assert len(lines) == len(DEFAULTS)
    for ln in lines:
        assert "# [" in ln and "]" in ln.split("# [", 1)[1], ln


def test_defaults_build_valid_parameters():
    screw = {k: v for k, v in _params().items() if k in FIELDS}
    assert ScrewParameters(**screw) == ScrewParameters()


ROS_TYPES = {"float": "DOUBLE", "int": "INTEGER", "str": "STRING", "bool": "BOOL"}


def test_ros_reads_the_types_we_mean():
    """rcl's own YAML parser (not PyYAML) gives double / integer / string parameters."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    ctx = Context()
    rclpy.init(context=ctx, args=["--ros-args", "--params-file", str(CONFIG)])
    try:
        node = Node("squeak_predictor", context=ctx,
                    automatically_declare_parameters_from_overrides=True)
        try:
            assert set(DEFAULTS) <= {p for p in node._parameters}
            for name, (default, typ) in DEFAULTS.items():
                p = node.get_parameter(name)
                assert p.type_ == Parameter.Type[ROS_TYPES[typ]], name
                assert _same(p.value, default, typ), name
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def _node_with_params_file(path: Path) -> dict:
    """Start SqueakPredictorNode with `--ros-args --params-file path`; its parameter values."""
    import rclpy
    from rclpy.context import Context

    from leadscrew_ros.ros.node import SqueakPredictorNode

    ctx = Context()
    rclpy.init(context=ctx, args=["--ros-args", "--params-file", str(path)])
    try:
        node = SqueakPredictorNode(context=ctx)
        try:
            return {name: node.get_parameter(name).value for name in DEFAULTS}
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_node_started_with_the_file_has_every_value():
    values, expected = _node_with_params_file(CONFIG), _params()
    for name, (_, typ) in DEFAULTS.items():
        assert type(values[name]).__name__ == typ, name
        assert _same(values[name], expected[name], typ), name


def test_node_takes_every_value_from_the_file(tmp_path):
    """A file differing from the defaults in every kind of entry (model, node, read-only)
    really overrides them."""
    changed = {"radius_m": 0.006, "n_bending": 5, "formulation": "consistent",
               "max_rate_hz": 50.0, "stale_timeout_s": 2.5, "joint_name": "screw_joint",
               "hardware_id": "screw_7", "input_queue_depth": 7,
               "record.split_duration_s": 30.0, "record.compression": "lz4"}
    doc = {KEY: {"ros__parameters": {**_params(), **changed}}}
    path = tmp_path / "changed.yaml"
    path.write_text(yaml.safe_dump(doc))
    values = _node_with_params_file(path)
    for name, (default, typ) in DEFAULTS.items():
        assert _same(values[name], changed.get(name, default), typ), name
