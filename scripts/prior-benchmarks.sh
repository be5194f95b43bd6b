#!/usr/bin/env bash
# The calibrated prior against the uncalibrated estimate of earlier versions (model/prior-raw),
# and what a prior knows where it has little or no evidence, with the control that knows nothing
# (fused/noise) beside it: the runs behind docs/llm-vs-prior.md, without an LLM (the lane in
# scripts/real-llm.sh adds the model's rows).
#
#   FERRET_PROCTHOR_DIR=/abs/path/to/procthor scripts/prior-benchmarks.sh
#
# FERRET_BENCH_OUT (default ferret-prior-bench/) receives one directory per run; FERRET_BIN runs
# a given ferret binary instead of building this checkout's.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:-}"
if [ -z "$DATA" ]; then
    echo "set FERRET_PROCTHOR_DIR to the ProcTHOR directory (the houses and the asset database)" >&2
    exit 2
fi
OUT="${FERRET_BENCH_OUT:-$ROOT/ferret-prior-bench}"
FOLDS="${FERRET_BENCH_FOLDS:-5}"
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
mkdir -p "$OUT"
cd "$OUT"
log() { printf '[bench %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }
asset=(--asset-db "$DATA/databases/asset-database.json")
train=(--houses "$DATA/smallhouse-train1000.jsonl.gz" "${asset[@]}")
# A house without any small object has no trial (oneroom-val100 has one): eval reports it and
# exits 1 after writing every other trial, which these tables can use.
quiet() { "$@" >/dev/null || log "  (exit $?: see the messages above; the finished trials were written)"; }

log "calibrated against raw: priors on all 1 500 training houses"
"$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" --out prior.json
"$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" \
    --containers furniture --out prior-furniture.json
both="optimistic+greedy,model/prior-raw,model/prior,model/prior-raw/exact,model/prior/exact,oracle"
# shellcheck disable=SC2054 # one option value, a comma-separated list
pairs=(--paired-against model/prior-raw,model/prior-raw/exact)
for set in multiroom-val150 smallhouse-val100 oneroom-val100; do
    for per in 1 all; do
        log "  $set, trials per house: $per"
        quiet "$ferret" eval --houses "$DATA/$set.jsonl.gz" "${asset[@]}" --prior prior.json \
            --strategies "$both" "${pairs[@]}" --trials-per-house "$per" --out "raw-$set-$per"
    done
done
log "  generated houses (the embedded default and its default prior)"
quiet "$ferret" eval --strategies "$both" "${pairs[@]}" --out raw-generated-1
quiet "$ferret" eval --strategies "$both" "${pairs[@]}" --trials-per-house all --out raw-generated-all
log "  multiroom-val150 under --protocol paper"
quiet "$ferret" eval --houses "$DATA/multiroom-val150.jsonl.gz" "${asset[@]}" \
    --prior prior-furniture.json --protocol paper --strategies "$both" "${pairs[@]}" \
    --out raw-paper-val150

# The priors of the LLM comparisons: training houses 100.. (and oneroom-train500); houses 0..60
# are where fusions are fitted, so a fit sees the prior as it is on houses it never saw.
log "unseen types and few houses, with the control fused/noise"
"$ferret" prior train "${train[@]}" --range 100..1000 --also "$DATA/oneroom-train500.jsonl.gz" \
    --out prior-lane.json
for n in 5 20 100; do
    "$ferret" prior train "${train[@]}" --range "100..$((100 + n))" --out "prior-$n.json"
done
unseen="optimistic+greedy,model/prior-raw,model/prior,model/prior/exact,fused/noise,fused/noise/exact,oracle"
for p in lane 5 20 100; do
    quiet "$ferret" calibrate "${train[@]}" --range 0..60 --prior "prior-$p.json" \
        --targets-per-house 1 --sources model/noise --fit-fusion "fusion-$p.json" \
        --fit-unseen-folds "$FOLDS" --out "fit-$p"
    for per in 1 all; do
        log "  prior $p, trials per house: $per"
        quiet "$ferret" eval --houses "$DATA/multiroom-val150.jsonl.gz" "${asset[@]}" \
            --prior "prior-$p.json" --fusion "fusion-$p.json" --strategies "$unseen" \
            --paired-against model/prior,fused/noise --trials-per-house "$per" --out "seen-$p-$per"
    done
done
for per in 1 all; do
    log "  unseen types ($FOLDS folds), trials per house: $per"
    quiet "$ferret" eval --houses "$DATA/multiroom-val150.jsonl.gz" "${asset[@]}" \
        --prior prior-lane.json --fusion fusion-lane.json --holdout-types "$FOLDS" \
        --strategies "$unseen" --paired-against model/prior,fused/noise --trials-per-house "$per" \
        --out "unseen-lane-$per"
done
log "done; outputs in $OUT"
