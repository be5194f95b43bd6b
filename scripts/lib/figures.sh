# shellcheck shell=bash
# Sourced by the scripts that make the docs' figures (task-figures.sh, team-figures.sh): where
# their runs go, and the prior they all plan with.
#
#   source "$ROOT/scripts/lib/figures.sh"
#   figures_dir                        # sets out: FERRET_FIG_OUT, or a temporary directory
#                                      # removed when the script exits
#   figures_prior "$ferret" "$DATA"    # the calibrated prior of the 1 500 small training
#                                      # houses, into $out/prior.json (progress to stderr)

figures_dir() {
    if [ -n "${FERRET_FIG_OUT:-}" ]; then
        out="$FERRET_FIG_OUT"
        mkdir -p "$out"
    else
        out="$(mktemp -d)"
        # shellcheck disable=SC2064 # the directory is known now, and must be what is removed
        trap "rm -rf '$out'" EXIT
    fi
}

figures_prior() {
    local ferret="$1" data="$2"
    "$ferret" prior train --houses "$data/smallhouse-train1000.jsonl.gz" \
        --also "$data/oneroom-train500.jsonl.gz" --asset-db "$data/databases/asset-database.json" \
        --out "$out/prior.json" >&2
}
