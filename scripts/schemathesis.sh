#!/usr/bin/env bash
# The API contract lane: Schemathesis with every check against a real `ferret serve` on
# 127.0.0.1, driven by the server's own /openapi.json. A request the document calls valid must
# be accepted, an invalid one refused with a 4xx, and every reply must be one the document lists
# for its route, in the documented shape.
#
#   scripts/schemathesis.sh             # install (cached), serve, test, stop the server
#   scripts/schemathesis.sh install     # only make the cached venv
#
# FERRET_BIN runs a given ferret binary instead of building this checkout's (scripts/lib/
# ferret-bin.sh). Schemathesis (pinned below) is installed with pip
# into a venv under $FERRET_ST_CACHE (default ~/.cache/ferret-schemathesis), once. pip takes its
# package index from its own configuration (PIP_INDEX_URL, pip.conf), never from this script.
# FERRET_ST_EXAMPLES sets the examples per operation (default 60). FERRET_ST_DB gives the server
# another database (a PostgreSQL URL, say; default a new SQLite file).
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
CACHE="${FERRET_ST_CACHE:-$HOME/.cache/ferret-schemathesis}"
VERSION=4.32.5
EXAMPLES="${FERRET_ST_EXAMPLES:-60}"
ST="$CACHE/venv/bin/st"

log() { printf '[schemathesis %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

install() {
    local installed=""
    if [ -x "$ST" ]; then
        installed="$("$CACHE/venv/bin/python" -m pip show schemathesis 2>/dev/null || true)"
    fi
    if printf '%s\n' "$installed" | grep -qx "Version: $VERSION"; then
        return
    fi
    log "installing schemathesis $VERSION into $CACHE/venv"
    mkdir -p "$CACHE"
    python3 -m venv "$CACHE/venv"
    "$CACHE/venv/bin/python" -m pip install --quiet "schemathesis==$VERSION"
}

install
[ "${1:-}" = install ] && exit 0

# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
BIN="$(ferret_bin)"

WORK="$(mktemp -d)"
SERVER_PID=""
cleanup() {
    if [ -n "$SERVER_PID" ]; then
        kill "$SERVER_PID" 2>/dev/null || true
        wait "$SERVER_PID" 2>/dev/null || true
    fi
    rm -rf "$WORK"
}
trap cleanup EXIT

# With a token, so that the document's security and the 401s are checked too.
TOKEN="schemathesis-$$-$RANDOM"
FERRET_SERVE_TOKEN="$TOKEN" "$BIN" serve \
    --scene "$ROOT/examples/apartment/scene.yaml" \
    --strategies optimistic+greedy,model/uniform \
    --listen 127.0.0.1:0 --db "${FERRET_ST_DB:-$WORK/serve.sqlite}" \
    >"$WORK/serve.out" 2>"$WORK/serve.err" &
SERVER_PID=$!
URL=""
for _ in $(seq 1 300); do
    URL="$(grep -o 'http://127\.0\.0\.1:[0-9]*' "$WORK/serve.out" 2>/dev/null | head -n 1 || true)"
    [ -n "$URL" ] && break
    if ! kill -0 "$SERVER_PID" 2>/dev/null; then
        cat "$WORK/serve.err" >&2
        log "ferret serve did not start"
        exit 1
    fi
    sleep 0.1
done
[ -n "$URL" ] || { log "ferret serve printed no address"; exit 1; }
log "testing $URL/openapi.json ($EXAMPLES examples per operation)"

started=$(date +%s)
status=0
# scripts/schemathesis_hooks.py gives every valid request id a fresh value (see there).
# GET /events, an event stream that never ends, is read for a second at most per case
# (scripts/schemathesis.toml): each event against the document's itemSchema and its data against
# the event's contentSchema.
# The token goes through the document's security scheme (scripts/schemathesis.toml), not as a
# header on every request, so that cases leaving it out really leave it out; the document itself
# is fetched with it first.
curl -sf -H "Authorization: Bearer $TOKEN" "$URL/openapi.json" -o "$WORK/openapi.json"
(cd "$WORK" && FERRET_ST_TOKEN="$TOKEN" PYTHONPATH="$ROOT/scripts" SCHEMATHESIS_HOOKS=schemathesis_hooks "$ST" --config-file "$ROOT/scripts/schemathesis.toml" run "$WORK/openapi.json" --url "$URL" --checks all -n "$EXAMPLES" \
    --seed 1 --no-color) || status=$?
log "finished in $(( $(date +%s) - started )) s with status $status"
if [ "$status" -ne 0 ]; then
    tail -n 40 "$WORK/serve.err" >&2
    exit "$status"
fi
