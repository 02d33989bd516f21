# SPDX-License-Identifier: Apache-2.0
# Sourced by scripts/run-*.sh: make .venv (in the repo root) and install the package into it.
#   ensure_venv EXTRAS     e.g. `ensure_venv ros` (run-demo.sh), `ensure_venv ros,test,doc`
# installs `pip install -e '.[EXTRAS]'` unless a stamp says that a superset is already there:
# .venv/.installed-<sha256 of setup.py and package.xml>-<extras, sorted, comma separated>.
# So reruns are fast, run-demo after run-tests installs nothing, run-tests after run-demo
# installs the test and doc extras once, and editing setup.py or package.xml (dependencies,
# entry points, version) changes the hash and reinstalls (the stamps of other hashes go).
ensure_venv() {
    local wanted="${1:-}"
    if [[ ! -x .venv/bin/python ]]; then
        python3 -m venv .venv
    fi
    local hash
    hash="$(cat setup.py package.xml | sha256sum | cut -d' ' -f1)"
    local stamp have extra missing
    for stamp in .venv/.installed-"$hash"-*; do
        [[ -e "$stamp" ]] || continue
        have=",${stamp#.venv/.installed-"$hash"-},"
        missing=""
        for extra in ${wanted//,/ }; do
            [[ "$have" == *",$extra,"* ]] || missing=1
        done
        [[ -z "$missing" ]] && return 0
    done
    # Also keep what this hash already has (run-demo after run-tests: no need to drop extras).
    local all="$wanted"
    for stamp in .venv/.installed-"$hash"-*; do
        [[ -e "$stamp" ]] && all="$all,${stamp#.venv/.installed-"$hash"-}"
    done
    all="$(tr ',' '\n' <<<"$all" | sed '/^$/d' | sort -u | paste -sd, -)"
    echo "Installing leadscrew_ros[$all] and its dependencies into .venv ..." >&2
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -e ".${all:+[$all]}"
    rm -f .venv/.installed-*
    touch ".venv/.installed-$hash-$all"
}
