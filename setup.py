# SPDX-License-Identifier: Apache-2.0
"""Packaging for leadscrew_ros (ament_python): works with colcon and with plain pip.

`pip install .` is the core: the model, the log tools (replay, info, recover), the fleet review
and the figures, with no ROS 2 at all. `.[ros]` adds the ROS 2 Jazzy wheels that the node,
`demo`, `simulate` and `replay --publish` need. The version is written once, in package.xml.
"""

import xml.etree.ElementTree as ET
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "leadscrew_ros"
HERE = Path(__file__).resolve().parent
# package.xml is the one place of the version (ROS tools, bloom and catkin_prepare_release read
# and bump it there); `leadscrew_ros.__version__` reads the installed metadata written from this.
VERSION = ET.parse(HERE / "package.xml").getroot().findtext("version").strip()

ROS = [  # the node and everything that starts one; see package.xml
    "ros-jazzy-rclpy[fastrtps]",
    "ros-jazzy-common-interfaces",
]

setup(
    name=PACKAGE,
    version=VERSION,
    description="Live prediction of friction-induced squeak in lead-screw drives (ROS 2)",
    license="Apache-2.0",
    maintainer="leadscrew_ros maintainers",
    maintainer_email="maintainers@leadscrew-ros.example.org",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={
        PACKAGE: ["py.typed"],  # PEP 561: the package ships its type hints
        # Message definitions for logs written without ROS 2 (bag/msgdefs.py,
        # tools/bundle_msgdefs.py)
        f"{PACKAGE}.bag": ["jazzy_msgs/share/*/msg/*.msg"],
    },
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml"))),
        (f"share/{PACKAGE}/foxglove", sorted(glob("foxglove/*.json"))),  # Foxglove layout
    ],
    python_requires=">=3.10",
    # Keep in step with package.xml's <exec_depend>s (test_package.py checks both lists).
    install_requires=[
        "numpy",
        "scipy",
        "matplotlib",
        "tqdm",
        "pyyaml",
        "mcap",
        "zstandard",  # MCAP chunk compression, read and written directly
        "lz4",
        "threadpoolctl",  # eigen-solves run single-threaded (live/recompute.py)
        "dask[distributed]",  # `review`: fleet review on a Dask cluster (review/fleet.py)
        "emcee",  # `calibrate`: the posterior samplers (review/calibration/sampling.py)
    ],
    extras_require={
        "ros": ROS,
        "test": ROS
        + [  # the suite tests the node too
            "pytest",
            "pytest-cov",  # scripts/run-tests.sh: --cov
            "coverage>=7.10",  # .coveragerc: patch = subprocess
            "pytest-timeout",  # setup.cfg: a hung test fails by name
            "pytest-xdist",  # scripts/run-tests.sh: two worker processes
            "hypothesis",
            "sympy",
            "colcon-core",
            "colcon-common-extensions",
            "colcon-ros",
            "mcap-ros2-support",  # an independent decoder of our logs (tests only)
            "rosbags",
            "mosqito",  # acoustics tests: TNR/PR and loudness reference
            "selenium",  # test_doc_browser.py drives Debian's headless Chromium
        ],
        "doc": [  # the Sphinx documentation in doc/ (doc/development/documentation.md)
            "sphinx",
            "myst-parser",
            "numpydoc",
            "sphinx-rtd-theme",
        ],
    },
    zip_safe=False,  # bag/msgdefs.py reads the bundled .msg files by path
    entry_points={
        "console_scripts": [
            "leadscrew-squeak = leadscrew_ros.cli:main",
            # Through the CLI layer: without rclpy it says what to install, in one line.
            "squeak_node = leadscrew_ros.cli.ros:squeak_node",
            "squeak_guard = leadscrew_ros.cli.ros:squeak_guard",
        ],
    },
)
