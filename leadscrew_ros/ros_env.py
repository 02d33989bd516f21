"""Environment defaults for anything in this package that starts rclpy.

DDS discovery stays on loopback unless the user explicitly chooses otherwise
(`ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET` to talk to another machine). Must run before
`rclpy.init`, which is when the RMW reads the environment.
"""

from __future__ import annotations

import os


def confine_to_localhost(private_domain: bool = False) -> None:
    """Default discovery to localhost; with `private_domain`, also pick a ROS_DOMAIN_ID of this
    process's own (self-contained runs such as the demo) unless one is set."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if private_domain:
        os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 101))
