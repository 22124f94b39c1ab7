#!/usr/bin/env bash
# The ROS 2 Jazzy command line (ros2, ros2 launch, launch_test) without a ROS install, built into a venv of its
# own from the upstream sources pinned in launch_scripts/ros2cli-sources.txt: see launch_scripts/ros2cli.py,
# which does the work (this picks the interpreter), and docs/ros-without-a-ros-install.md.
#
# Usage: bash launch_scripts/ros2cli.sh [--from DIR] [--venv DIR] [--verify-only] [--force] [--interfaces-from VENV]
#   --from DIR      take the source archives from DIR (checked against their SHA-256); default: download them
#   --venv DIR      where to build (default .venv-ros2cli at the repository root)
#   --verify-only   only check the archives of --from DIR, build nothing
#   --force         build again although the stamp says the venv is current
#   --interfaces-from VENV  the project venv whose interfaces the CLI sees (default .venv; see setup.sh)
# Then: source .venv-ros2cli/env.sh (or DIR/env.sh).
# Environment: SORTING_LINE_PYTHON, the CPython 3.11 or 3.12 to build with, a version or a command as for
# setup.sh. Default: the interpreter of the project venv (--interfaces-from), whose compiled interfaces the
# CLI imports, so the two must be one Python version (ros2cli.py checks).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ARGS=()
if [[ -n "${SORTING_LINE_PYTHON:-}" ]]; then
  PYTHON="$(bash "$ROOT/launch_scripts/setup.sh" --find-python)" ||
    { echo "ros2cli.sh: no CPython 3.11 or 3.12 for SORTING_LINE_PYTHON=$SORTING_LINE_PYTHON" >&2; exit 1; }
  # The interpreter itself: not a launcher (pyenv shims) that may pick another one elsewhere, nor a venv's.
  PYTHON="$("$PYTHON" -c 'import sys; print(getattr(sys, "_base_executable", sys.executable))')"
  ARGS=(--python "$PYTHON")
else
  # ros2cli.py needs only the standard library; it finds the venv's interpreter itself.
  PYTHON="$(command -v python3)" ||
    { echo "ros2cli.sh: no python3 on PATH to run launch_scripts/ros2cli.py" >&2; exit 1; }
fi
exec "$PYTHON" "$ROOT/launch_scripts/ros2cli.py" "${ARGS[@]}" "$@"
