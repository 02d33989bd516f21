# SPDX-License-Identifier: Apache-2.0
"""Packaging: package.xml is sound and lists setup.py's dependencies, the version is written
once, colcon builds and installs (the layers: test_layers.py; without ROS:
test_offline_install.py)."""

import json
import os
import runpy
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

import leadscrew_ros

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "leadscrew_ros"
EXEC_DEPENDS = [
    "rclpy",
    "std_msgs",
    "sensor_msgs",
    "geometry_msgs",
    "diagnostic_msgs",
    "std_srvs",
    "python3-numpy",
    "python3-scipy",
    "python3-matplotlib",
]
# What a colcon workspace needs of the source tree (no .venv, build outputs, tests or tools).
SOURCE_ITEMS = ["package.xml", "setup.py", "setup.cfg", "resource", "config", "foxglove", PACKAGE]


def _run(cmd, **kwargs):
    """Run with the parent's environment (the ros-wheels bootstrapper needs it) and capture."""
    kwargs.setdefault("env", os.environ.copy())
    return subprocess.run(cmd, capture_output=True, text=True, **kwargs)


# setup.py's requirements -> their package.xml keys (rosdep keys; the ROS wheels -> ROS packages).
ROSDEP_KEYS = {
    "numpy": ["python3-numpy"],
    "scipy": ["python3-scipy"],
    "matplotlib": ["python3-matplotlib"],
    "tqdm": ["python3-tqdm"],
    "pyyaml": ["python3-yaml"],
    "mcap": ["python3-mcap-pip"],
    "zstandard": ["python3-zstandard"],
    "lz4": ["python3-lz4"],
    "threadpoolctl": ["python3-threadpoolctl"],
    "dask[distributed]": ["python3-dask", "python3-distributed"],
    "emcee": ["python3-emcee"],
    "ros-jazzy-rclpy[fastrtps]": ["rclpy"],
    "ros-jazzy-common-interfaces": [
        "std_msgs",
        "sensor_msgs",
        "geometry_msgs",
        "diagnostic_msgs",
        "std_srvs",
    ],
}


def _setup_kwargs(monkeypatch) -> dict:
    """What setup.py passes to setuptools.setup (run with setup() replaced: nothing is built)."""
    captured: dict = {}
    monkeypatch.chdir(REPO)
    monkeypatch.setattr("setuptools.setup", lambda **kw: captured.update(kw))
    runpy.run_path(str(REPO / "setup.py"), run_name="__main__")
    return captured


def test_the_version_is_written_once(monkeypatch):
    """package.xml's version is setup.py's (the metadata) and leadscrew_ros.__version__ (the
    installed copy's metadata: test_offline_install.py)."""
    version = ET.parse(REPO / "package.xml").getroot().findtext("version")
    r = _run([sys.executable, "setup.py", "--version"], cwd=REPO, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split()[-1] == version
    assert _setup_kwargs(monkeypatch)["version"] == version == leadscrew_ros.__version__
    for path in ("setup.py", "leadscrew_ros/__init__.py"):  # no second copy of the number
        assert f'"{version}"' not in (REPO / path).read_text(), path


def test_package_xml_lists_every_dependency_of_setup_py(monkeypatch):
    kwargs = _setup_kwargs(monkeypatch)
    root = ET.parse(REPO / "package.xml").getroot()
    exec_depends = [e.text for e in root.findall("exec_depend")]
    requires = kwargs["extras_require"]["ros"] + kwargs["install_requires"]
    assert sorted(requires) == sorted(ROSDEP_KEYS)
    assert exec_depends == [k for r in requires for k in ROSDEP_KEYS[r]]  # same order
    # The core needs no ROS wheel; the test extra has them (the suite tests the node).
    assert not [r for r in kwargs["install_requires"] if r.startswith("ros-")]
    assert set(kwargs["extras_require"]["ros"]) <= set(kwargs["extras_require"]["test"])
    assert {"sphinx", "myst-parser", "sphinx-rtd-theme"} <= set(kwargs["extras_require"]["doc"])
    # Keys rosdistro lacks are defined in rosdep/leadscrew_ros.yaml, each with a real rule.
    local = yaml.safe_load((REPO / "rosdep" / "leadscrew_ros.yaml").read_text())
    assert set(local) <= set(exec_depends) and "python3-mcap-pip" in local
    assert all(rules for rules in local.values())


def test_package_xml():
    root = ET.parse(REPO / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == PACKAGE
    assert root.findtext("version") == "0.1.0"
    assert root.findtext("license") == "Apache-2.0"
    assert root.findtext("export/build_type") == "ament_python"
    assert root.find("maintainer").get("email")
    exec_depends = {e.text for e in root.findall("exec_depend")}
    assert set(EXEC_DEPENDS) <= exec_depends
    assert "python3-pytest" in {e.text for e in root.findall("test_depend")}


@pytest.fixture(scope="module")
def colcon_install(tmp_path_factory):
    """`colcon build` (plain; setuptools >= 80 breaks --symlink-install) in a scratch workspace."""
    colcon = Path(sys.executable).parent / "colcon"
    if not colcon.exists():
        pytest.fail(f"colcon not found next to {sys.executable}: pip install -e '.[test]'")
    ws = tmp_path_factory.mktemp("colcon_ws")
    src = ws / "src" / PACKAGE
    src.mkdir(parents=True)
    for item in SOURCE_ITEMS:
        if (REPO / item).is_dir():
            shutil.copytree(
                REPO / item,
                src / item,
                ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"),
            )
        else:
            shutil.copy2(REPO / item, src / item)
    env = dict(os.environ, AMENT_PREFIX_PATH=sys.prefix)
    r = _run(
        [
            str(colcon),
            "--log-base",
            str(ws / "log"),
            "build",
            "--base-paths",
            "src",
            "--event-handlers",
            "console_direct-",
        ],
        cwd=ws,
        env=env,
        timeout=300,
    )
    assert r.returncode == 0, f"colcon build failed:\n{r.stdout}\n{r.stderr}"
    return ws / "install" / PACKAGE


def test_colcon_installs_share_files(colcon_install):
    share = colcon_install / "share"
    assert (share / PACKAGE / "package.xml").is_file()
    assert (share / PACKAGE / "config" / "leadscrew.yaml").is_file()
    assert (share / PACKAGE / "foxglove" / "squeak_predictor.json").is_file()
    assert (share / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()
    # package data: the bundled message definitions (bag/msgdefs.py)
    assert [
        p.name
        for p in colcon_install.glob(
            f"lib/python3*/site-packages/{PACKAGE}/bag/jazzy_msgs/share/std_msgs/msg/Float64.msg"
        )
    ]


def _installed_env(colcon_install):
    site = sorted(colcon_install.glob("lib/python3*/site-packages"))
    assert len(site) == 1, site
    return dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(
            [str(site[0])] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        ),
    )


def test_installed_package_is_the_one_imported(colcon_install, tmp_path):
    r = _run(
        [sys.executable, "-c", "import leadscrew_ros; print(leadscrew_ros.__file__)"],
        cwd=tmp_path,
        env=_installed_env(colcon_install),
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert Path(r.stdout.strip()).resolve().is_relative_to(colcon_install.resolve()), r.stdout


def test_installed_console_script_runs(colcon_install, tmp_path):
    # setup.cfg puts scripts where `ros2 run` looks: lib/<package>/
    script = colcon_install / "lib" / PACKAGE / "leadscrew-squeak"
    assert script.is_file(), sorted(str(p) for p in colcon_install.rglob("leadscrew-squeak"))
    r = _run(
        [str(script), "modes", "--json"],
        cwd=tmp_path,
        env=_installed_env(colcon_install),
        timeout=300,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    modes = json.loads(r.stdout)["modes"]
    assert modes and all({"label", "frequency_hz"} <= set(m) for m in modes)
    assert modes[0]["frequency_hz"] == pytest.approx(224.0, rel=0.005)


def test_license_and_an_spdx_line_in_every_source_file():
    """Apache-2.0 as package.xml and setup.py say: the LICENSE text, a changelog in the ROS
    format, and an SPDX line within the first lines of every tracked source file."""
    assert "Apache License" in (REPO / "LICENSE").read_text()
    assert "Version 2.0, January 2004" in (REPO / "LICENSE").read_text()
    changelog = (REPO / "CHANGELOG.rst").read_text().splitlines()
    assert changelog[1] == f"Changelog for package {PACKAGE}" and "Forthcoming" in changelog
    tracked = _run(["git", "ls-files"], cwd=REPO).stdout.split()
    sources = [f for f in tracked if f.endswith((".py", ".sh", ".yaml", ".cfg")) or f == ".ci/run"]
    assert len(sources) > 50, sources
    missing = [
        f
        for f in sources
        if "SPDX-License-Identifier: Apache-2.0"
        not in "".join((REPO / f).read_text().splitlines(keepends=True)[:3])
    ]
    assert missing == [], missing
