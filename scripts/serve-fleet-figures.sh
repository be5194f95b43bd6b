#!/usr/bin/env bash
# The figures of docs/serve.md's fleet section: `ferret bench serve` on val150 houses 0..40
# (50 robots × 20 trials by default) as one server on SQLite, before and after (when
# FERRET_BEFORE_BIN names an older ferret binary, alternating runs), and as two replicas on one
# PostgreSQL (and again keeping no replay costs, the control for kept replays), then two
# replicas with one killed (SIGKILL) mid-run. Each line of the output is one
# run's JSON from `ferret bench serve --json`, prefixed by its label.
#
#   FERRET_PROCTHOR_DIR=/abs/path/to/procthor scripts/serve-fleet-figures.sh > figures.jsonl
#
# Needs Debian's PostgreSQL: a throwaway cluster is started (scripts/postgres.sh) unless
# FERRET_TEST_POSTGRES names a server. FERRET_BIN runs a given ferret instead of building this
# checkout's; FERRET_FIG_RUNS sets how many runs of each (default 2). Then robots sharing one
# deployment (`--shared-deployment`), the servers of FERRET_BEFORE_BIN and of this checkout under
# the same robots (`--serve-bin`), on SQLite and on two replicas with PostgreSQL;
# FERRET_FIG_SHARED_ONLY=1 runs only those. Last, trials that never repeat (`--fresh-trials`:
# each from a pose and with a target of its own), the servers of FERRET_BEFORE_BIN and of this
# checkout under the same robots again; FERRET_FIG_FRESH_ONLY=1 runs only those.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:?set FERRET_PROCTHOR_DIR to the ProcTHOR directory}"
RUNS="${FERRET_FIG_RUNS:-2}"
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
log() { printf '[fleet-figures %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }
if [ -z "${FERRET_TEST_POSTGRES:-}" ]; then
    eval "$("$ROOT/scripts/postgres.sh" start)"
    pg_started="$FERRET_PG_DIR"
fi
houses=(--houses "$DATA/multiroom-val150.jsonl.gz" --asset-db "$DATA/databases/asset-database.json"
    --range 0..40)
run() {
    local label="$1"
    shift
    log "$label"
    printf '%s\t' "$label"
    "$@" "${houses[@]}" --json | tr -d '\n '
    echo
}
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"; if [ -n "${pg_started:-}" ]; then "$ROOT/scripts/postgres.sh" stop "$pg_started"; fi' EXIT
only="${FERRET_FIG_SHARED_ONLY:-0}${FERRET_FIG_FRESH_ONLY:-0}"
for ((i = 1; i <= RUNS; i++)); do
    [ "$only" != 00 ] && break
    if [ -n "${FERRET_BEFORE_BIN:-}" ]; then
        run "sqlite-before" "$FERRET_BEFORE_BIN" bench serve
    fi
    run "sqlite" "$ferret" bench serve
    db="$("$ROOT/scripts/postgres.sh" new-db "fleet_$$_$i")"
    run "postgres-2-replicas" "$ferret" bench serve --replicas 2 --db "$db"
    # The control: every trial end replays every other candidate again.
    db="$("$ROOT/scripts/postgres.sh" new-db "fleet_$$_${i}_nokept")"
    run "postgres-2-replicas-kept-replays-0" "$ferret" bench serve --replicas 2 --db "$db" \
        --kept-replays 0
done
if [ "$only" = 00 ]; then
    db="$("$ROOT/scripts/postgres.sh" new-db "fleet_$$_kill")"
    run "postgres-2-replicas-kill" "$ferret" bench serve --replicas 2 --db "$db" --kill-replica-after 5
fi
# before_and_after NAME FLAG: the servers of FERRET_BEFORE_BIN (when given) and of this checkout,
# each a process of its own (`--serve-bin`) under the same robots running `bench serve FLAG`,
# alternating, on SQLite and on two replicas with PostgreSQL.
before_and_after() {
    local name="$1" flag="$2" i who bin db
    for ((i = 1; i <= RUNS; i++)); do
        for who in before this; do
            bin="$ferret"
            if [ "$who" = before ]; then
                [ -n "${FERRET_BEFORE_BIN:-}" ] || continue
                bin="$FERRET_BEFORE_BIN"
            fi
            run "$name-sqlite-$who" "$ferret" bench serve "$flag" --serve-bin "$bin" \
                --db "$tmp/$name-$who-$i.sqlite"
            db="$("$ROOT/scripts/postgres.sh" new-db "fleet_$$_${name}_${who}_$i")"
            run "$name-postgres-2-replicas-$who" "$ferret" bench serve "$flag" \
                --serve-bin "$bin" --replicas 2 --db "$db"
        done
    done
}
# A fleet sharing one deployment.
if [ "${FERRET_FIG_FRESH_ONLY:-0}" != 1 ]; then
    before_and_after shared --shared-deployment
fi
# Trials that never repeat: kept replays are never found again, every end replays every other
# candidate.
if [ "${FERRET_FIG_SHARED_ONLY:-0}" != 1 ]; then
    before_and_after fresh --fresh-trials
fi
