#!/usr/bin/env bash
# The figures of docs/tasks.md: household tasks on multiroom-val150 with the calibrated prior
# trained on the 1 500 small training houses. For each task kind (all of 2, all of 3, any of 2;
# each without a destination and brought to the start) one `ferret eval` of optimistic+greedy,
# sequential/model/prior (one search after another), model/prior (the task planner, K = 8),
# model/uniform (the same planner knowing nothing) and the oracle, compared in pairs against
# sequential; then what the K-candidate cap costs on all of 3 brought to the start (K = 8, 12,
# exact, each the wall time of its run), the same strategies in the prior's own world
# (crates/lab/examples/prior_world.rs), and the planner's decision latency
# (`ferret bench planner --targets`).
#
#   FERRET_PROCTHOR_DIR=/abs/path/to/procthor scripts/task-figures.sh > figures.md
#
# FERRET_BIN runs a given ferret instead of building this checkout's; FERRET_FIG_TRIALS sets the
# tasks per house (default 3: 450 paired tasks per kind); FERRET_FIG_OUT keeps the runs'
# directories there (default: a temporary directory, removed at exit). Progress goes to stderr.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:?set FERRET_PROCTHOR_DIR to the ProcTHOR directory}"
PER_HOUSE="${FERRET_FIG_TRIALS:-3}"
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
# shellcheck source=scripts/lib/figures.sh
source "$ROOT/scripts/lib/figures.sh"
figures_dir
log() { printf '[task-figures %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

houses=(--houses "$DATA/multiroom-val150.jsonl.gz" --asset-db "$DATA/databases/asset-database.json")
log "training the prior"
figures_prior "$ferret" "$DATA"

echo "# Household tasks on multiroom-val150"
echo
echo "$("$ferret" --version); $(nproc) cores; $(date -u +%Y-%m-%d); $PER_HOUSE tasks per house"
strategies="optimistic+greedy,sequential/model/prior,model/prior,model/uniform,oracle"
for kind in all:2 all:3 any:2; do
    for deliver in none start; do
        name="${kind/:/-}-$deliver"
        extra=()
        [ "$deliver" = start ] && extra=(--deliver start)
        log "eval --task $kind ${extra[*]}"
        "$ferret" eval "${houses[@]}" --prior "$out/prior.json" --task "$kind" "${extra[@]}" \
            --trials-per-house "$PER_HOUSE" --strategies "$strategies" \
            --paired-against sequential/model/prior --out "$out/$name" >/dev/null 2>"$out/$name.log"
        echo
        echo "## --task $kind ${extra[*]}"
        echo
        # The table, then the comparison against sequential.
        python3 - "$out/$name/summary.md" <<'PY'
import sys
lines = open(sys.argv[1]).read().split("\n")
def block(start):
    i = next(i for i, l in enumerate(lines) if l.startswith(start))
    j = next(j for j in range(i + 2, len(lines)) if not lines[j].startswith("|"))
    return "\n".join(lines[i:j])
print(block("| strategy | trials"))
print()
print(block("Against sequential"))
PY
    done
done

echo
echo "## The K-candidate cap: all of 3 brought to the start"
echo
echo "| planner | mean cost (m) | vs sequential (m), 95 % CI | wins / ties / losses | wall time of the run |"
echo "|---|---:|---:|---:|---:|"
for spec in model/prior model/prior/k12 model/prior/exact; do
    name="cap-${spec//\//-}"
    log "eval cap $spec"
    start=$(date +%s%N)
    "$ferret" eval "${houses[@]}" --prior "$out/prior.json" --task all:3 --deliver start \
        --trials-per-house "$PER_HOUSE" --strategies "sequential/model/prior,$spec" \
        --out "$out/$name" >/dev/null 2>"$out/$name.log"
    secs=$(( ($(date +%s%N) - start) / 1000000 ))
    python3 - "$out/$name/summary.csv" "$out/$name/paired.csv" "$spec" "$secs" <<'PY'
import csv, sys
summary, paired, spec, secs = sys.argv[1:]
mean = next(r for r in csv.DictReader(open(summary)) if r["strategy"] == spec)["mean_m"]
p = next(r for r in csv.DictReader(open(paired)) if r["strategy"] == spec and r["reference"] == "sequential/model/prior")
print(f"| {spec} | {float(mean):.2f} | {float(p['mean_diff_m']):+.2f} [{float(p['ci95_low_m']):+.2f}, {float(p['ci95_high_m']):+.2f}] | {p['wins']} / {p['ties']} / {p['losses']} | {int(secs) / 1000:.1f} s |")
PY
done

echo
echo "## In the prior's own world: all of 3 brought to the start"
echo
log "prior_world"
(cd "$ROOT" && env -u RUSTFLAGS cargo build --release --quiet -p ferret-lab --example prior_world) >&2
"${CARGO_TARGET_DIR:-$ROOT/target}/release/examples/prior_world" "${houses[@]}" \
    --prior "$out/prior.json" --task all:3 --deliver start --worlds 20 \
    --strategies sequential/model/prior,model/prior,model/prior/k12,model/uniform

echo
echo "## Decision latency"
echo
echo '```'
for m in 1 2 3 4; do
    sizes="8,12"
    [ "$m" = 3 ] && sizes="8,12,15"
    "$ferret" bench planner --targets "$m" --sizes "$sizes" --instances 100
done
echo '```'
