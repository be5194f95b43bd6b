#!/usr/bin/env bash
# The figures of docs/teams.md: teams of 1, 2 and 3 robots on multiroom-val150 with the
# calibrated prior trained on the 1 500 small training houses. For one target and for `all` of
# 2, robots all at the house's start and spread over the floor, one `ferret eval --robots N` of
# the coordinated planner (model/prior), independent robots (independent/model/prior: the
# baseline), split rooms (split/model/prior), the same two without a likelihood
# (model/uniform, independent/model/uniform: the control) and the team oracle, compared in
# pairs against independent/model/prior; the gap each team closes between one robot and the
# oracle; and a robot's decision time in a team of 3 (the criterion bench team_decision).
#
#   FERRET_PROCTHOR_DIR=/abs/path/to/procthor scripts/team-figures.sh > figures.md
#
# FERRET_BIN runs a given ferret instead of building this checkout's; FERRET_FIG_OUT keeps the
# runs' directories there (default: a temporary directory, removed at exit). FERRET_FIG_BENCH=0
# leaves out the bench. Progress goes to stderr.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DATA="${FERRET_PROCTHOR_DIR:?set FERRET_PROCTHOR_DIR to the ProcTHOR directory}"
# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
ferret="$(ferret_bin)"
# shellcheck source=scripts/lib/figures.sh
source "$ROOT/scripts/lib/figures.sh"
figures_dir
log() { printf '[team-figures %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

houses=(--houses "$DATA/multiroom-val150.jsonl.gz" --asset-db "$DATA/databases/asset-database.json")
log "training the prior"
figures_prior "$ferret" "$DATA"

team="model/prior,independent/model/prior,split/model/prior,model/uniform,independent/model/uniform,oracle"
for kind in one all:2; do
    task=()
    [ "$kind" != one ] && task=(--task "$kind")
    for starts in together spread; do
        for robots in 1 2 3; do
            name="${kind/:/-}-$starts-$robots"
            strategies="$team" against=independent/model/prior
            [ "$robots" = 1 ] && strategies="model/prior,model/uniform,oracle" against=model/prior
            log "eval ${task[*]} --robots $robots --starts $starts"
            start=$(date +%s%N)
            "$ferret" eval "${houses[@]}" --prior "$out/prior.json" "${task[@]}" \
                --robots "$robots" --starts "$starts" --strategies "$strategies" \
                --paired-against "$against" --out "$out/$name" \
                >/dev/null 2>"$out/$name.log"
            echo $(( ($(date +%s%N) - start) / 1000000 )) >"$out/$name.ms"
        done
    done
done

echo "# Teams on multiroom-val150"
echo
echo "$("$ferret" --version); $(nproc) cores; $(date -u +%Y-%m-%d); one trial per house"
python3 - "$out" <<'PY'
import csv, sys
out = sys.argv[1]
def summary(name):
    return {r["strategy"]: r for r in csv.DictReader(open(f"{out}/{name}/summary.csv"))}
def paired(name):
    return {(r["strategy"], r["reference"]): r for r in csv.DictReader(open(f"{out}/{name}/paired.csv"))}
base = "independent/model/prior"
for kind, title in [("one", "one target"), ("all-2", "all of 2 targets")]:
    for starts in ["together", "spread"]:
        one = summary(f"{kind}-{starts}-1")
        alone, oracle1 = float(one["model/prior"]["mean_m"]), float(one["oracle"]["mean_m"])
        ms = open(f"{out}/{kind}-{starts}-3.ms").read().strip()
        print(f"\n## {title}, robots {'at the start' if starts == 'together' else 'spread'}\n")
        print(f"One robot: model/prior {alone:.2f} m, oracle {oracle1:.2f} m, model/uniform {float(one['model/uniform']['mean_m']):.2f} m. "
              f"Gap closed = (one robot − team) / (one robot − oracle); the run of 3 robots took {int(ms) / 1000:.1f} s.\n")
        print("| robots | strategy | makespan (m) | total travel (m) | vs independent/model/prior (m), 95 % CI | wins / ties / losses | gap closed to one robot's oracle | to the team's oracle |")
        print("|---:|---|---:|---:|---:|---:|---:|---:|")
        for robots in [2, 3]:
            name = f"{kind}-{starts}-{robots}"
            s, p = summary(name), paired(name)
            team_oracle = float(s["oracle"]["mean_m"])
            for strategy, row in s.items():
                m = float(row["mean_m"])
                t = float(row["mean_total_travel_m"])
                d = p.get((strategy, base))
                vs = f"{float(d['mean_diff_m']):+.2f} [{float(d['ci95_low_m']):+.2f}, {float(d['ci95_high_m']):+.2f}]" if d else "–"
                wtl = f"{d['wins']} / {d['ties']} / {d['losses']}" if d else "–"
                gap1 = 100 * (alone - m) / (alone - oracle1)
                gapt = 100 * (alone - m) / (alone - team_oracle)
                print(f"| {robots} | {strategy} | {m:.2f} | {t:.2f} | {vs} | {wtl} | {gap1:.0f} % | {gapt:.0f} % |")
PY

if [ "${FERRET_FIG_BENCH:-1}" != 0 ]; then
    echo
    echo "## A robot's decision in a team"
    echo
    log "cargo bench team_decision"
    (cd "$ROOT" && cargo bench -q -p ferret-plan --bench planner -- team_decision >&2)
    python3 - "${CARGO_TARGET_DIR:-$ROOT/target}/criterion/team_decision" <<'PY'
import json, sys
for robots in ["1", "3"]:
    e = json.load(open(f"{sys.argv[1]}/k8_robots/{robots}/new/estimates.json"))
    print(f"- {robots} robot{'s' if robots != '1' else ''}, K = 8, 22 containers: median {e['median']['point_estimate'] / 1000:.1f} µs")
PY
fi
