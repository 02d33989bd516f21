# SPDX-License-Identifier: Apache-2.0
"""The session deadline (harness/session_deadline.py): past it no test starts, and pytest still
ends with its summary, the failures named and the tests that never ran counted, with xdist
workers and without; the failures file names each failure as it happens. Run on a small suite
of its own in a child pytest, so the deadline is certainly passed after each worker's first
test whatever the machine's load."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
FIRST = ("test_one.py::test_fails", "test_two.py::test_fails")  # each file's first test
SUITE = {
    name.split("::")[0]: "def test_fails():\n    assert 1 == 2\n\n"
    + "".join(f"def test_passes_{k}():\n    pass\n\n" for k in range(4))
    for name in FIRST
}


def _pytest(tmp_path: Path, workers: int, deadline_s: str | None) -> tuple[int, str, str]:
    for name, text in SUITE.items():
        (tmp_path / name).write_text(text)
    env = {k: v for k, v in os.environ.items() if k not in ("SESSION_DEADLINE_S",)}
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), env.get("PYTHONPATH", "")])
    env["FAILURES_FILE"] = str(tmp_path / "failures.txt")
    env.pop("PYTEST_XDIST_WORKER", None)  # the child is a session of its own
    if deadline_s is not None:
        env["SESSION_DEADLINE_S"] = deadline_s
    args = ["-p", "harness.session_deadline", "-p", "no:cacheprovider", "-q", "-n", str(workers)]
    done = subprocess.run(
        [sys.executable, "-m", "pytest", *args, "--dist", "loadfile", "-rf", str(tmp_path)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    failures = tmp_path / "failures.txt"
    return done.returncode, done.stdout, failures.read_text() if failures.exists() else ""


@pytest.mark.parametrize("workers", [0, 2])
def test_past_the_deadline_no_test_starts_and_the_summary_says_what_never_ran(tmp_path, workers):
    code, out, failures = _pytest(tmp_path, workers, "0.001")
    assert code == pytest.ExitCode.INTERRUPTED, out
    assert "session deadline: 0.001 s passed" in out
    ran = [line.split()[1] for line in failures.splitlines()]  # only first tests can fail
    assert 1 <= len(ran) <= max(workers, 1) and set(ran) <= set(FIRST), failures
    assert all(f"FAILED {nodeid}" in out for nodeid in ran)
    assert "tests that never ran" in out
    never = int(out.split(" collected tests never ran")[0].rsplit("\n", 1)[-1].split(" of ")[0])
    assert never == 10 - len(ran)  # each worker stopped after its first test


@pytest.mark.parametrize("workers", [0, 2])
def test_without_a_deadline_every_test_runs(tmp_path, workers):
    code, out, failures = _pytest(tmp_path, workers, None)
    assert code == pytest.ExitCode.TESTS_FAILED, out
    assert "2 failed, 8 passed" in out and "never ran" not in out
    assert sorted(failures.splitlines()) == [f"FAILED {nodeid} (call)" for nodeid in FIRST]
