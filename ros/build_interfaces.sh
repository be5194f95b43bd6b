#!/usr/bin/env bash
# Generates ferret_interfaces and nav2_msgs (NavigateToPose only) with rosidl into a virtual
# environment holding the ROS 2 wheels of ros/requirements.txt: plain CMake, no colcon, no ROS
# install. The C/C++ type supports and the Python modules land in the venv itself (lib/,
# lib/python3.X/site-packages, share/), where rclpy and the wheels' start-up hook find them.
#
#   ros/build_interfaces.sh VENV
#
# Needs a C and C++ compiler (gcc/g++) and make.
set -euo pipefail

VENV="$(cd "${1:?usage: ros/build_interfaces.sh VENV}" && pwd)"
HERE="$(cd "$(dirname "$0")" && pwd)"
PY="$VENV/bin/python"
log() { printf '[build_interfaces %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

for tool in cc c++ make; do
    if ! command -v "$tool" >/dev/null 2>&1; then
        log "$tool not found: generating the interfaces needs a C/C++ toolchain (apt-get install build-essential)"
        exit 1
    fi
done

# The message wheels export CMake targets whose include directories name the wheel builder's
# Python and numpy (e.g. /opt/python/cp311-cp311/include/python3.11), which do not exist here
# and make CMake stop. Point them at this venv's interpreter and numpy.
py_include="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
np_include="$("$PY" -c 'import numpy; print(numpy.get_include())')"
"$PY" - "$VENV/share" "$py_include" "$np_include" <<'EOF'
import pathlib, re, sys
share, py_include, np_include = sys.argv[1:]
numpy_dir = re.compile(r"/[^;\"]*?/site-packages/numpy/_core/include")
python_dir = re.compile(r"/[^;\"]*?/include/python3\.\d+")
fixed = 0
for f in pathlib.Path(share).glob("*/cmake/*.cmake"):
    text = f.read_text()
    new = numpy_dir.sub(lambda m: m.group(0) if pathlib.Path(m.group(0)).is_dir() else np_include, text)
    new = python_dir.sub(lambda m: m.group(0) if pathlib.Path(m.group(0)).is_dir() else py_include, new)
    if new != text:
        f.write_text(new)
        fixed += 1
print(f"fixed the include paths of {fixed} exported CMake files", file=sys.stderr)
EOF

BUILD="$(mktemp -d)"
trap 'rm -rf "$BUILD"' EXIT
export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV" PATH="$VENV/bin:$PATH"
# nav2_msgs first: nothing depends on it, but a failure there is the likelier one to report.
for pkg in nav2_msgs ferret_interfaces; do
    log "generating $pkg"
    started=$(date +%s)
    if ! { cmake -S "$HERE/interfaces/$pkg" -B "$BUILD/$pkg" -DCMAKE_INSTALL_PREFIX="$VENV" \
              -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$PY" &&
           cmake --build "$BUILD/$pkg" -j "${CMAKE_BUILD_PARALLEL_LEVEL:-1}" &&
           cmake --install "$BUILD/$pkg"; } >"$BUILD/$pkg.log" 2>&1; then
        tail -40 "$BUILD/$pkg.log" >&2
        log "generating $pkg failed (the end of its log is above)"
        exit 1
    fi
    log "$pkg generated in $(( $(date +%s) - started )) s"
done
"$PY" -c 'from nav2_msgs.action import NavigateToPose; from ferret_interfaces.action import SearchObject; from ferret_interfaces.msg import Detection, Belief'
