#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Static checks with the project's configuration (pyproject.toml), from the repo's .venv:
#   ruff check          lint rules (pyflakes, pycodestyle, isort, bugbear, pyupgrade, pydocstyle)
#   ruff format --check formatting (reports, changes nothing)
#   mypy                type check of leadscrew_ros ([tool.mypy] packages)
# Exit status: 0 when all pass; 1 when any found something (all three always run).
# Fix what can be fixed automatically with: .venv/bin/ruff check --fix . && .venv/bin/ruff format .
set -uo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
set -e
if [[ -n "${LINT_VENV:-}" ]]; then
    # An existing environment that already has the package's dependencies and the tools
    # (e.g. LINT_VENV=/path/to/shared/.venv): used as it is, nothing is installed.
    bin="$LINT_VENV/bin"
else
    source scripts/_venv.sh
    ensure_venv
    # The pinned tools (scripts/lint-requirements.txt), installed once per change of that file.
    stamp=".venv/.lint-$(sha256sum scripts/lint-requirements.txt | cut -d' ' -f1)"
    if [[ ! -e "$stamp" ]]; then
        echo "Installing the lint tools into .venv ..." >&2
        .venv/bin/python -m pip install -q -r scripts/lint-requirements.txt
        rm -f .venv/.lint-*
        touch "$stamp"
    fi
    bin=.venv/bin
fi
set +e

status=0
run() {
    echo "== $*"
    "$@" || status=1
}
run "$bin/ruff" check .
run "$bin/ruff" format --check --output-format=concise .
run "$bin/mypy"
if [[ $status -eq 0 ]]; then
    echo "lint: all checks passed"
else
    echo "lint: FAILED (see above)" >&2
fi
exit "$status"
