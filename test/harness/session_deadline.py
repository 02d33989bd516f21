# SPDX-License-Identifier: Apache-2.0
"""A deadline for the whole test session, as a pytest plugin (test/conftest.py imports its
hooks; a test of it loads it with `-p harness.session_deadline`).

A loaded machine can make the whole suite slower than the outer `timeout` of
scripts/run-tests.sh, which kills pytest without a summary. With SESSION_DEADLINE_S set (the
script does), no test starts after the deadline: the running ones end, pytest prints what
failed and names what never ran, and exits non-zero. FAILURES_FILE, if set, gets each
failure's name as it happens, for the script to print should the outer guard fire after all.
"""

from __future__ import annotations

import os
import time

import pytest

_DEADLINE_AT = "LEADSCREW_TEST_DEADLINE_AT"  # epoch seconds, shared with xdist's workers
_WORKER = "PYTEST_XDIST_WORKER" in os.environ
_session = None
_collected: set[str] = set()  # node ids (the controller's, or a run without xdist)
_reported: set[str] = set()


def pytest_configure(config):
    seconds = os.environ.get("SESSION_DEADLINE_S")
    if seconds and not _WORKER:  # the controller, or a run without xdist
        os.environ[_DEADLINE_AT] = str(time.time() + float(seconds))


def pytest_sessionstart(session):
    global _session
    _session = session


def pytest_runtest_logfinish(nodeid, location):
    deadline = os.environ.get(_DEADLINE_AT)
    if deadline and time.time() > float(deadline) and _session is not None:
        _session.shouldstop = (
            f"session deadline: {os.environ.get('SESSION_DEADLINE_S')} s passed "
            "(SESSION_DEADLINE_S), no test started after it"
        )


def pytest_collection_finish(session):
    _collected.update(item.nodeid for item in session.items)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node, ids):
    _collected.update(ids)


def pytest_runtest_logreport(report):
    if _WORKER:
        return
    if report.when == "call" or report.outcome != "passed":
        _reported.add(report.nodeid)
    if report.failed and os.environ.get("FAILURES_FILE"):
        with open(os.environ["FAILURES_FILE"], "a", encoding="utf-8") as f:
            f.write(f"FAILED {report.nodeid} ({report.when})\n")


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    never = sorted(_collected - _reported)
    if _WORKER or not never or config.option.collectonly:
        return
    per_file: dict[str, int] = {}
    for nodeid in never:
        path = nodeid.split("::", 1)[0]
        per_file[path] = per_file.get(path, 0) + 1
    terminalreporter.section("tests that never ran", sep="=", red=True)
    for path, count in per_file.items():
        terminalreporter.line(f"{path}: {count} not run")
    terminalreporter.line(f"{len(never)} of {len(_collected)} collected tests never ran")
