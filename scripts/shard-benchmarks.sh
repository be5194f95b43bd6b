#!/usr/bin/env bash
# The figures of docs/scale.md: one machine against 3 shards + merge on multiroom-val150 with
# every target of every house, under ferret's protocol and under the paper's (with a prior
# trained on furniture containers, as scripts/prior-benchmarks.sh does). Every process runs
# under /usr/bin/time -v; the table gives wall time and CPU (user + sys) of each step, and checks
# that the merged trials.csv, summary.csv and paired.csv are the one-machine files byte for byte.
# The shards run one after another, so that their CPU time is measured without contention.
#
#   FERRET_PROCTHOR_DIR=/abs/path/to/procthor scripts/shard-benchmarks.sh
#
# FERRET_BENCH_OUT (default ferret-shard-bench/) receives the runs and times.tsv; FERRET_BIN runs
# a given ferret binary instead of building this checkout's.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:?set FERRET_PROCTHOR_DIR to the ProcTHOR directory}"
OUT="${FERRET_BENCH_OUT:-$ROOT/ferret-shard-bench}"
SHARDS="${FERRET_BENCH_SHARDS:-3}"
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
mkdir -p "$OUT"
cd "$OUT"
log() { printf '[shard-bench %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }
# timed NAME CMD...: runs CMD under /usr/bin/time -v, appends NAME, wall s, user+sys s to times.tsv.
timed() {
    local name="$1"
    shift
    /usr/bin/time -v -o "$name.time" "$@" >"$name.log" 2>&1 || {
        log "  $name failed (exit $?): see $OUT/$name.log"
        return 1
    }
    awk -v n="$name" '
        /User time/ {u=$NF} /System time/ {s=$NF}
        /Elapsed \(wall clock\)/ {split($NF, t, ":"); w = (length(t) == 3) ? t[1]*3600+t[2]*60+t[3] : t[1]*60+t[2]}
        END {printf "%s\t%.2f\t%.2f\n", n, w, u+s}' "$name.time" >>times.tsv
}
: >times.tsv
asset=(--asset-db "$DATA/databases/asset-database.json")
val=(--houses "$DATA/multiroom-val150.jsonl.gz" "${asset[@]}" --trials-per-house all)
log "prior on furniture containers (for --protocol paper)"
"$ferret" prior train --houses "$DATA/smallhouse-train1000.jsonl.gz" "${asset[@]}" \
    --also "$DATA/oneroom-train500.jsonl.gz" --containers furniture --out prior-furniture.json \
    >/dev/null
for proto in default paper; do
    extra=()
    [ "$proto" = paper ] && extra=(--protocol paper --prior prior-furniture.json)
    log "$proto: one machine"
    timed "$proto-one" "$ferret" eval "${val[@]}" "${extra[@]}" --out "$proto-one"
    dirs=()
    for ((i = 0; i < SHARDS; i++)); do
        log "$proto: shard $i/$SHARDS"
        timed "$proto-shard$i" "$ferret" eval "${val[@]}" "${extra[@]}" --shard "$i/$SHARDS" \
            --out "$proto-shard$i"
        dirs+=("$proto-shard$i")
    done
    log "$proto: merge"
    timed "$proto-merge" "$ferret" merge "${dirs[@]}" --out "$proto-merged"
    for f in trials.csv summary.csv paired.csv; do
        cmp "$proto-one/$f" "$proto-merged/$f"
    done
    log "$proto: merged trials.csv, summary.csv, paired.csv are the one-machine files"
done
column -t times.tsv >&2
