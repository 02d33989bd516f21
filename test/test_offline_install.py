# SPDX-License-Identifier: Apache-2.0
"""The core install works with no ROS 2 at all: the model, log and review commands run, and the
ROS commands say in one line what to install (exit 2).

Both at once, in one run of every command (offline_cli.py): in a fresh venv (no
--system-site-packages) with a plain `pip install .`, which proves install_requires is complete
without the ROS wheels and the installed package (bundled message definitions, version from the
metadata) works; and there with every ROS 2 module made unimportable by a sitecustomize on
PYTHONPATH whose finder refuses and logs them (in the Dask workers too), which proves that
nothing on the offline path even tries to import rclpy or a message package, indirectly or
optionally. The blocker itself and `squeak_node` are checked in this environment.
"""

import json
import os
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import mcap.reader
import pytest

REPO = Path(__file__).resolve().parents[1]
DRIVER = Path(__file__).with_name("offline_cli.py")
VERSION = ET.parse(REPO / "package.xml").getroot().findtext("version")
# What a core install has none of: rclpy, rosidl_*, the message and interface packages.
ROS_ROOTS = (
    "rclpy",
    "std_msgs",
    "sensor_msgs",
    "builtin_interfaces",
    "rcl_interfaces",
    "diagnostic_msgs",
    "std_srvs",
    "geometry_msgs",
    "rpyutils",
    "ament_index_python",
)
SITECUSTOMIZE = f"""
import importlib.abc, os, sys
class _NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        top = name.partition('.')[0]
        if top in {ROS_ROOTS!r} or top.startswith('rosidl_'):
            log = os.environ.get('LEADSCREW_BLOCKED_LOG')
            if log:
                with open(log, 'a') as f:
                    f.write(name + '\\n')
            raise ModuleNotFoundError(f'No module named {{name!r}} (blocked)', name=name)
        return None
sys.meta_path.insert(0, _NoRos())
"""
INSTALL_ROS = "pip install 'leadscrew_ros[ros]'"
# The source tree pip needs (no .venv, tests, build outputs).
SOURCE_ITEMS = [
    "package.xml",
    "setup.py",
    "setup.cfg",
    "LICENSE",
    "resource",
    "config",
    "foxglove",
    "leadscrew_ros",
]


def _driver(python: str, work: Path, env: dict) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(
        [python, str(DRIVER), str(work)],
        cwd=work,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    return json.loads((work / "report.json").read_text())


def _by_name(report: dict) -> dict:
    return {
        " ".join(c["argv"][:1] + [a for a in c["argv"] if a == "--publish"]): c
        for c in report["commands"]
    }


def _check_commands(report: dict, work: Path) -> None:
    """Every offline command: exit 0 and its expected output; every ROS command: one line."""
    runs = _by_name(report)
    for name in ("demo", "simulate", "replay --publish", "watch", "record", "params"):
        c = runs.pop(name)
        assert (c["code"], c["stdout"], c["stderr"]) == (
            2,
            "",
            f"leadscrew-squeak: error: '{name}' needs ROS 2 (rclpy): {INSTALL_ROS}\n",
        )
    for name, c in runs.items():
        assert c["code"] == 0, (name, c["stderr"])
        assert c["blocked"] == [], (name, c["blocked"])  # not even an optional attempt
    assert report["blocked_by_the_log"] == []
    out = {name: c["stdout"] for name, c in runs.items()}
    assert "B1x" in out["modes"] and "224." in out["modes"]
    assert "squeak modes: B1y 224" in out["predict"]
    assert "valid points: 5/5" in out["sweep"]
    assert len(json.loads(out["map"])["unstable"]) == 3
    assert "fig11_frequency_vs_speed.png" in out["figures"]
    assert (work / "figures" / "summary.txt").is_file()
    assert len(list((work / "figures").glob("*.png"))) >= 8
    assert "linear regime" in out["transient"]
    assert f"{report['log']}" in out["info"] and "/motor_speed" in out["info"]
    assert "nothing to recover" in out["recover"]
    assert (work / "review" / "fleet.csv").is_file()
    # The annotated log's schemas: complete ros2msg text (from the bundled copy without ROS).
    (annotated,) = (work / "replay").glob("*.annotated.mcap")
    with open(annotated, "rb") as f:
        summary = mcap.reader.make_reader(f).get_summary()
    schemas = {s.name: s.data.decode() for s in summary.schemas.values()}
    assert schemas["std_msgs/msg/Float64MultiArray"] == report["definition"]
    assert "MSG: std_msgs/msg/MultiArrayDimension" in report["definition"]


# ----------------------------------------------------------------------------- ROS blocked
@pytest.fixture(scope="module")
def blocked_site(tmp_path_factory) -> Path:
    """A directory whose sitecustomize blocks every ROS 2 module."""
    site = tmp_path_factory.mktemp("no_ros_site")
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    return site


@pytest.fixture(scope="module")
def blocked_env(blocked_site):
    site = blocked_site
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(
            [str(site), str(REPO)]
            + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        ),
    )
    return env


def test_the_blocker_blocks(blocked_env, tmp_path):
    env = dict(blocked_env, LEADSCREW_BLOCKED_LOG=str(tmp_path / "blocked.log"))
    r = subprocess.run(
        [sys.executable, "-c", "import std_msgs.msg"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert r.returncode == 1 and "ModuleNotFoundError: No module named 'std_msgs" in r.stderr
    assert (tmp_path / "blocked.log").read_text() == "std_msgs\n"


def test_squeak_node_with_ros_blocked(blocked_env, tmp_path):
    code = "import sys; from leadscrew_ros.cli.ros import squeak_node; sys.exit(squeak_node())"
    r = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=blocked_env,
        timeout=120,
    )
    assert (r.returncode, r.stdout, r.stderr) == (
        2,
        "",
        f"squeak_node: error: 'squeak_node' needs ROS 2 (rclpy): {INSTALL_ROS}\n",
    )


# ----------------------------------------------------------------------------- clean venv
@pytest.fixture(scope="module")
def clean_venv(tmp_path_factory):
    """A venv of the base interpreter (no --system-site-packages, no pip of its own), then
    `pip install SRC` into it (no extras) by this environment's pip (`pip --python`): the
    dependencies come from the configured index (here a local mirror); no pip cache is read or
    written, no bytecode compiled up front (the commands write what they import, in the venv)."""
    root = tmp_path_factory.mktemp("clean_venv")
    src = root / "src"
    src.mkdir()
    for item in SOURCE_ITEMS:
        if (REPO / item).is_dir():
            shutil.copytree(
                REPO / item,
                src / item,
                ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"),
            )
        else:
            shutil.copy2(REPO / item, src / item)
    # Nothing of this environment may leak in: its ROS wheels' paths, the source tree.
    env = {
        k: v
        for k, v in os.environ.items()
        if k
        not in (
            "PYTHONPATH",
            "AMENT_PREFIX_PATH",
            "LD_LIBRARY_PATH",
            "VIRTUAL_ENV",
            "PYTHONHOME",
            "PYTHONDONTWRITEBYTECODE",
            "_ROS_WHEELS_BOOTSTRAP_COMPLETE",
        )
    }
    venv = root / "venv"
    python = venv / "bin" / "python"
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-m", "venv", "--without-pip", str(venv)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "-q",
            "--no-cache-dir",
            "--no-compile",
            str(src),
        ],
        cwd=root,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    print(f"\nclean venv: created and installed in {time.monotonic() - t0:.1f} s")
    return venv, env


def test_clean_venv_has_no_ros(clean_venv):
    venv, env = clean_venv
    code = (
        "import importlib.metadata as m, importlib.util as u, json; print(json.dumps(["
        "sorted(d.metadata['Name'].lower() for d in m.distributions()), "
        f"[n for n in {ROS_ROOTS!r} if u.find_spec(n)]]))"
    )
    r = subprocess.run(
        [str(venv / "bin" / "python"), "-c", code],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    names, importable = json.loads(r.stdout)
    assert "leadscrew_ros" in names and "mcap" in names and "dask" in names
    assert [n for n in names if n.startswith("ros-") or "rclpy" in n] == [], names
    assert importable == []


def test_offline_commands_in_clean_venv(clean_venv, blocked_site, tmp_path):
    """Both ways at once: the installed package in the clean venv, with the blocker, so that
    an optional attempt to import ROS 2 is seen too (the venv has none to find)."""
    venv, env = clean_venv
    work = tmp_path / "work"
    env = dict(env, PYTHONPATH=str(blocked_site), LEADSCREW_BLOCKED_LOG=str(tmp_path / "b.log"))
    report = _driver(str(venv / "bin" / "python"), work, env)
    assert Path(report["package"]).is_relative_to(venv)  # the installed copy ...
    assert report["version"] == VERSION  # ... its version from metadata
    assert Path(report["definition_prefix"]).is_relative_to(venv)  # the bundled copy
    _check_commands(report, work)
    # the ROS commands did try (and were refused): the check above saw the real path
    assert all(c["blocked"] for c in report["commands"] if c["code"] == 2)


@pytest.mark.parametrize(
    "script, argv, prog",
    [("leadscrew-squeak", ["demo"], "leadscrew-squeak"), ("squeak_node", [], "squeak_node")],
)
def test_ros_executables_in_clean_venv_say_what_to_install(
    clean_venv, tmp_path, script, argv, prog
):
    venv, env = clean_venv
    command = argv[0] if argv else script
    r = subprocess.run(
        [str(venv / "bin" / script), *argv],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert (r.returncode, r.stdout, r.stderr) == (
        2,
        "",
        f"{prog}: error: '{command}' needs ROS 2 (rclpy): {INSTALL_ROS}\n",
    )


def test_bundled_message_definitions_equal_the_installed_ones():
    """leadscrew_ros/bag/jazzy_msgs/ is tools/bundle_msgdefs.py's copy of the ROS 2 wheels'
    definitions (this environment has them: the test extra includes ros)."""
    sys.path.insert(0, str(REPO / "tools"))
    try:
        import bundle_msgdefs
    finally:
        sys.path.remove(str(REPO / "tools"))
    assert bundle_msgdefs.stale() == [], "run tools/bundle_msgdefs.py"
