"""config/leadscrew.yaml must list every ScrewParameters field with its default, typed for ROS."""

import math
from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from leadscrew_ros.model.parameters import ScrewParameters, field_names

CONFIG = Path(__file__).resolve().parents[1] / "config" / "leadscrew.yaml"
FIELDS = {f.name: f for f in fields(ScrewParameters)}


def _params() -> dict:
    doc = yaml.safe_load(CONFIG.read_text())
    assert list(doc) == ["squeak_predictor"]
    assert list(doc["squeak_predictor"]) == ["ros__parameters"]
    return doc["squeak_predictor"]["ros__parameters"]


def test_keys_are_the_dataclass_fields():
    assert set(_params()) == set(field_names())


@pytest.mark.parametrize("name", field_names())
def test_value_is_the_default_with_the_right_type(name):
    value, f = _params()[name], FIELDS[name]
    if f.type == "float":
        # float, never int: ROS rejects an integer YAML value for a double parameter
        assert type(value) is float, f"{name}: {value!r} must be written as a float"
        assert math.isclose(value, f.default, rel_tol=1e-12, abs_tol=0.0)
    elif f.type == "int":
        assert type(value) is int, f"{name}: {value!r} must be written as an int"
        assert value == f.default
    else:
        assert type(value) is str
        assert value == f.default


def test_defaults_build_valid_parameters():
    assert ScrewParameters(**_params()) == ScrewParameters()


def test_ros_reads_the_types_we_mean():
    """rcl's own YAML parser (not PyYAML) gives double / integer / string parameters."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    expected = {"float": Parameter.Type.DOUBLE, "int": Parameter.Type.INTEGER,
                "str": Parameter.Type.STRING}
    ctx = Context()
    rclpy.init(context=ctx, args=["--ros-args", "--params-file", str(CONFIG)])
    try:
        node = Node("squeak_predictor", context=ctx,
                    automatically_declare_parameters_from_overrides=True)
        try:
            for name, f in FIELDS.items():
                p = node.get_parameter(name)
                assert p.type_ == expected[f.type], name
                if f.type == "float":
                    assert math.isclose(p.value, f.default, rel_tol=1e-12, abs_tol=0.0), name
                else:
                    assert p.value == f.default, name
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
