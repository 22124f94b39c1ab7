#!/usr/bin/env bash
# Every test of sorting_line, from a fresh clone: installs what it needs (launch_scripts/setup.sh),
# then runs the Rust tests, then the Python/ROS integration tests (the rest of tests/python) with the
# Python unit tests (tests/python/unit, on the host) and the slower Rust checks
# (launch_scripts/rust_checks.sh) in the background beside them. The ROS tests run inside a
# loopback-only network namespace on a test-specific ROS_DOMAIN_ID, so no DDS traffic leaves
# this machine and parallel runs cannot cross-talk over the network. (Not over shared memory,
# which namespaces do not separate: every rclpy participant in LOCALHOST mode opens Fast DDS's
# /dev/shm port 7000, whatever its domain, besides ports derived from its domain id.)
# Two Pythons: the whole suite runs in .venv (with the training stack; a fresh clone's is CPython
# 3.11), and the README's snippets and a subset (OTHER_PYTHON_TESTS) run again in a core venv
# (setup.sh without --train) of the other supported version, .venv-3.12 (or .venv-3.11), set up in
# the background beside the lints and the Rust tests. Without that interpreter the subset is skipped, loudly.
#
# Usage: launch_scripts/test.sh [--rust-only] [PYTEST_ARGS...]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source launch_scripts/jobs.sh

RUST_ONLY=0
if [[ "${1:-}" == "--rust-only" ]]; then RUST_ONLY=1; shift; fi

# Each step says when it starts, in seconds since test.sh began: a CI log then shows where the minutes go
# (docs/installing.md, "How long test.sh takes"), besides pytest's --durations for the slowest tests.
step() { printf '\n== %s  [test.sh +%d s]\n' "$*" "$SECONDS"; }

# The subset of the suite that runs on the other Python version: the README's snippets, the env,
# the vector env, bags, bag check, the controllers and the pytest plugin (tests needing the training
# stack skip there: tests/python/support/training_stack.py), less the two longest, which test nothing of the
# Python version (a throughput benchmark; the plugin's examples in a pytest of their own), which took 113
# of 388 s at load 9-13. What it costs: docs/installing.md, "Python 3.11 and 3.12".
OTHER_PYTHON_TESTS=(test_readme.py test_bridge.py test_bridge_vector.py test_bags.py test_bag_check.py
  test_controller.py test_learned_controller.py test_pytest_plugin.py
  --deselect test_bridge.py::test_throughput_benchmark_runs_and_reports_the_targets
  --deselect test_pytest_plugin.py::test_the_examples_pass_and_a_changed_controller_fails)
OTHER_PYTHON_TESTS=("${OTHER_PYTHON_TESTS[@]/#test_/tests/python/test_}")

step "set-up (venv with the training stack, interfaces, release build)"
# A fresh clone's .venv is CPython 3.11 unless SORTING_LINE_PYTHON says otherwise; an existing one keeps
# its version (3.11 or 3.12). (Not exported: launch_scripts/ros2cli.sh reads SORTING_LINE_PYTHON as a command.)
MAIN_CHOICE="${SORTING_LINE_PYTHON:-}"
[[ -x .venv/bin/python || -n "$MAIN_CHOICE" ]] || MAIN_CHOICE=3.11
SORTING_LINE_PYTHON="$MAIN_CHOICE" bash launch_scripts/setup.sh --train
# Foxglove's own JavaScript readers for tests/python/test_foxglove.py, as tests/foxglove/package-lock.json
# pins them (Node.js is the machine's package; seconds once npm's cache has them).
if [[ $RUST_ONLY == 0 ]]; then
  (cd tests/foxglove && npm ci --no-audit --no-fund --loglevel=error) || { echo "test.sh: npm ci in tests/foxglove failed" >&2; exit 1; }
fi
MAIN_PYTHON="$(.venv/bin/python -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
OTHER_PYTHON=3.12
[[ $MAIN_PYTHON == 3.12 ]] && OTHER_PYTHON=3.11
OTHER_VENV="$ROOT/.venv-$OTHER_PYTHON"
other_missing() {
  printf '\n!! test.sh: WARNING: no CPython %s found (python%s on PATH or in pyenv; or set SORTING_LINE_PYTHON):\n' \
    "$OTHER_PYTHON" "$OTHER_PYTHON" >&2
  printf '!! the README snippets and the subset of the suite on Python %s are SKIPPED; only %s was tested.\n\n' \
    "$OTHER_PYTHON" "$MAIN_PYTHON" >&2
}

# The real ros2 CLI for the CLI tests (test_ros2cli.py, test_launch_testing.py, ...): launch_scripts/ros2cli.sh
# builds it (or finds it current in its cache) from the folder of source archives beside the clone, here,
# outside the test network namespace, because it needs PyPI; in the background, next to the Rust tests.
# Ray RLlib for tests/python/test_rllib.py: ~1 min warm, more cold, mostly download, so
# also in the background next to the Rust tests; the Python tests start once it is in (pip must not
# write into the venv while they import from it).
# The colcon workspace of tests/python/test_colcon_package.py (the node as a ROS 2 package): colcon from
# PyPI in a cached venv of its own, then a plain `colcon build` against .venv that reuses the release
# build's target/ (about 1 min of CPU, the interface packages' C/C++/Python generation): also in the
# background. A failed build is recorded for the test, which then fails showing the log.
# The core venv of the other Python version (about 2 min from a warm pip cache; its native extension
# build waits for the Rust steps' cargo lock): in the background too.
if [[ $RUST_ONLY == 0 ]]; then
  if SORTING_LINE_PYTHON=$OTHER_PYTHON bash launch_scripts/setup.sh --find-python >/dev/null; then
    job_start other env SORTING_LINE_PYTHON="$OTHER_PYTHON" SORTING_LINE_VENV="$OTHER_VENV" \
      bash launch_scripts/setup.sh --no-cargo
  else
    OTHER_VENV=""
    other_missing
  fi
  job_start ros2cli .venv/bin/python tests/python/support/ros2_cli.py --build
  job_start rllib bash launch_scripts/setup.sh --rllib --no-cargo
  SORTING_LINE_COLCON_WS="$(mktemp -d /tmp/sorting_line_colcon_ws.XXXXXX)"
  export SORTING_LINE_COLCON_WS
  job_start colcon .venv/bin/python tests/python/support/colcon_ws.py --build
fi

step "Rust formatting (rustfmt.toml)"
if cargo fmt --version >/dev/null 2>&1; then
  # --all: the workspace's native/ crate (the Python extension) too.
  cargo fmt --all --check || { echo "test.sh: run \`cargo fmt --all\` (the diff above is what it would change)" >&2; exit 1; }
else
  echo "test.sh: rustfmt is not installed (rustup component add rustfmt): formatting not checked"
fi

step "Python lint and formatting (ruff.toml)"
.venv/bin/ruff check --no-cache . || { echo "test.sh: fix what \`.venv/bin/ruff check\` reports above (\`--fix\` fixes the ones marked [*])" >&2; exit 1; }
.venv/bin/ruff format --check --no-cache . || { echo "test.sh: run \`.venv/bin/ruff format\` (it would reformat the files above)" >&2; exit 1; }

step "Shell scripts (shellcheck, every rule: each one disabled is disabled on its line, with the reason)"
# Debian's package, installed here when missing (test.sh runs as root, as CI does).
if ! command -v shellcheck >/dev/null 2>&1; then
  echo "test.sh: installing shellcheck (apt-get install shellcheck)"
  { apt-get update -qq && apt-get install -y -qq --no-install-recommends shellcheck; } >/dev/null ||
    { echo "test.sh: could not install shellcheck with apt-get" >&2; exit 1; }
fi
# .githooks/: the hooks contributors install (CONTRIBUTING.md), bash scripts without the suffix.
mapfile -t shell_scripts < <(git ls-files '*.sh' .ci/run .githooks)
shellcheck -x "${shell_scripts[@]}" || { echo "test.sh: fix what shellcheck reports above (or disable a rule on its line, saying why)" >&2; exit 1; }
echo "test.sh: shellcheck $(shellcheck --version | sed -n 's/^version: //p'): ${#shell_scripts[@]} scripts clean"

step "Python types (mypy: the bridge modules without rclpy, [tool.mypy] in bridge/pyproject.toml)"
# About 11 CPU-seconds from a cold cache (bridge/.mypy_cache), under 1 warm; prints its verdict only.
(cd bridge && ../.venv/bin/mypy) || { echo "test.sh: fix the type errors above (\`cd bridge && ../.venv/bin/mypy\`)" >&2; exit 1; }

step "Python dependencies declared (deptry: bridge/pyproject.toml against the imports of sorting_line_gym)"
(cd bridge && ../.venv/bin/deptry .) || { echo "test.sh: declare what deptry reports above in bridge/pyproject.toml (dependencies or an extra), or drop what is not imported" >&2; exit 1; }

step "Rust tests (unit, golden trajectories, properties)"
cargo test --release --locked

step "Rust checks (launch_scripts/rust_checks.sh: clippy, rustdoc, the library alone, the vendored crates' tests)"
# About 10 CPU-minutes that nothing after them needs; before the Python tiers, which mostly wait, they
# took 9 of a fresh clone's 22 minutes before the first Python test (2026-12-03). So they run in the
# background, niced (the tests' processes come first on a CPU; the cores' caches are still shared, and
# the ROS tier ran about 2 minutes slower beside them: docs/installing.md), and their output and verdict
# come after the ROS tier; a failure there still fails test.sh. With --rust-only, here and now.
if [[ $RUST_ONLY == 1 ]]; then
  bash launch_scripts/rust_checks.sh
  exit 0
fi
job_start rust_checks nice -n 19 bash launch_scripts/rust_checks.sh

step "Ray RLlib for the RLlib tests"
job_join rllib "test.sh: installing Ray RLlib (setup.sh --rllib, launch_scripts/requirements-rllib.txt)"
export SORTING_LINE_RLLIB=1

step "ros2 CLI for the CLI tests"
job_join ros2cli "test.sh: building the ros2 CLI venv (launch_scripts/ros2cli.sh)"

step "colcon workspace for the ROS 2 package test"
job_join colcon "test.sh: tests/python/support/colcon_ws.py --build"

step "core venv of Python $OTHER_PYTHON for the subset"
# Joined before the suite: its editable install builds the native extension into bridge/.
if [[ -n "$OTHER_VENV" ]]; then
  job_join other "test.sh: setting up $OTHER_VENV (SORTING_LINE_VENV=$OTHER_VENV setup.sh --no-cargo)"
  if "$OTHER_VENV/bin/python" -c 'import importlib.util, sys; sys.exit(importlib.util.find_spec("torch") is None)'; then
    echo "test.sh: $OTHER_VENV is to be a core venv, but torch is installed in it" >&2
    exit 1
  fi
  # The core stays under 1.5 GB (docs/installing.md): a new dependency that pulls in a large one shows here.
  size_mb="$(du -sm "$OTHER_VENV" | cut -f1)"
  if ((size_mb >= 1536)); then
    echo "test.sh: the core venv $OTHER_VENV is $size_mb MB, over 1.5 GB: what of requirements-bridge.txt grew it?" >&2
    exit 1
  fi
  echo "test.sh: core venv $OTHER_VENV: $size_mb MB, no torch"
fi

# The Python unit tier (tests/python/unit: no root, no ROS environment, no network namespace, no node):
# the tier a contributor runs as any user in a minute or two (CONTRIBUTING.md, "Tests"), here on the
# host, outside the namespace; the ROS tier leaves unit/ out, so no test runs twice. As user nobody when
# nobody can run the venv's interpreter, which shows the tier needs no root; else as the current user
# (here and in CI /root is mode 700, so nobody cannot reach the pyenv interpreter behind .venv/bin/python).
# It runs beside the ROS tier, niced, like the Rust checks (its output comes after the ROS tier's), in
# a pytest temporary folder of its own. PYTEST_ARGS go to the ROS tier only: a path among them would
# put this session in the ROS tier.
# shellcheck disable=SC2317 # its lines run, through `bash -c unit_tier` (export -f) below
unit_tier() {
  set -euo pipefail
  local unit_home
  unit_home="$(mktemp -d /tmp/sorting_line_unit.XXXXXX)"
  # -n 0: one process here, where it shares the cores with the ROS tier (alone it takes two: pytest.ini).
  local unit_tests=(.venv/bin/python -m pytest tests/python/unit -q -rs -p no:cacheprovider --durations=8
    -n 0 --basetemp "$unit_home/pytest")
  local nobody=(setpriv --reuid=65534 --regid=65534 --clear-groups)
  # The probe runs the interpreter as the tier does (through env) and checks that it is the venv's: a
  # checkout under a directory nobody cannot enter (mktemp -d's mode 700) once let a bare probe start
  # another Python while the tier's own command was refused.
  local probe=(env .venv/bin/python -c "import sys; sys.exit(sys.prefix == sys.base_prefix)")
  local status=0
  if [[ $EUID == 0 ]] && command -v setpriv >/dev/null && "${nobody[@]}" "${probe[@]}" >/dev/null 2>&1; then
    chown 65534:65534 "$unit_home"
    echo "test.sh: the unit tier runs as user nobody (uid 65534), outside the network namespace"
    # A HOME of its own (caches, matplotlib); git trusts this root-owned clone (test_commit_msg_hook runs git).
    "${nobody[@]}" env HOME="$unit_home" PYTHONDONTWRITEBYTECODE=1 GIT_CONFIG_COUNT=1 \
      GIT_CONFIG_KEY_0=safe.directory GIT_CONFIG_VALUE_0="*" "${unit_tests[@]}" || status=$?
  else
    local why
    why="user nobody cannot run $(readlink -f .venv/bin/python)"
    [[ $EUID == 0 ]] || why="not root, so no other user to switch to"
    echo "test.sh: the unit tier runs as user $(id -un) (uid $EUID), outside the network namespace: $why"
    "${unit_tests[@]}" || status=$?
  fi
  rm -rf "$unit_home"
  return "$status"
}
export -f unit_tier
status=0
step "Python unit tests (tests/python/unit), in the background beside the ROS tier, niced: output after it"
job_start unit nice -n 19 bash -c unit_tier

step "Python/ROS integration tests (loopback-only network namespace)"
if ! command -v unshare >/dev/null || ! command -v ip >/dev/null; then
  echo "test.sh: needs unshare (util-linux) and ip (iproute2) to isolate DDS traffic" >&2
  exit 1
fi
# A domain id of its own per run: derived from the PID, within 100..199.
export ROS_DOMAIN_ID="${SORTING_LINE_TEST_DOMAIN:-$((100 + $$ % 100))}"
export SORTING_LINE_BIN="$ROOT/target/release/sorting_line"
# unshare -n needs root (CI and the dev machines run as root); say so rather than fail obscurely.
if ! unshare -n true 2>/dev/null; then
  echo "test.sh: cannot create a network namespace (unshare -n needs root); refusing to run DDS tests on the host network" >&2
  exit 1
fi
# rmw_fastrtps adds Fast DDS's shared-memory transport in LOCALHOST mode, and a process that dies
# without closing its participant (the tests kill nodes, workers and scripts on purpose) leaves its
# segments and ports in /dev/shm, which no network namespace separates: a run left ~230 MB there.
# `fastdds shm clean` removes the ones no live process holds (it checks their locks), before and
# after the tests, so runs neither pile them up nor start among a dead run's ports.
shm_clean() { .venv/bin/fastdds shm clean | tr '\n' ' ' | sed 's/^/Fast DDS /; s/ $/\n/' || true; }
shm_clean
# The tier runs in SHARDS pytest sessions at once (default 2), each in a network namespace of its own on
# a domain id of its own, taking the test files from a shared folder of claims (a file runs in the
# session that claims it first: tests/python/support/shards.py). Most of these tests wait, so one session
# kept the 2 cores about half busy for the last third of the tier (docs/installing.md). The first session
# prints here; the others' output follows it.
SHARDS="${SORTING_LINE_TEST_SHARDS:-2}"
if ! [[ $SHARDS =~ ^[1-9]$ ]]; then
  echo "test.sh: SORTING_LINE_TEST_SHARDS=$SHARDS: allowed a whole number 1 ..= 9 (ROS-tier sessions at once)" >&2
  exit 2
fi
claims="$(mktemp -d /tmp/sorting_line_claims.XXXXXX)"
# shellcheck disable=SC2317 # its lines run, through `bash -c ros_shard` (export -f) below
ros_shard() {
  set -euo pipefail
  local shard=$1
  shift
  local base
  base="$(mktemp -d "/tmp/sorting_line_ros_tier$shard.XXXXXX")"
  local status=0 domain=$ROS_DOMAIN_ID
  # The others' domains spread over 100..199, so the ids the tests derive from their session's stay apart too.
  ((shard == 0)) || domain=$((100 + (ROS_DOMAIN_ID - 100 + shard * 100 / SHARDS) % 100))
  # shellcheck disable=SC2016 # the inner script expands its own arguments and environment
  ROS_DOMAIN_ID=$domain unshare -n bash -c '
    set -euo pipefail
    ip link set lo up
    source launch_scripts/env.sh
    echo "test.sh: ROS-tier session $1 of $SHARDS, ROS_DOMAIN_ID=$ROS_DOMAIN_ID"
    base=$2
    shift 2
    # --durations: where the minutes of the suite go, in every CI log (the 20 slowest of each session);
    # classic output: no percentage, which would count the tests of the other sessions too.
    python -m pytest tests/python --ignore=tests/python/unit -q -rs -p no:cacheprovider --durations=20 \
      -o console_output_style=classic \
      --basetemp "$base/pytest" "$@"
  ' test.sh "$shard" "$base" "$@" || status=$?
  rm -rf "$base"
  return "$status"
}
export -f ros_shard
export SHARDS SORTING_LINE_TEST_CLAIMS="$claims"
for ((shard = 1; shard < SHARDS; shard++)); do
  job_start "ros_shard$shard" bash -c '
    set -euo pipefail
    ros_shard "$@"
  ' test.sh "$shard" "$@"
done
ros_shard 0 "$@" || status=$?
for ((shard = 1; shard < SHARDS; shard++)); do
  step "Python/ROS integration tests, session $shard of $SHARDS (beside the one above)"
  job_collect "ros_shard$shard" "test.sh: ROS-tier session $shard" || status=1
done
unset SORTING_LINE_TEST_CLAIMS
rm -rf "$claims"
shm_clean

step "Python unit tests (tests/python/unit), run beside the ROS tier"
job_collect unit "test.sh: the unit tier (tests/python/unit)" || status=1

step "Python $OTHER_PYTHON, core venv: the README's snippets and a subset of the suite"
if [[ -n "$OTHER_VENV" ]]; then
  start=$SECONDS
  unshare -n env SORTING_LINE_VENV="$OTHER_VENV" SORTING_LINE_CORE_VENV=1 bash -c '
    set -euo pipefail
    ip link set lo up
    source launch_scripts/env.sh
    python -m pytest "$@" -q -rs -p no:cacheprovider --durations=5
  ' test.sh "${OTHER_PYTHON_TESTS[@]}" || status=$?
  echo "test.sh: Python $OTHER_PYTHON subset: $((SECONDS - start)) s; $OTHER_VENV is $(du -sh "$OTHER_VENV" | cut -f1)"
  shm_clean
else
  other_missing
fi
rm -rf "$SORTING_LINE_COLCON_WS"

step "Rust checks (launch_scripts/rust_checks.sh), run beside the Python tiers"
job_collect rust_checks "test.sh: launch_scripts/rust_checks.sh" || status=1
step "done (exit $status)"
exit "$status"
