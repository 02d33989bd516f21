# SPDX-License-Identifier: Apache-2.0
"""Everything that creates a ROS 2 node: the squeak predictor node, its parameters and
diagnostics, input recording, the actuator simulator, the demo, live replay and the shutdown
helper."""

from ..model.exports import lazy

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


# Resolved on first use: importing one module of this layer (e.g. `parameters` for the
# config docs) does not import the others, nor rclpy through them.
__getattr__ = lazy(__name__, _HOMES)
