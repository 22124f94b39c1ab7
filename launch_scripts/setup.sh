#!/usr/bin/env bash
# Idempotent set-up of sorting_line on a machine WITHOUT a ROS install (Debian 12; CPython 3.11 or 3.12):
#   1. .venv/ at the repository root (python3.12 where present, else python3.11)
#   2. the pinned wheels: ros-jazzy-* of launch_scripts/requirements-ros.txt (rclpy + Fast DDS, messages,
#      and the rosidl/ament build tools) and the core of requirements-bridge.txt (bags, ONNX runtime,
#      pytest, the checks); with --train also requirements-train.txt (torch, SB3, RL Zoo, tensorboard)
#   3. msg/ (ROS package sorting_line_interfaces) and msg/simulation_interfaces/ (the standard's
#      simulator-control interfaces, which no wheel provides) compiled with plain CMake and installed INTO .venv/,
#      so `.venv/bin/python -c "from sorting_line_interfaces.msg import LineState"` works with nothing
#      sourced (the ros-wheels-bootstrapper .pth in the venv sets LD_LIBRARY_PATH by re-executing python)
#   4. bridge/ (Python package sorting_line_gym, with its native extension built by maturin from native/)
#      installed editable into .venv/
#   5. `cargo build --release` (cargo's own checks make it a no-op when nothing changed), started first,
#      in the background, as it needs nothing of steps 1-4
#   6. only with --train: the training stack (requirements-train.txt, ~5 GB: torch and its CUDA libraries);
#      only with --rllib: that and Ray RLlib (requirements-rllib.txt; test.sh and reliability.sh ask for it)
# Steps 2-4 and 6 already done are skipped (stamps in .venv/.sorting_line/, keyed on hashes of the inputs).
# Without --train the venv (the core: node tools, bridge, bag tools, controller, pytest plugin) stays
# under 1.5 GB; its size is printed at the end.
#
# Usage: launch_scripts/setup.sh [--force] [--no-cargo] [--train] [--rllib] | --find-python
#   --force      redo steps 2, 3 and 4 even if their stamps match
#   --no-cargo   skip step 5 (same as SORTING_LINE_SKIP_CARGO=1)
#   --train      also install the training stack (sorting-line-train, -benchmark's RL agents, -transfer,
#                -export, a controller's --policy MODEL.zip; run.sh and test.sh ask for it)
#   --rllib      --train and Ray RLlib (655 MB; ~1 min from a warm pip cache, ~6 min cold on a loaded machine;
#                test.sh asks for it in the background, next to the Rust tests; run.sh does not need it)
#   --find-python  only print the interpreter a new venv would be made with (exit 3 if there is none)
# Environment (all optional):
#   SORTING_LINE_PYTHON      interpreter for a new venv: a command or path, or a version (3.11, 3.12),
#                            looked up as pythonX.Y on PATH and in pyenv's versions (default: 3.12, else
#                            3.11). CPython 3.11 or 3.12 with its headers and venv (Debian: pythonX.Y-dev
#                            pythonX.Y-venv). An existing venv of either version is kept unless this asks
#                            for the other one.
#   SORTING_LINE_VENV        the venv to set up (default: .venv at the repository root; test.sh makes a
#                            second one for the other Python version)
#   SORTING_LINE_KEEP_BUILD  1 = keep the CMake build tree (.venv/.sorting_line/build) for debugging
# Afterwards: `source launch_scripts/env.sh` (venv + Fast DDS profile + RMW settings).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/launch_scripts/jobs.sh"

VENV="${SORTING_LINE_VENV:-$ROOT/.venv}"
STATE="$VENV/.sorting_line"
REQ="$ROOT/launch_scripts/requirements-ros.txt"
REQ_BRIDGE="$ROOT/launch_scripts/requirements-bridge.txt"
REQ_TRAIN="$ROOT/launch_scripts/requirements-train.txt"
REQ_RLLIB="$ROOT/launch_scripts/requirements-rllib.txt"
BRIDGE="$ROOT/bridge"
MSG_DIR="$ROOT/msg"
# Bump when the recipe below changes in a way that needs a rebuild of existing venvs.
RECIPE=3
# The CPython versions the pinned wheels (ros-jazzy-* included) exist for, the preferred one first.
PYTHON_VERSIONS=(3.12 3.11)

FORCE=0
CARGO=1
TRAIN=0
RLLIB=0
FIND_ONLY=0
[[ "${SORTING_LINE_SKIP_CARGO:-0}" == 1 ]] && CARGO=0
for arg in "$@"; do
  case "$arg" in
    --force) FORCE=1 ;;
    --no-cargo) CARGO=0 ;;
    --train) TRAIN=1 ;;
    --rllib) RLLIB=1 TRAIN=1 ;;
    --find-python) FIND_ONLY=1 ;;
    -h|--help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "setup.sh: unknown argument: $arg (see --help)" >&2; exit 2 ;;
  esac
done

T0=$SECONDS
say() { printf '[setup %3ds] %s\n' "$((SECONDS - T0))" "$*"; }
die() { printf '[setup] ERROR: %s\n' "$*" >&2; exit 1; }

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
# The X.Y of an interpreter that is CPython 3.11 or 3.12, else nothing.
python_version() { # PYTHON
  "$1" -c 'import sys, platform
v = "%d.%d" % sys.version_info[:2]
print(v if platform.python_implementation() == "CPython" and v in ("3.11", "3.12") else "")' 2>/dev/null
}

# Candidates for Python X.Y: pythonX.Y on PATH (a pyenv shim fails unless the version is active, which
# the check above catches), then pyenv's installs of it.
python_candidates() { # X.Y
  echo "python$1"
  local root
  root="$(pyenv root 2>/dev/null || true)"
  if [[ -n "$root" ]]; then
    # A glob of pyenv's own folder names (X.Y.Z): no odd characters for ls to mangle.
    # shellcheck disable=SC2012
    ls -d "$root/versions/$1".*/bin/"python$1" 2>/dev/null | sort -V -r || true
  fi
}

# Sets PYTHON to the interpreter for a new venv and WANTED to the version SORTING_LINE_PYTHON names (empty:
# any supported one).
find_python() {
  local wanted="${SORTING_LINE_PYTHON:-}" versions=("${PYTHON_VERSIONS[@]}") v c
  WANTED=""
  if [[ -n "$wanted" && ! "$wanted" =~ ^3\.[0-9]+$ ]]; then # a command or path
    PYTHON="$wanted"
    WANTED="$(python_version "$PYTHON")"
    [[ -n "$WANTED" ]] ||
      die "SORTING_LINE_PYTHON=$wanted is not CPython ${PYTHON_VERSIONS[*]} (the pinned wheels exist for those)"
    return
  fi
  if [[ -n "$wanted" ]]; then
    [[ " ${PYTHON_VERSIONS[*]} " == *" $wanted "* ]] ||
      die "SORTING_LINE_PYTHON=$wanted: allowed ${PYTHON_VERSIONS[*]} (the pinned wheels exist for those)"
    versions=("$wanted")
    WANTED="$wanted"
  fi
  for v in "${versions[@]}"; do
    while IFS= read -r c; do
      if [[ "$(python_version "$c")" == "$v" ]]; then
        PYTHON="$c"
        return
      fi
    done < <(python_candidates "$v")
  done
  PYTHON=""
}

venv_ok() {
  local v
  [[ -x "$VENV/bin/python" ]] || return 1
  v="$(python_version "$VENV/bin/python")"
  [[ -n "$v" && ( -z "$WANTED" || "$v" == "$WANTED" ) ]]
}

make_venv() {
  find_python
  if venv_ok; then
    say "venv: $VENV (exists, Python $(python_version "$VENV/bin/python"))"
    return
  fi
  [[ -n "$PYTHON" ]] ||
    die "no CPython ${WANTED:-${PYTHON_VERSIONS[*]}} found (pythonX.Y on PATH or in pyenv; or set SORTING_LINE_PYTHON)"
  if [[ -e "$VENV" ]]; then
    say "venv: $VENV is broken or not Python ${WANTED:-${PYTHON_VERSIONS[*]}}, recreating it"
    rm -rf "$VENV"
  fi
  say "venv: creating $VENV with $("$PYTHON" -c 'import sys; print(sys.executable, sys.version.split()[0])')"
  "$PYTHON" -m venv "$VENV" || die "python -m venv failed (Debian: apt-get install python$(python_version "$PYTHON")-venv)"
}

if [[ $FIND_ONLY == 1 ]]; then
  find_python
  [[ -n "$PYTHON" ]] || { echo "setup.sh: no CPython ${WANTED:-${PYTHON_VERSIONS[*]}} found" >&2; exit 3; }
  command -v "$PYTHON"
  exit 0
fi

# ---------------------------------------------------------------------------------------------
# 2. pinned wheels
# ---------------------------------------------------------------------------------------------
PY_ID=""
pip_key() { { echo "recipe=$RECIPE"; echo "python=$PY_ID"; cat "$REQ" "$REQ_BRIDGE"; } | sha; }
PIP=(pip install --no-input --disable-pip-version-check -q)

install_wheels() {
  local key
  key="$(pip_key)"
  if stamp_matches pip "$key"; then
    say "wheels: up to date (requirements-ros.txt, requirements-bridge.txt unchanged)"
    return
  fi
  say "wheels: installing requirements-ros.txt and requirements-bridge.txt (the core)"
  rm -f "$STATE/pip.stamp"
  "$VENV/bin/python" -m "${PIP[@]}" -r "$REQ" -r "$REQ_BRIDGE" || die "pip install -r $REQ -r $REQ_BRIDGE failed"
  write_stamp pip "$key"
}

# The training stack (--train), and Ray RLlib on top of it (--rllib): NAME, its requirements files.
install_extra() { # NAME WHAT REQUIREMENTS...
  local name="$1" what="$2" key
  shift 2
  key="$( { pip_key; cat "$@"; } | sha)"
  if stamp_matches "$name" "$key"; then
    say "$name: up to date ($(basename -a "$@" | paste -sd' '))"
    return
  fi
  say "$name: installing $what"
  local -a reqs=()
  local f
  for f in "$REQ" "$REQ_BRIDGE" "$@"; do reqs+=(-r "$f"); done
  "$VENV/bin/python" -m "${PIP[@]}" "${reqs[@]}" || die "pip install ${reqs[*]} failed"
  write_stamp "$name" "$key"
}

# ---------------------------------------------------------------------------------------------
# 3. the interface packages (msg/: sorting_line_interfaces; msg/simulation_interfaces/) -> .venv
# ---------------------------------------------------------------------------------------------
# Trap: the wheels' exported CMake files (share/*/cmake/*.cmake, the *__rosidl_generator_pyExport
# ones) hard-code the include dirs of the interpreter that built the wheels
# (/opt/python/cp311-cp311/... for the cp311 wheels, cp312-cp312 for the cp312 ones). Point them at this
# venv's Python and numpy include dirs.
fix_wheel_cmake_paths() {
  local py_inc np_inc files v tag
  v="$(python_version "$VENV/bin/python")"
  tag="cp${v/./}-cp${v/./}"
  py_inc="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
  np_inc="$("$VENV/bin/python" -c 'import numpy; print(numpy.get_include())')"
  [[ -f "$py_inc/Python.h" ]] ||
    die "Python headers missing ($py_inc/Python.h); Debian: apt-get install python$v-dev"
  files="$(grep -rlF --include='*.cmake' "/opt/python/$tag" "$VENV/share" || true)"
  if [[ -n "$files" ]]; then
    say "interfaces: rewriting build-machine include paths in $(wc -l <<<"$files") wheel CMake files"
    # numpy first: its path contains the Python prefix.
    xargs -d "\n" sed -i \
      -e "s#/opt/python/$tag/lib/python$v/site-packages/numpy/_core/include#${np_inc}#g" \
      -e "s#/opt/python/$tag/include/python$v#${py_inc}#g" <<<"$files"
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
  [[ -f "$SITE/$1/msg/__init__.py" ]]
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
  rm -rf "${SITE:?}/$1"
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
  if ! command -v cc >/dev/null 2>&1 || ! command -v c++ >/dev/null 2>&1; then
    die "C/C++ compilers missing; Debian: apt-get install build-essential"
  fi
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
  # The editable install builds the native extension (native/, with maturin) into the package
  # directory: a change of its Rust sources (or of the line model's) builds it again.
  key="$( { echo "$ROOT"; cat "$BRIDGE/pyproject.toml" "$ROOT/Cargo.toml" "$ROOT/Cargo.lock";
            find "$ROOT/native" "$ROOT/src" -name '*.rs' -o -name Cargo.toml | LC_ALL=C sort | xargs cat; } | sha)"
  if stamp_matches bridge "$key"; then
    say "bridge: up to date"
    return
  fi
  say "bridge: pip install -e bridge, building its native extension (dependencies come from the pinned requirements)"
  # maturin's build hooks run the `maturin` command: the venv's, on PATH.
  PATH="$VENV/bin:$PATH" "$VENV/bin/python" -m pip install --no-input --disable-pip-version-check -q --no-deps \
    --no-build-isolation -e "$BRIDGE" ||
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
# Serialise concurrent runs on one venv (run.sh and test.sh may both call this): lock on this script
# file for .venv, on a file beside the venv for another one (test.sh sets up both at once).
if command -v flock >/dev/null 2>&1; then
  if [[ "$VENV" == "$ROOT/.venv" ]]; then
    exec 9<"${BASH_SOURCE[0]}"
  else
    exec 9>"$VENV.lock"
  fi
  flock -x 9
fi

start_rust
make_venv
PY_ID="$("$VENV/bin/python" -c 'import sys; print(sys.version.split()[0], sys.implementation.cache_tag)')"
SITE="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
mkdir -p "$STATE"
install_wheels
# As if-statements, not `[[ ]] && step`: bash runs a function called from an && list without errexit,
# so a failing command inside it would not end the script.
if [[ $TRAIN == 1 ]]; then
  install_extra train "requirements-train.txt (torch, SB3, RL Zoo, tensorboard: ~5 GB, most of it torch's CUDA libraries)" "$REQ_TRAIN"
fi
if [[ $RLLIB == 1 ]]; then
  install_extra rllib "requirements-rllib.txt (Ray; ~1 min from a warm pip cache, minutes cold)" "$REQ_TRAIN" "$REQ_RLLIB"
fi
build_interfaces simulation_interfaces "$MSG_DIR/simulation_interfaces" \
  'from simulation_interfaces.srv import StepSimulation; from simulation_interfaces.action import SimulateSteps'
build_interfaces sorting_line_interfaces "$MSG_DIR" \
  'from sorting_line_interfaces.msg import LineState; from sorting_line_interfaces.srv import ResetLine'
install_bridge
build_rust
if "$VENV/bin/python" -c 'import importlib.util, sys; sys.exit(importlib.util.find_spec("torch") is None)'; then
  stack="with the training stack"
else
  stack="the core, without the training stack: setup.sh --train adds it"
fi
say "venv: $(du -sh "$VENV" | cut -f1) ($stack; Python $(python_version "$VENV/bin/python"))"
say "done (source launch_scripts/env.sh to use the venv with the project's ROS settings)"
