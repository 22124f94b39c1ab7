#!/usr/bin/env bash
# Idempotent set-up of sorting_line on a machine WITHOUT a ROS install (Debian 12, Python 3.11):
#   1. .venv/ at the repository root (python3.11)
#   2. the pinned ros-jazzy-* wheels of launch_scripts/requirements-ros.txt (rclpy + Fast DDS, messages,
#      and the rosidl/ament build tools)
#   3. msg/ (ROS package sorting_line_interfaces) and msg/simulation_interfaces/ (the standard's
#      simulator-control interfaces, which no wheel provides) compiled with plain CMake and installed INTO .venv/,
#      so `.venv/bin/python -c "from sorting_line_interfaces.msg import LineState"` works with nothing
#      sourced (the ros-wheels-bootstrapper .pth in the venv sets LD_LIBRARY_PATH by re-executing python)
#   4. bridge/ (Python package sorting_line_gym) installed editable into .venv/
#   5. `cargo build --release` (cargo's own checks make it a no-op when nothing changed), started first,
#      in the background, as it needs nothing of steps 1-4
#   6. only with --rllib: Ray RLlib (launch_scripts/requirements-rllib.txt; test.sh and reliability.sh ask for it)
# Steps 2-4 and 6 already done are skipped (stamps in .venv/.sorting_line/, keyed on hashes of the inputs).
#
# Usage: launch_scripts/setup.sh [--force] [--no-cargo] [--rllib]
#   --force      redo steps 2, 3 and 4 even if their stamps match
#   --no-cargo   skip step 5 (same as SORTING_LINE_SKIP_CARGO=1)
#   --rllib      also install Ray RLlib (655 MB; ~1 min from a warm pip cache, ~6 min cold on a loaded machine;
#                test.sh asks for it in the background, next to the Rust tests; run.sh does not need it)
# Environment (all optional):
#   SORTING_LINE_PYTHON      interpreter for a new venv (default: python3.11; must be CPython 3.11 with
#                            its headers, e.g. Debian packages python3.11-venv python3.11-dev)
#   SORTING_LINE_KEEP_BUILD  1 = keep the CMake build tree (.venv/.sorting_line/build) for debugging
# Afterwards: `source launch_scripts/env.sh` (venv + Fast DDS profile + RMW settings).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/launch_scripts/jobs.sh"

VENV="$ROOT/.venv"
STATE="$VENV/.sorting_line"
REQ="$ROOT/launch_scripts/requirements-ros.txt"
REQ_BRIDGE="$ROOT/launch_scripts/requirements-bridge.txt"
REQ_RLLIB="$ROOT/launch_scripts/requirements-rllib.txt"
BRIDGE="$ROOT/bridge"
MSG_DIR="$ROOT/msg"
PYTHON="${SORTING_LINE_PYTHON:-python3.11}"
# Bump when the recipe below changes in a way that needs a rebuild of existing venvs.
RECIPE=3

FORCE=0
CARGO=1
RLLIB=0
[[ "${SORTING_LINE_SKIP_CARGO:-0}" == 1 ]] && CARGO=0
for arg in "$@"; do
  case "$arg" in
    --force) FORCE=1 ;;
    --no-cargo) CARGO=0 ;;
    --rllib) RLLIB=1 ;;
    -h|--help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "setup.sh: unknown argument: $arg (see --help)" >&2; exit 2 ;;
  esac
done

T0=$SECONDS
say() { printf '[setup %3ds] %s\n' "$((SECONDS - T0))" "$*"; }
die() { printf '[setup] ERROR: %s\n' "$*" >&2; exit 1; }

# Serialise concurrent runs (run.sh and test.sh may both call this): lock on this script file.
if command -v flock >/dev/null 2>&1; then
  exec 9<"${BASH_SOURCE[0]}"
  flock -x 9
fi

sha() { sha256sum | cut -c1-16; }

# Stamps: step NAME is done when $STATE/NAME.stamp holds the hash of its inputs (KEY); --force
# ignores them.
stamp_matches() { # NAME KEY
  [[ $FORCE == 0 && -f "$STATE/$1.stamp" && "$(cat "$STATE/$1.stamp")" == "$2" ]]
}
write_stamp() { # NAME KEY
  mkdir -p "$STATE"
  echo "$2" >"$STATE/$1.stamp"
}

# ---------------------------------------------------------------------------------------------
# 1. venv
# ---------------------------------------------------------------------------------------------
venv_ok() {
  [[ -x "$VENV/bin/python" ]] &&
    "$VENV/bin/python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' >/dev/null 2>&1
}

make_venv() {
  if venv_ok; then
    say "venv: $VENV (exists)"
    return
  fi
  command -v "$PYTHON" >/dev/null 2>&1 || die "$PYTHON not found (set SORTING_LINE_PYTHON)"
  "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' ||
    die "$PYTHON is not Python 3.11 (the ros-jazzy-* wheels are cp311)"
  if [[ -e "$VENV" ]]; then
    say "venv: $VENV is broken or not Python 3.11, recreating it"
    rm -rf "$VENV"
  fi
  say "venv: creating $VENV with $("$PYTHON" -c 'import sys; print(sys.executable, sys.version.split()[0])')"
  "$PYTHON" -m venv "$VENV" || die "python -m venv failed (Debian: apt-get install python3.11-venv)"
}

# ---------------------------------------------------------------------------------------------
# 2. pinned wheels
# ---------------------------------------------------------------------------------------------
PY_ID=""
pip_key() { { echo "recipe=$RECIPE"; echo "python=$PY_ID"; cat "$REQ" "$REQ_BRIDGE"; } | sha; }

install_wheels() {
  local key
  key="$(pip_key)"
  if stamp_matches pip "$key"; then
    say "wheels: up to date (requirements-ros.txt, requirements-bridge.txt unchanged)"
    return
  fi
  say "wheels: installing requirements-ros.txt and requirements-bridge.txt (torch brings ~4 GB of CUDA libraries)"
  rm -f "$STATE/pip.stamp"
  "$VENV/bin/python" -m pip install --no-input --disable-pip-version-check -q -r "$REQ" -r "$REQ_BRIDGE" ||
    die "pip install -r $REQ -r $REQ_BRIDGE failed"
  write_stamp pip "$key"
}

install_rllib() {
  local key
  key="$( { pip_key; cat "$REQ_RLLIB"; } | sha)"
  if stamp_matches rllib "$key"; then
    say "rllib: up to date (requirements-rllib.txt unchanged)"
    return
  fi
  say "rllib: installing requirements-rllib.txt (Ray; ~1 min from a warm pip cache, minutes cold)"
  "$VENV/bin/python" -m pip install --no-input --disable-pip-version-check -q -r "$REQ" -r "$REQ_BRIDGE" -r "$REQ_RLLIB" ||
    die "pip install -r $REQ_RLLIB failed"
  write_stamp rllib "$key"
}

# ---------------------------------------------------------------------------------------------
# 3. the interface packages (msg/: sorting_line_interfaces; msg/simulation_interfaces/) -> .venv
# ---------------------------------------------------------------------------------------------
# Trap: the wheels' exported CMake files (share/*/cmake/*.cmake, the *__rosidl_generator_pyExport
# ones) hard-code the include dirs of the interpreter that built the wheels
# (/opt/python/cp311-cp311/...). Point them at this venv's Python and numpy include dirs.
fix_wheel_cmake_paths() {
  local py_inc np_inc files
  py_inc="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
  np_inc="$("$VENV/bin/python" -c 'import numpy; print(numpy.get_include())')"
  [[ -f "$py_inc/Python.h" ]] ||
    die "Python headers missing ($py_inc/Python.h); Debian: apt-get install python3.11-dev"
  files="$(grep -rlF --include='*.cmake' '/opt/python/cp311-cp311' "$VENV/share" || true)"
  if [[ -n "$files" ]]; then
    say "interfaces: rewriting build-machine include paths in $(wc -l <<<"$files") wheel CMake files"
    # numpy first: its path contains the Python prefix.
    xargs -d "\n" sed -i \
      -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#${np_inc}#g" \
      -e "s#/opt/python/cp311-cp311/include/python3.11#${py_inc}#g" <<<"$files"
    if grep -rlF --include='*.cmake' '/opt/python/' "$VENV/share" >/dev/null; then
      die "unexpected /opt/python/ paths left in $VENV/share/*/cmake (new wheel versions?)"
    fi
  fi
}

# An interface package: NAME, its source dir, and a Python import that proves it works.
# sorting_line_interfaces is msg/; simulation_interfaces (the standard's simulator-control
# interfaces, no wheel exists) is msg/simulation_interfaces/, a package of its own inside it.
iface_key() { # NAME DIR
  {
    echo "recipe=$RECIPE"
    # What the build uses of the venv: the Python, the ROS wheels (rosidl, rclpy), numpy's
    # headers. Not requirements-bridge.txt as a whole: a change there (a new tool for the
    # bridge) must not cost a rebuild of the interfaces.
    echo "python=$PY_ID"
    cat "$REQ"
    "$VENV/bin/python" -c 'import numpy; print("numpy", numpy.__version__)'
    # every file of the package (not of a package nested in it), names and contents
    (cd "$2" && find . -mindepth 1 -type d -exec test -f '{}/package.xml' \; -prune -o \
      -type f ! -name '.*' ! -name '*~' -print0 | LC_ALL=C sort -z | xargs -0 sha256sum)
  } | sha
}

iface_installed() { # NAME
  [[ -f "$VENV/lib/python3.11/site-packages/$1/msg/__init__.py" ]]
}

# Remove the files of a previous install (a deleted .msg must not survive in site-packages).
uninstall_interfaces() { # NAME
  local manifest="$STATE/${1}_install_manifest.txt" f
  # Earlier set-ups named the manifest (and stamp) of sorting_line_interfaces without the package.
  [[ "$1" == sorting_line_interfaces && -f "$STATE/interfaces_install_manifest.txt" ]] &&
    mv "$STATE/interfaces_install_manifest.txt" "$manifest"
  [[ -f "$manifest" ]] || return 0
  while IFS= read -r f; do
    [[ "$f" == "$VENV"/* ]] && rm -f -- "$f"
  done <"$manifest"
  rm -rf "$VENV/lib/python3.11/site-packages/$1"
  rm -f "$manifest"
}

build_interfaces() { # NAME DIR IMPORT_CHECK
  local name="$1" dir="$2" check="$3" key build logs jobs
  key="$(iface_key "$name" "$dir")"
  if stamp_matches "$name" "$key" && iface_installed "$name"; then
    say "interfaces: $name up to date"
    return
  fi
  # Provided by something else in the venv (a wheel): use that, as with a ROS install.
  if [[ ! -f "$STATE/${name}_install_manifest.txt" && ! ( "$name" == sorting_line_interfaces &&
    -f "$STATE/interfaces_install_manifest.txt" ) ]] && iface_installed "$name"; then
    say "interfaces: $name is already installed in .venv by another package; not building our copy"
    return
  fi
  command -v cc >/dev/null 2>&1 && command -v c++ >/dev/null 2>&1 ||
    die "C/C++ compilers missing; Debian: apt-get install build-essential"
  fix_wheel_cmake_paths
  rm -f "$STATE/$name.stamp" "$STATE/interfaces.stamp"
  uninstall_interfaces "$name"

  build="$STATE/build/$name"
  logs="$STATE/logs/$name"
  jobs="$(nproc 2>/dev/null || echo 2)"
  rm -rf "$build"
  mkdir -p "$build" "$logs"

  # Build against the venv only: no ROS environment of the caller may leak in.
  local -a envv=(env -u PYTHONPATH -u AMENT_PREFIX_PATH -u CMAKE_PREFIX_PATH -u COLCON_PREFIX_PATH
    -u ROS_DISTRO -u ROS_VERSION -u PYTHONHOME
    "PATH=$VENV/bin:$PATH" "AMENT_PREFIX_PATH=$VENV" "CMAKE_PREFIX_PATH=$VENV"
    "CMAKE_BUILD_PARALLEL_LEVEL=$jobs")
  run_logged() { # step cmd...
    local step="$1"; shift
    if ! "${envv[@]}" "$@" >"$logs/$step.log" 2>&1; then
      tail -n 40 "$logs/$step.log" >&2
      die "interfaces: $name: $step failed (full log: $logs/$step.log)"
    fi
  }

  say "interfaces: configuring $name (CMake $("$VENV/bin/cmake" --version | head -1 | awk '{print $3}'))"
  run_logged configure "$VENV/bin/cmake" -S "$dir" -B "$build" \
    -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_INSTALL_PREFIX="$VENV" \
    -DPython3_EXECUTABLE="$VENV/bin/python" \
    -DPython3_FIND_VIRTUALENV=ONLY \
    -DBUILD_TESTING=OFF \
    -DSORTING_LINE_INTERFACES_PYTHON_ONLY=ON
  say "interfaces: building $name (-j$jobs)"
  run_logged build "$VENV/bin/cmake" --build "$build" -j "$jobs"
  say "interfaces: installing $name into .venv"
  run_logged install "$VENV/bin/cmake" --install "$build"
  cp "$build/install_manifest.txt" "$STATE/${name}_install_manifest.txt"
  [[ "${SORTING_LINE_KEEP_BUILD:-0}" == 1 ]] || rm -rf "$build"

  # Prove it, from a clean environment (nothing sourced).
  env -u PYTHONPATH -u AMENT_PREFIX_PATH -u LD_LIBRARY_PATH -u _ROS_WHEELS_BOOTSTRAP_COMPLETE \
    "$VENV/bin/python" -c "$check" ||
    die "interfaces: $name installed, but the import check failed"
  write_stamp "$name" "$key"
  say "interfaces: $name installed"
}

# ---------------------------------------------------------------------------------------------
# 4. the bridge package (bridge/, sorting_line_gym), editable so the tests run the source tree
# ---------------------------------------------------------------------------------------------
install_bridge() {
  local key
  key="$( { echo "$ROOT"; cat "$BRIDGE/pyproject.toml"; } | sha)"
  if stamp_matches bridge "$key"; then
    say "bridge: up to date"
    return
  fi
  say "bridge: pip install -e bridge (dependencies come from the pinned requirements)"
  "$VENV/bin/python" -m pip install --no-input --disable-pip-version-check -q --no-deps --no-build-isolation -e "$BRIDGE" ||
    die "pip install -e $BRIDGE failed"
  write_stamp bridge "$key"
}

# ---------------------------------------------------------------------------------------------
# 5. Rust
# ---------------------------------------------------------------------------------------------
# The release build needs nothing of steps 1-4, and they mostly wait on downloads and CMake while
# it mostly computes: it starts first, in the background (its output kept until step 5), which
# takes minutes off a fresh set-up. An exit before step 5 takes it down.
start_rust() {
  [[ $CARGO == 1 ]] || return 0
  command -v cargo >/dev/null 2>&1 || die "cargo not found: install the Rust toolchain (rustup) first"
  say "cargo: cargo build --release (in the background, beside the steps below)"
  job_start cargo cargo build --release --manifest-path "$ROOT/Cargo.toml"
}

build_rust() {
  if [[ $CARGO == 0 ]]; then
    say "cargo: skipped (--no-cargo)"
    return
  fi
  job_join cargo "[setup] cargo build --release"
  say "cargo: release build done"
}

# ---------------------------------------------------------------------------------------------
start_rust
make_venv
PY_ID="$("$VENV/bin/python" -c 'import sys; print(sys.version.split()[0], sys.implementation.cache_tag)')"
mkdir -p "$STATE"
install_wheels
[[ $RLLIB == 1 ]] && install_rllib
build_interfaces simulation_interfaces "$MSG_DIR/simulation_interfaces" \
  'from simulation_interfaces.srv import StepSimulation; from simulation_interfaces.action import SimulateSteps'
build_interfaces sorting_line_interfaces "$MSG_DIR" \
  'from sorting_line_interfaces.msg import LineState; from sorting_line_interfaces.srv import ResetLine'
install_bridge
build_rust
say "done (source launch_scripts/env.sh to use the venv with the project's ROS settings)"
