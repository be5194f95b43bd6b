#!/usr/bin/env bash
# A throwaway PostgreSQL cluster for tests and benchmarks: initdb in a temporary directory, owned
# by the `postgres` system user (the server refuses to run as root), listening on 127.0.0.1 only,
# with fsync on (what a fleet runs) and a trust login for the local test user.
#
#   eval "$(scripts/postgres.sh start)"   # prints: export FERRET_TEST_POSTGRES=postgres://...
#   scripts/postgres.sh new-db NAME       # another empty database there; prints its URL
#   scripts/postgres.sh stop "$FERRET_PG_DIR"
#
# `start` picks a free port, waits until the server accepts connections and creates a database
# `ferret`. Needs Debian's PostgreSQL (initdb, pg_ctl on PATH or under /usr/lib/postgresql).
set -euo pipefail

find_bin() {
    local name="$1"
    if command -v "$name" >/dev/null 2>&1; then
        command -v "$name"
        return
    fi
    local found
    found="$(find /usr/lib/postgresql -mindepth 3 -maxdepth 3 -path "*/bin/$name" 2>/dev/null \
        | sort -V | tail -1 || true)"
    [ -n "$found" ] || {
        echo "postgres.sh: $name not found (install Debian's postgresql package)" >&2
        exit 1
    }
    echo "$found"
}

as_postgres() {
    if [ "$(id -u)" = 0 ]; then
        # runuser keeps the environment minimal; the binaries are given by absolute path.
        runuser -u postgres -- "$@"
    else
        "$@"
    fi
}

start() {
    local initdb pg_ctl psql dir port
    initdb="$(find_bin initdb)"
    pg_ctl="$(find_bin pg_ctl)"
    psql="$(find_bin psql)"
    dir="$(mktemp -d /tmp/ferret-pg.XXXXXX)"
    chmod 755 "$dir"
    [ "$(id -u)" = 0 ] && chown postgres "$dir"
    port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
    as_postgres "$initdb" -D "$dir/data" -U postgres --auth=trust -E UTF8 --no-locale >"$dir/initdb.log" 2>&1 || {
        cat "$dir/initdb.log" >&2
        exit 1
    }
    as_postgres "$pg_ctl" -D "$dir/data" -l "$dir/server.log" -w -t 30 \
        -o "-c listen_addresses=127.0.0.1 -p $port -k $dir -c max_connections=200" start >/dev/null || {
        cat "$dir/server.log" >&2
        exit 1
    }
    as_postgres "$psql" -h 127.0.0.1 -p "$port" -U postgres -qc 'CREATE DATABASE ferret' >/dev/null
    echo "export FERRET_PG_DIR=$dir"
    echo "export FERRET_TEST_POSTGRES=postgres://postgres@127.0.0.1:$port/ferret"
}

stop() {
    local dir="${1:?give the cluster directory that start printed (FERRET_PG_DIR)}"
    local pg_ctl
    pg_ctl="$(find_bin pg_ctl)"
    [ -d "$dir/data" ] && as_postgres "$pg_ctl" -D "$dir/data" -m fast -w stop >/dev/null 2>&1 || true
    rm -rf "$dir"
}

new_db() {
    local name="${1:?give the new database a name}" url="${FERRET_TEST_POSTGRES:?run start first}"
    local psql base
    psql="$(find_bin psql)"
    base="${url%/*}"
    "$psql" "$url" -qc "CREATE DATABASE \"$name\"" >/dev/null
    echo "$base/$name"
}

case "${1:-}" in
start) start ;;
new-db) new_db "${2:-}" ;;
stop) stop "${2:-}" ;;
*)
    echo "usage: $0 start | new-db NAME | stop DIR" >&2
    exit 2
    ;;
esac
