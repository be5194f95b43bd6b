# shellcheck shell=bash
# Sourced by the scripts that run the `ferret` binary: one answer to "which ferret?".
#
#   source "$ROOT/scripts/lib/ferret-bin.sh"
#   ferret="$(ferret_bin)"                      # or: ferret_bin --features minilm
#
# FERRET_BIN, when set, is the binary (a path, or a command on PATH), so a script can time or
# test a build it did not make. Otherwise cargo builds this checkout's release binary into
# ${CARGO_TARGET_DIR:-target} (a relative CARGO_TARGET_DIR is taken from the checkout's root, as
# cargo does there). cargo runs even when the binary exists, because only cargo knows whether it
# is older than the sources, and a script must never measure a stale build; it is a no-op when
# nothing changed. The arguments are extra `cargo build` options (features). RUSTFLAGS is left
# out of the build, as for the wheel (scripts/lib/ferret-wheel.sh): a binary tuned to this CPU
# may not start on the other machines a sharded run sends it to. Prints the absolute path, since
# the scripts change directory; cargo's output goes to stderr.

FERRET_BIN_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"

ferret_bin() {
    local bin="${FERRET_BIN:-}"
    if [ -z "$bin" ]; then
        local target="${CARGO_TARGET_DIR:-target}"
        case "$target" in
            /*) ;;
            *) target="$FERRET_BIN_ROOT/$target" ;;
        esac
        (cd "$FERRET_BIN_ROOT" && env -u RUSTFLAGS CARGO_TARGET_DIR="$target" \
            cargo build --release --quiet -p ferret-cli "$@") >&2 || return 1
        bin="$target/release/ferret"
    elif [[ "$bin" != */* ]]; then
        bin="$(command -v "$bin")" || {
            echo "FERRET_BIN=$FERRET_BIN: no such command on PATH" >&2
            return 1
        }
    fi
    if [ ! -x "$bin" ]; then
        echo "$bin: not an executable ferret binary (FERRET_BIN names the one to use)" >&2
        return 1
    fi
    echo "$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")"
}
