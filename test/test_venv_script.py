# SPDX-License-Identifier: Apache-2.0
"""scripts/_venv.sh: each README command installs the extras it needs, once (a stamp per extras
set and setup.py/package.xml hash; a superset serves too). pip is a stand-in that logs."""

import os
import shutil
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FAKE_PYTHON = """#!/bin/sh
echo "$*" >> "$(dirname "$0")/../pip.log"
"""


def _ensure(ws: Path, extras: str) -> list[str]:
    """Run `ensure_venv EXTRAS` in `ws`; the pip installs it made ('' entries dropped)."""
    log = ws / ".venv" / "pip.log"
    log.unlink(missing_ok=True)
    r = subprocess.run(
        ["bash", "-c", f"source scripts/_venv.sh && ensure_venv {extras}"],
        cwd=ws,
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ),
    )
    assert r.returncode == 0, r.stderr
    calls = log.read_text().splitlines() if log.exists() else []
    return [c for c in calls if "--upgrade pip" not in c]


def test_stamps_per_extras_set(tmp_path):
    for name in ("setup.py", "package.xml", "scripts"):
        (shutil.copytree if (REPO / name).is_dir() else shutil.copy2)(REPO / name, tmp_path / name)
    python = tmp_path / ".venv" / "bin" / "python"
    python.parent.mkdir(parents=True)
    python.write_text(FAKE_PYTHON)
    python.chmod(0o755)

    assert _ensure(tmp_path, "ros") == ["-m pip install -q -e .[ros]"]  # run-demo
    assert _ensure(tmp_path, "ros") == []  # rerun: fast
    assert _ensure(tmp_path, "ros,test,doc") == ["-m pip install -q -e .[doc,ros,test]"]
    assert _ensure(tmp_path, "ros") == []  # a superset serves run-demo
    assert _ensure(tmp_path, "test,ros,doc") == []  # any order
    assert [p.name.rsplit("-", 1)[1] for p in (tmp_path / ".venv").glob(".installed-*")] == [
        "doc,ros,test"
    ]
    with open(tmp_path / "setup.py", "a") as f:  # a dependency changed: reinstall
        f.write("\n# changed\n")
    assert _ensure(tmp_path, "ros") == ["-m pip install -q -e .[ros]"]
    assert len(list((tmp_path / ".venv").glob(".installed-*"))) == 1
    assert _ensure(tmp_path, "") == []  # the core is in every install
