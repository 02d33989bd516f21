# SPDX-License-Identifier: Apache-2.0
"""The package's layers: imports flow one way (model -> live -> bag -> review -> ros -> cli),
and the four lower layers import with rclpy and every ROS message package unavailable."""

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from harness.blocker import BLOCKER, ROS_MODULES

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "leadscrew_ros"
LAYERS = ("model", "live", "bag", "review", "ros", "cli")
ROS_FREE = LAYERS[:4]
# Inside `model`, the same one-way rule between its sub-packages (squeak_model is a module).
MODEL_PARTS = (
    "physics",
    "acoustics",
    "uncertainty",
    "squeak_model",
    "studies",
    "calibration",
    "nonlinear",
)


def _modules(layer: str) -> list[str]:
    return sorted(
        ".".join(p.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__")
        for p in (PACKAGE / layer).rglob("*.py")
    )


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute module) of every import in the file, at any depth (functions,
    TYPE_CHECKING blocks included)."""
    module = ".".join(path.relative_to(REPO).with_suffix("").parts)
    package = (
        module.rsplit(".", 1)[0] if path.name != "__init__.py" else module.removesuffix(".__init__")
    )
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                target = f"{base}.{node.module}" if node.module else base
                names = [f"{target}.{a.name}" for a in node.names] if not node.module else []
                out += [(node.lineno, n) for n in names or [target]]
            else:
                out.append((node.lineno, node.module or ""))
    return sorted(out)


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return (
        parts[1] if parts[0] == "leadscrew_ros" and len(parts) > 1 and parts[1] in LAYERS else None
    )


def _model_part(module: str) -> str | None:
    """The sub-package (or `squeak_model`) of a module of `model`; None for `model` itself."""
    parts = module.split(".")
    return (
        parts[2]
        if parts[:2] == ["leadscrew_ros", "model"] and len(parts) > 2 and parts[2] in MODEL_PARTS
        else None
    )


def violations(path: Path) -> list[str]:
    """Imports of `path` that reach a layer above its own, or, inside `model`, a sub-package
    above its own."""
    module = ".".join(path.relative_to(REPO).with_suffix("").parts)
    own, own_part = _layer(module), _model_part(module)
    found = []
    for line, target in _imports(path):
        layer, part = _layer(target), _model_part(target)
        if own and layer and LAYERS.index(layer) > LAYERS.index(own):
            found.append(f"{path.relative_to(REPO)}:{line}: {own} imports {target}")
        elif own_part and part and MODEL_PARTS.index(part) > MODEL_PARTS.index(own_part):
            found.append(f"{path.relative_to(REPO)}:{line}: model.{own_part} imports {target}")
        if own in ROS_FREE and target.split(".")[0] in ROS_MODULES:
            found.append(f"{path.relative_to(REPO)}:{line}: {own} imports {target}")
    return found


def test_every_module_is_in_a_layer():
    top = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert top == ["__init__.py"]
    assert sorted(
        p.name for p in PACKAGE.iterdir() if p.is_dir() and p.name != "__pycache__"
    ) == sorted(LAYERS)


def test_imports_flow_one_way():
    found = [v for p in sorted(PACKAGE.rglob("*.py")) for v in violations(p)]
    assert not found, "\n".join(found)


def test_the_direction_check_sees_a_violation(tmp_path, monkeypatch):
    """The check above can fail: an upward import, relative or absolute, inside a function."""
    fake = tmp_path / "leadscrew_ros" / "bag"
    fake.mkdir(parents=True)
    (fake / "x.py").write_text(
        "def f():\n    from ..ros.node import main\n"
        "import leadscrew_ros.review.replay\nfrom .cdr import y\n"
        "from std_msgs.msg import Float64\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    assert violations(fake / "x.py") == [
        "leadscrew_ros/bag/x.py:2: bag imports leadscrew_ros.ros.node",
        "leadscrew_ros/bag/x.py:3: bag imports leadscrew_ros.review.replay",
        "leadscrew_ros/bag/x.py:5: bag imports std_msgs.msg",
    ]


def test_the_direction_check_sees_a_model_sub_package_violation(tmp_path, monkeypatch):
    """Inside `model`: physics may not import the squeak model, the squeak model not a study."""
    fake = tmp_path / "leadscrew_ros" / "model" / "physics"
    fake.mkdir(parents=True)
    (fake / "x.py").write_text("from ..squeak_model import SqueakModel\nfrom .kernels import k\n")
    (fake.parent / "squeak_model.py").write_text(
        "from .studies.sweep import sweep\nfrom .uncertainty.scatter import Scatter\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    assert violations(fake / "x.py") == [
        "leadscrew_ros/model/physics/x.py:1: model.physics imports leadscrew_ros.model.squeak_model"
    ]
    assert violations(fake.parent / "squeak_model.py") == [
        "leadscrew_ros/model/squeak_model.py:1: model.squeak_model imports "
        "leadscrew_ros.model.studies.sweep"
    ]


@pytest.mark.parametrize("layer", ROS_FREE)
def test_layer_imports_without_ros(layer):
    modules = _modules(layer)
    assert len(modules) >= 3, modules
    code = BLOCKER + (
        f"for n in {modules!r}: importlib.import_module(n)\n"
        "print(len([m for m in sys.modules if m.startswith('leadscrew_ros')]))\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        capture_output=True,
        text=True,
        env=os.environ.copy(),
        timeout=120,
    )
    assert r.returncode == 0, r.stdout + r.stderr


def test_the_blocker_blocks():
    r = subprocess.run(
        [sys.executable, "-c", BLOCKER + "import leadscrew_ros.ros.node\n"],
        cwd=REPO,
        capture_output=True,
        text=True,
        env=os.environ.copy(),
        timeout=120,
    )
    blocked = re.search(r"blocked for this test: (\w+)", r.stderr)
    assert r.returncode != 0 and blocked and blocked[1] in ROS_MODULES, r.stderr


ARCHITECTURE = REPO / "doc" / "development" / "architecture.md"


def _layout_block() -> str:
    page = ARCHITECTURE.read_text(encoding="utf-8")
    return page.split("```\nleadscrew_ros/\n", 1)[1].split("\n```", 1)[0]


def test_architecture_page_lists_every_module_in_its_layer():
    """The tree of doc/development/architecture.md names every module under its layer (and
    sub-package), and nothing that is not there."""
    listed, stack = set(), []
    for line in _layout_block().splitlines():
        if not line.strip():
            continue
        depth, name = (len(line) - len(line.lstrip())) // 2, line.split()[0]
        if depth == 0:
            break  # tools/, config/ ...: outside the package
        if name.endswith("/") or name.endswith(".py"):
            stack = stack[: depth - 1] + [name.rstrip("/")]
            if name.endswith(".py"):
                listed.add("/".join(stack))
    actual = {
        str(p.relative_to(PACKAGE))
        for p in PACKAGE.rglob("*.py")
        if p.name != "__init__.py" or p.parent.name == "cli"
    }
    assert listed == actual
