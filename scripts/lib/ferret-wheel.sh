# shellcheck shell=bash
# Sourced by the Python and ROS lanes: the `ferret` wheel built from this checkout and installed
# into the lane's venv, and the `ferret` binary its tests compare with. Expects ROOT, TARGET, VENV,
# PY and a `log` function; sets WHEELS (a scratch directory, removed on exit) and exports FERRET_BIN
# as an absolute path, because the tests run from that scratch directory.

# shellcheck source=scripts/lib/ferret-bin.sh
source "$(dirname "${BASH_SOURCE[0]}")/ferret-bin.sh"

install_ferret_wheel() {
    WHEELS="$(mktemp -d)"
    trap 'rm -rf "$WHEELS"' EXIT
    log "building the ferret wheel"
    local started
    started=$(date +%s)
    # Portable: whatever RUSTFLAGS the caller has set for local experiments stays out of the wheel.
    # shellcheck disable=SC2153 # TARGET is the caller's (above)
    (cd "$ROOT" && env -u RUSTFLAGS CARGO_TARGET_DIR="$TARGET" "$VENV/bin/maturin" build --release \
        --quiet -m crates/python/Cargo.toml --interpreter "$PY" --out "$WHEELS")
    log "wheel built in $(( $(date +%s) - started )) s: $(cd "$WHEELS" && ls)"
    "$PY" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps "$WHEELS"/*.whl

    FERRET_BIN="$(CARGO_TARGET_DIR="$TARGET" ferret_bin)"
    export FERRET_BIN
}
