#!/usr/bin/env bash
# The live view lane: `ferret serve`'s page in a real browser. Debian's Chromium, driven by
# Playwright for Python, opens the page of real servers on 127.0.0.1 while a simulated robot
# drives deployments and trials through the API; pytest asserts from the page's DOM that every
# change shows within a second, that a wrong token shows a refusal and no data, that the page
# breaks no Content-Security-Policy and loads nothing from elsewhere, that `--view-only` refuses
# writes, and that a trial driven through one replica on PostgreSQL shows on another's page.
#
#   scripts/browser-tests.sh                          # install (cached), test
#   scripts/browser-tests.sh install                  # only Chromium and the cached venv
#   scripts/browser-tests.sh -k token                 # more arguments go to pytest
#   FERRET_BROWSER_SHOTS=docs scripts/browser-tests.sh -k search   # redraw the screenshots
#
# Chromium comes from Debian (apt-get, so root) when /usr/bin/chromium is missing; Playwright's
# own browser download is never used. Playwright and pytest (pinned in
# crates/serve/tests/browser/requirements.txt) are installed by pip into a venv under
# ${FERRET_BROWSER_CACHE:-~/.cache/ferret-browser}/venv-<hash of the pins>, made once per set of
# pins. pip takes its package index from its own configuration (PIP_INDEX_URL, pip.conf), never
# from this script. FERRET_BIN is the ferret binary to test (default: this checkout's release
# build, which cargo brings up to date). The replicas' database is made on the PostgreSQL of
# FERRET_TEST_POSTGRES, or on a throwaway cluster (scripts/postgres.sh) started for the run and
# stopped after it. FERRET_BROWSER_SHOTS is a directory for the screenshots the tests take.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
TESTS="$ROOT/crates/serve/tests/browser"
REQS="$TESTS/requirements.txt"
CACHE="${FERRET_BROWSER_CACHE:-$HOME/.cache/ferret-browser}"
HASH="$(sha256sum "$REQS" | cut -c1-12)"
VENV="$CACHE/venv-$HASH"
PY="$VENV/bin/python"
CHROMIUM="${FERRET_CHROMIUM:-/usr/bin/chromium}"

log() { printf '[browser-tests %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

if [ ! -x "$CHROMIUM" ]; then
    if [ "$(id -u)" -ne 0 ]; then
        log "$CHROMIUM is missing and installing Debian's chromium needs root"
        exit 1
    fi
    log "installing Debian's chromium"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
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

# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
FERRET_BIN="$(ferret_bin)"
export FERRET_BIN FERRET_CHROMIUM="$CHROMIUM"
if [ -n "${FERRET_BROWSER_SHOTS:-}" ]; then
    mkdir -p "$FERRET_BROWSER_SHOTS"
    FERRET_BROWSER_SHOTS="$(cd "$FERRET_BROWSER_SHOTS" && pwd)"
    export FERRET_BROWSER_SHOTS
fi

log "testing the live view of $FERRET_BIN in $("$CHROMIUM" --version 2>/dev/null || echo "$CHROMIUM")"
# From a scratch directory, so that no cache is left in the checkout; Playwright is told where
# no browser of its own lives, so that nothing tries to fetch one.
WORK="$(mktemp -d /tmp/ferret-browser.XXXXXX)"
trap 'rm -rf "$WORK"' EXIT
cd "$WORK"
PLAYWRIGHT_BROWSERS_PATH="$WORK/no-browsers" PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 \
    "$PY" -m pytest -p no:cacheprovider -q --basetemp="$WORK/tmp" "$TESTS" "$@"
