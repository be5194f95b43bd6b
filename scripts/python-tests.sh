#!/usr/bin/env bash
# The Python package lane: builds the `ferret` wheel once (maturin, release, abi3), installs it
# into a cached virtual environment and runs pytest on crates/python/tests.
#
#   scripts/python-tests.sh              # build, install, test
#   scripts/python-tests.sh install      # only make the cached venv
#   scripts/python-tests.sh -k search    # more arguments go to pytest
#
# The venv lives under ${FERRET_PY_CACHE:-~/.cache/ferret-python}/venv-<hash of the pinned
# requirements>, made once per set of pins. pip takes its package index from its own
# configuration (PIP_INDEX_URL, pip.conf), never from this script. FERRET_BIN is the `ferret`
# binary the tests compare with (default: this checkout's release build, which cargo brings up
# to date); FERRET_PROCTHOR_DIR switches on the tests on real ProcTHOR houses. The wheel is built
# without CPU-specific flags, so it runs on any x86-64 (or aarch64) Linux with CPython ≥ 3.9.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
REQS="$ROOT/crates/python/requirements-test.txt"
CACHE="${FERRET_PY_CACHE:-$HOME/.cache/ferret-python}"
HASH="$(sha256sum "$REQS" | cut -c1-12)"
VENV="$CACHE/venv-$HASH"
PY="$VENV/bin/python"
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"

log() { printf '[python-tests %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

if ! command -v python3 >/dev/null 2>&1; then
    log "python3 not found: the Python package lane needs CPython ≥ 3.9 with venv"
    exit 1
fi

if [ ! -x "$PY" ] || [ ! -f "$VENV/.complete" ]; then
    log "making $VENV"
    rm -rf "$VENV"
    mkdir -p "$CACHE"
    python3 -m venv "$VENV"
    "$PY" -m pip install --quiet --disable-pip-version-check -r "$REQS"
    touch "$VENV/.complete"
fi
[ "${1:-}" = install ] && exit 0

. "$ROOT/scripts/lib/ferret-wheel.sh"
install_ferret_wheel
# From a scratch directory, so that `import ferret` finds the installed wheel rather than the
# source tree, and no cache is left in the checkout.
cd "$WHEELS"
"$PY" -m pytest -p no:cacheprovider -q "$ROOT/crates/python/tests" "$@"
