#!/usr/bin/env bash
# The live view's figures of docs/serve.md: what open pages cost a fleet. `ferret bench serve`
# with 50 robots on two replicas sharing a throwaway PostgreSQL, val150 houses 0..40, run
# without pages and with 5 reading pages and 1 stalled one (`--pages 5 --stalled-pages 1`),
# alternating, FERRET_FIG_RUNS times each (default 3), so both are measured in one run under the
# same machine. Then the memory run: 50 robots × 40 trials on houses 0..5 (every grid built
# early), with and without pages, the first replica's resident memory from a quarter into the
# run (about 24 000 events). With FERRET_BEFORE_BIN naming an older ferret binary, each round
# first runs its servers (`--serve-bin`, no pages) under the same robots: what publishing
# events costs a fleet with no page open. Each line of the output is one run's JSON from
# `ferret bench serve --json`, prefixed by its label.
#
#   FERRET_PROCTHOR_DIR=/abs/path/to/procthor scripts/serve-view-figures.sh > view.jsonl
#
# Needs Debian's PostgreSQL: a throwaway cluster is started (scripts/postgres.sh) unless
# FERRET_TEST_POSTGRES names a server. FERRET_BIN runs a given ferret instead of building this
# checkout's.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:?set FERRET_PROCTHOR_DIR to the ProcTHOR directory}"
RUNS="${FERRET_FIG_RUNS:-3}"
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
log() { printf '[view-figures %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }
if [ -z "${FERRET_TEST_POSTGRES:-}" ]; then
    eval "$("$ROOT/scripts/postgres.sh" start)"
    pg_started="$FERRET_PG_DIR"
fi
trap 'if [ -n "${pg_started:-}" ]; then "$ROOT/scripts/postgres.sh" stop "$pg_started"; fi' EXIT
houses=(--houses "$DATA/multiroom-val150.jsonl.gz" --asset-db "$DATA/databases/asset-database.json")
run() {
    local label="$1"
    shift
    log "$label"
    printf '%s\t' "$label"
    local db
    db="$("$ROOT/scripts/postgres.sh" new-db "view_$$_${label//-/_}_$i")"
    "$ferret" bench serve --replicas 2 --db "$db" "${houses[@]}" "$@" --json | tr -d '\n '
    echo
}
for ((i = 1; i <= RUNS; i++)); do
    if [ -n "${FERRET_BEFORE_BIN:-}" ]; then
        run "before" --range 0..40 --serve-bin "$FERRET_BEFORE_BIN"
    fi
    run "no-pages" --range 0..40
    run "5-pages" --range 0..40 --pages 5 --stalled-pages 1
done
i=memory
run "memory-no-pages" --range 0..5 --trials 40
run "memory-5-pages" --range 0..5 --trials 40 --pages 5 --stalled-pages 1
