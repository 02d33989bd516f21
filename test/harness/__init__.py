# SPDX-License-Identifier: Apache-2.0
"""Shared test harness (not a test module: pytest collects nothing here).

- `ros`: `RosWorld`, one test's rclpy Context + executor + nodes, spun with deadlines.
- `squeak`: `SqueakWorld`, a RosWorld with a probe on the squeak_predictor's topics.
- `processes`: node / CLI child processes on a private domain, and their cleanup.
- `recording`: a recording node process with a feed it already answers.
- `logs`: MCAP / rosbag2 test logs and the replay entry points.
- `blocker`: a Python prelude that makes every ROS package unimportable.
- `cdr_reference`, `contact_quadrature`: independent reference implementations.
- `mosqito_signals`: MoSQITo's tonality test signals made again (no network in CI).

Test modules import from here, never from each other; conftest.py wraps the worlds as
fixtures (`ros_world`, `make_ros_world`, `ros`, `ns`).
"""
