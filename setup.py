# SPDX-License-Identifier: Apache-2.0
"""Packaging for leadscrew_ros (ament_python): works with colcon and with plain pip."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "leadscrew_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    description="Live prediction of friction-induced squeak in lead-screw drives (ROS 2)",
    license="Apache-2.0",
    maintainer="leadscrew_ros maintainers",
    maintainer_email="maintainers@leadscrew-ros.example.org",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={PACKAGE: ["py.typed"]},   # PEP 561: the package ships its type hints
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml"))),
        (f"share/{PACKAGE}/foxglove", sorted(glob("foxglove/*.json"))),   # Foxglove layout
    ],
    python_requires=">=3.10",
    install_requires=[
        "numpy",
        "scipy",
        "matplotlib",
        "tqdm",
        "pyyaml",
        "ros-jazzy-rclpy[fastrtps]",
        "ros-jazzy-common-interfaces",
        "mcap",
        "mcap-ros2-support",
        "zstandard",             # MCAP chunk compression, read and written directly
        "lz4",
        "threadpoolctl",         # the node's eigen-solves run single-threaded (live.py)
        "dask[distributed]",     # `review`: fleet review on a Dask cluster (review/fleet.py)
    ],
    extras_require={
        "test": [
            "pytest",
            "hypothesis",
            "sympy",
            "colcon-core",
            "colcon-common-extensions",
            "colcon-ros",
            "rosbags",
            "mosqito",           # acoustics tests: TNR/PR and loudness reference
        ],
    },
    zip_safe=True,
    entry_points={
        "console_scripts": [
            "leadscrew-squeak = leadscrew_ros.cli:main",
            "squeak_node = leadscrew_ros.ros.node:main",
        ],
    },
)
