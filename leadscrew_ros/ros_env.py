"""Process plumbing for anything in this package that starts rclpy: environment defaults and
an orderly teardown.

DDS discovery stays on loopback unless the user explicitly chooses otherwise
(`ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET` to talk to another machine). Must run before
`rclpy.init`, which is when the RMW reads the environment.
"""

from __future__ import annotations

import os

import rclpy


def confine_to_localhost(private_domain: bool = False) -> None:
    """Default discovery to localhost; with `private_domain`, also pick a ROS_DOMAIN_ID of this
    process's own (self-contained runs such as the demo) unless one is set."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if private_domain:
        os.environ.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 101))


def close(ctx, executor, nodes) -> None:
    """Remove and destroy `nodes` (in the given order), stop the executor, shut `ctx` down."""
    for node in nodes:
        if executor is not None:
            executor.remove_node(node)
        node.destroy_node()
    if executor is not None:
        executor.shutdown(timeout_sec=1.0)
    rclpy.try_shutdown(context=ctx)
