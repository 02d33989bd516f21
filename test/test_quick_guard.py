# SPDX-License-Identifier: Apache-2.0
"""benchmarks/quick.py, CI's regression guard: a ratio above its target is reported (MISSED)
without failing; only one above `FAIL_FACTOR` times its target fails the run (exit 1). The
ratios here are made up around the real targets (no timing is measured)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import quick  # noqa: E402

TARGET = quick.bench_contact.TARGET  # an upper bound of its ratio, as every quick.py target


@pytest.mark.parametrize(
    ("times_target", "expected"),
    [
        (0.5, "met"),
        (1.0, "met"),
        (1.01, "MISSED"),
        (quick.FAIL_FACTOR, "MISSED"),
        (quick.FAIL_FACTOR * 1.01, "FAILED"),
        (10.0, "FAILED"),
    ],
)
def test_verdict_of_a_ratio_against_its_target(times_target, expected):
    assert quick.verdict(times_target * TARGET, TARGET) == expected


def test_a_row_without_a_target_never_fails():
    assert quick.verdict(1e9, None) == ""


def _run(monkeypatch, capsys, table):
    monkeypatch.setattr(quick, "rows", lambda: table)
    code = quick.main()
    return code, capsys.readouterr()


def _row(i, ratio, target=TARGET, again=None):
    return (f"row {i}", "bench_x.py", ratio, target, again)


def test_missed_targets_keep_exit_code_0(monkeypatch, capsys):
    code, out = _run(
        monkeypatch, capsys, [_row(0, 0.9 * TARGET), _row(1, 1.9 * TARGET), _row(2, 3.0, None)]
    )
    assert code == 0
    assert "| row 0 | bench_x.py |" in out.out and "met |" in out.out
    assert "MISSED |" in out.out and "FAILED |" not in out.out
    assert out.err == ""


def test_a_ratio_beyond_twice_its_target_in_every_run_fails_and_says_which(monkeypatch, capsys):
    runs = []

    def again():
        runs.append(2.5 * TARGET)
        return runs[-1]

    code, out = _run(
        monkeypatch,
        capsys,
        [
            _row(0, 0.9 * TARGET, again=again),
            _row(1, 2.5 * TARGET, again=again),
            _row(2, 3.0, None),
        ],
    )
    assert code == 1
    assert len(runs) == quick.RETRIES  # row 1 measured again, row 0 not
    assert "FAILED (runs:" in out.out  # the table is printed in full
    assert "| row 2 |" in out.out
    assert "row 1" in out.err and "row 0" not in out.err


def test_noise_over_the_fail_line_once_does_not_fail(monkeypatch, capsys):
    code, out = _run(monkeypatch, capsys, [_row(0, 2.5 * TARGET, again=lambda: 1.2 * TARGET)])
    assert code == 0
    assert "MISSED (runs:" in out.out and out.err == ""
