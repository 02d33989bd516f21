# SPDX-License-Identifier: Apache-2.0
"""Everything that creates a ROS 2 node: the squeak predictor node, its parameters and
diagnostics, input recording, the actuator simulator, the demo, live replay and the shutdown
helper."""
