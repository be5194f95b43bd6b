#!/usr/bin/env bash
# Single-target runs of two ferret binaries, file by file: household tasks must leave every
# single-target output as it was. Runs the same evaluations with FERRET_BEFORE_BIN (an older
# ferret) and this checkout's binary (or FERRET_BIN), then compares trials.csv, summary.csv,
# summary.md, paired.csv, run.json and costs.png byte for byte, and trajectories.png too (its
# title may differ only where an article changed: "a apple" became "an apple"). Then a
# selection over each run (`ferret select`: replay.csv and selection.csv) and a deployment
# (`ferret deploy`: deploy.csv). Prints one line per file: `same` or `DIFFERS`; exits 1 when a
# file other than trajectories.png differs.
#
#   FERRET_BEFORE_BIN=/abs/path/to/old/ferret FERRET_PROCTHOR_DIR=/abs/path/to/procthor \
#       scripts/single-target-identity.sh
#
# The runs: the quick start (100 generated houses, the default strategies), and on
# multiroom-val150 the default strategies, three trials per house with model/prior/exact and
# model/uniform, and the paper protocol. FERRET_ID_OUT keeps the runs' directories there
# (default: a temporary directory, removed at exit).
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:?set FERRET_PROCTHOR_DIR to the ProcTHOR directory}"
before="${FERRET_BEFORE_BIN:?set FERRET_BEFORE_BIN to the ferret binary to compare with}"
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
if [ -n "${FERRET_ID_OUT:-}" ]; then
    out="$FERRET_ID_OUT"
    mkdir -p "$out"
else
    out="$(mktemp -d)"
    trap 'rm -rf "$out"' EXIT
fi
log() { printf '[single-target-identity %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

val=(--houses "$DATA/multiroom-val150.jsonl.gz" --asset-db "$DATA/databases/asset-database.json")
runs=(
    "quickstart|"
    "val150|${val[*]}"
    "val150-3|${val[*]} --trials-per-house 3 --strategies optimistic+greedy,model/uniform,model/prior/exact"
    "val150-paper|${val[*]} --protocol paper --strategies optimistic+greedy,model/prior,model/prior/exact"
)
failed=0
# replay.csv is appended house by house as replays finish, in no fixed order: its rows are
# compared sorted (the key line and header first, as written).
same() {
    if [ "$(basename "$1")" = replay.csv ]; then
        cmp -s <(head -2 "$1"; tail -n +3 "$1" | sort) <(head -2 "$2"; tail -n +3 "$2" | sort)
    else
        cmp -s "$1" "$2"
    fi
}
compare() {
    local name="$1" file="$2"
    if same "$out/before/$name/$file" "$out/after/$name/$file"; then
        printf '%-14s %-18s same\n' "$name" "$file"
    else
        printf '%-14s %-18s DIFFERS\n' "$name" "$file"
        [ "$file" = trajectories.png ] || failed=1
    fi
}
for run in "${runs[@]}"; do
    name="${run%%|*}"
    read -r -a extra <<<"${run#*|}"
    for side in before after; do
        bin="$ferret"
        [ "$side" = before ] && bin="$before"
        dir="$out/$side/$name"
        mkdir -p "$out/$side"
        log "$side: eval $name"
        "$bin" eval "${extra[@]}" --out "$dir" >/dev/null 2>"$dir.log" || {
            echo "$side eval $name failed; see $dir.log" >&2
            exit 1
        }
        log "$side: select $name"
        "$bin" select --trials "$dir" --deployments 20 --trials-per-deployment 20 --out "$dir/select" \
            >/dev/null 2>>"$dir.log"
    done
    for f in trials.csv summary.csv summary.md paired.csv run.json costs.png trajectories.png \
        replay.csv select/selection.csv select/choices.csv select/selection.md; do
        compare "$name" "$f"
    done
done
for side in before after; do
    bin="$ferret"
    [ "$side" = before ] && bin="$before"
    log "$side: deploy"
    "$bin" deploy "${val[@]}" --trials 30 --out "$out/$side/deploy" >/dev/null 2>"$out/$side/deploy.log"
done
compare deploy deploy.csv
exit "$failed"
