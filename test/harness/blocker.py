# SPDX-License-Identifier: Apache-2.0
"""A Python prelude for `python -c` children: every ROS package becomes unimportable, so a
child proves that what it imports needs none (the ROS-free layers, the message encoders)."""

# What a module of a ROS-free layer may not import, directly or through a dependency.
ROS_MODULES = (
    "rclpy",
    "rcl_interfaces",
    "builtin_interfaces",
    "std_msgs",
    "sensor_msgs",
    "diagnostic_msgs",
    "std_srvs",
    "geometry_msgs",
    "rosidl_runtime_py",
    "rosidl_parser",
    "rpyutils",
)

BLOCKER = f"""
import importlib, importlib.abc, sys
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {ROS_MODULES!r}:
            raise ImportError('blocked for this test: ' + name)
sys.meta_path.insert(0, Block())
"""
