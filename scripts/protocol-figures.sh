#!/usr/bin/env bash
# The cost of the paper protocol (docs/protocol.md, "Measured"): `ferret eval` on every target of
# multiroom-val150 (`--trials-per-house all`) with optimistic+greedy, model/prior and
# model/prior/exact, under `--protocol paper`, then the same run without the soft cost (`--travel-cost
# plain`: what the protocol's other parts cost) and under the default protocol. When
# FERRET_BEFORE_BIN names an older ferret binary, its paper runs alternate with this checkout's and
# every trials.csv must be byte for byte the first paper run's (the default protocol's against
# each other); a difference fails the script after the table is printed.
#
#   FERRET_PROCTHOR_DIR=/abs/path/to/procthor scripts/protocol-figures.sh > figures.tsv
#   FERRET_BEFORE_BIN=/abs/path/to/old/ferret FERRET_PROCTHOR_DIR=... scripts/protocol-figures.sh
#
# Output: one tab-separated line per run (label, wall s, CPU s = user + sys, peak memory MB,
# trials), after `#` lines naming the machine and the command. FERRET_BIN runs a given ferret
# instead of building this checkout's; FERRET_FIG_RUNS sets how many paper runs of each binary
# (default 2); FERRET_FIG_RANGE passes `--range` (e.g. 0..10 for a quick look); FERRET_FIG_OUT keeps
# the runs' output directories there (default: a temporary directory, removed at exit).
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:?set FERRET_PROCTHOR_DIR to the ProcTHOR directory}"
RUNS="${FERRET_FIG_RUNS:-2}"
before="${FERRET_BEFORE_BIN:-}"
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
[ -x /usr/bin/time ] || { echo "needs GNU time at /usr/bin/time" >&2; exit 2; }
log() { printf '[protocol-figures %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }
if [ -n "${FERRET_FIG_OUT:-}" ]; then
    out="$FERRET_FIG_OUT"
    mkdir -p "$out"
else
    out="$(mktemp -d)"
    trap 'rm -rf "$out"' EXIT
fi

args=(eval --houses "$DATA/multiroom-val150.jsonl.gz" --asset-db "$DATA/databases/asset-database.json"
    --trials-per-house all --strategies "optimistic+greedy,model/prior,model/prior/exact")
if [ -n "${FERRET_FIG_RANGE:-}" ]; then
    args+=(--range "$FERRET_FIG_RANGE")
fi
echo "# $(nproc) cores; $(lscpu | sed -n 's/^Model name: *//p' | head -1)"
shown="${args[*]}"
echo "# ferret ${shown//"$DATA"/\$FERRET_PROCTHOR_DIR} [--protocol paper [--travel-cost plain]] --out DIR"
printf 'label\twall_s\tcpu_s\tpeak_mb\ttrials\n'

# run LABEL BIN ARGS...: one eval into $out/LABEL under /usr/bin/time, one line of the table.
run() {
    local label="$1" bin="$2"
    shift 2
    log "$label"
    if ! /usr/bin/time -f '%e %U %S %M' -o "$out/$label.time" \
        "$bin" "${args[@]}" "$@" --out "$out/$label" >"$out/$label.log" 2>&1; then
        log "$label failed:"
        tail -n 20 "$out/$label.log" >&2
        exit 1
    fi
    local wall user sys kib
    read -r wall user sys kib <"$out/$label.time"
    printf '%s\t%s\t%s\t%d\t%d\n' "$label" "$wall" "$(awk -v u="$user" -v s="$sys" 'BEGIN { printf "%.2f", u + s }')" \
        $((kib / 1024)) $(($(wc -l <"$out/$label/trials.csv") - 1))
}

status=0
# same REFERENCE LABEL...: every trials.csv byte for byte the reference's.
same() {
    local reference="$1"
    shift
    for label in "$@"; do
        if cmp -s "$out/$reference/trials.csv" "$out/$label/trials.csv"; then
            echo "# trials.csv of $label is byte for byte $reference's"
        else
            echo "# trials.csv of $label DIFFERS from $reference's"
            status=1
        fi
    done
}

paper=()
for ((i = 1; i <= RUNS; i++)); do
    if [ -n "$before" ]; then
        run "paper-before-$i" "$before" --protocol paper
        paper+=("paper-before-$i")
    fi
    run "paper-$i" "$ferret" --protocol paper
    paper+=("paper-$i")
done
run "paper-plain-cost" "$ferret" --protocol paper --travel-cost plain
defaults=()
if [ -n "$before" ]; then
    run "default-before" "$before"
    defaults+=("default-before")
fi
run "default" "$ferret"
defaults+=("default")
same "${paper[0]}" "${paper[@]:1}"
same "${defaults[0]}" "${defaults[@]:1}"
exit "$status"
