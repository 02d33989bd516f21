# SPDX-License-Identifier: Apache-2.0
# Sourced by scripts/run-*.sh: make .venv (in the repo root) and install the package into it.
# The pip step is skipped while .venv/.installed-<sha256 of setup.py> exists, so reruns are fast;
# editing setup.py (dependencies, entry points) changes the hash and reinstalls.
# Both scripts install '.[test,doc]' so that one stamp serves both (the extras are small).
ensure_venv() {
    if [[ ! -x .venv/bin/python ]]; then
        python3 -m venv .venv
    fi
    local stamp
    stamp=".venv/.installed-$(sha256sum setup.py | cut -d' ' -f1)"
    if [[ ! -e "$stamp" ]]; then
        echo "Installing leadscrew_ros and its dependencies into .venv ..." >&2
        .venv/bin/python -m pip install -q --upgrade pip
        .venv/bin/python -m pip install -q -e '.[test,doc]'
        rm -f .venv/.installed-*
        touch "$stamp"
    fi
}
