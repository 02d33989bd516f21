# SPDX-License-Identifier: Apache-2.0
"""Everything that creates a ROS 2 node: the squeak predictor node, its parameters and
diagnostics, input recording, the actuator simulator, the demo, live replay and the shutdown
helper."""

from importlib import import_module
from typing import Any

_HOMES = {
    "ActuatorSimulator": "simulator",
    "NodeSettings": "parameters",
    "SqueakPredictorNode": "node",
    "publish_log": "replay_live",
    "run_demo": "demo",
    "run_simulator": "simulator",
}
__all__ = [
    "ActuatorSimulator",
    "NodeSettings",
    "SqueakPredictorNode",
    "publish_log",
    "run_demo",
    "run_simulator",
]


def __getattr__(name: str) -> Any:
    # Resolved on first use: importing one module of this layer (e.g. `parameters` for the
    # config docs) does not import the others, nor rclpy through them.
    if name in _HOMES:
        return getattr(import_module(f".{_HOMES[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
