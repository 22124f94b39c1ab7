#!/usr/bin/env bash
# Every test of sorting_line, from a fresh clone: installs what it needs (launch_scripts/setup.sh),
# then runs the Rust tests and the Python/ROS integration tests. The ROS tests run inside a
# loopback-only network namespace on a test-specific ROS_DOMAIN_ID, so no DDS traffic leaves
# this machine and parallel runs cannot cross-talk over the network. (Not over shared memory,
# which namespaces do not separate: every rclpy participant in LOCALHOST mode opens Fast DDS's
# /dev/shm port 7000, whatever its domain, besides ports derived from its domain id.)
#
# Usage: launch_scripts/test.sh [--rust-only] [PYTEST_ARGS...]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source launch_scripts/jobs.sh

RUST_ONLY=0
if [[ "${1:-}" == "--rust-only" ]]; then RUST_ONLY=1; shift; fi

step() { printf '\n== %s\n' "$*"; }

step "set-up (venv, interfaces, release build)"
bash launch_scripts/setup.sh

# The real ros2 CLI for tests/python/test_ros2cli.py: built (or found in its cache) here, outside the
# test network namespace, because it needs PyPI; in the background, next to the Rust tests.
# Ray RLlib for tests/python/test_rllib.py: ~1 min warm, more cold, mostly download, so
# also in the background next to the Rust tests; the Python tests start once it is in (pip must not
# write into the venv while they import from it).
# The colcon workspace of tests/python/test_colcon_package.py (the node as a ROS 2 package): colcon from
# PyPI in a cached venv of its own, then a plain `colcon build` against .venv that reuses the release
# build's target/ (about 1 min of CPU, the interface packages' C/C++/Python generation): also in the
# background. A failed build is recorded for the test, which then fails showing the log.
if [[ $RUST_ONLY == 0 ]]; then
  job_start ros2cli .venv/bin/python tests/python/ros2_cli.py --build
  job_start rllib bash launch_scripts/setup.sh --rllib --no-cargo
  SORTING_LINE_COLCON_WS="$(mktemp -d /tmp/sorting_line_colcon_ws.XXXXXX)"
  export SORTING_LINE_COLCON_WS
  job_start colcon .venv/bin/python tests/python/colcon_ws.py --build
fi

step "Rust formatting (rustfmt.toml)"
if cargo fmt --version >/dev/null 2>&1; then
  cargo fmt --check || { echo "test.sh: run \`cargo fmt\` (the diff above is what it would change)" >&2; exit 1; }
else
  echo "test.sh: rustfmt is not installed (rustup component add rustfmt): formatting not checked"
fi

step "Python lint and formatting (ruff.toml)"
.venv/bin/ruff check --no-cache . || { echo "test.sh: fix what \`.venv/bin/ruff check\` reports above (\`--fix\` fixes the ones marked [*])" >&2; exit 1; }
.venv/bin/ruff format --check --no-cache . || { echo "test.sh: run \`.venv/bin/ruff format\` (it would reformat the files above)" >&2; exit 1; }

step "Rust lints (clippy, warnings are errors; with and without the ros feature)"
# About 2 CPU-minutes: a metadata-only check of every dependency (clippy cannot reuse the release
# build), then seconds for the crate without the ros feature.
if cargo clippy --version >/dev/null 2>&1; then
  cargo clippy --locked --all-targets -- -D warnings
  cargo clippy --locked --all-targets --no-default-features -- -D warnings
else
  echo "test.sh: clippy is not installed (rustup component add clippy): lints not checked"
fi

step "Rust tests (unit, golden trajectories, properties)"
cargo test --release --locked

step "The simulation library alone (no ros feature: no DDS dependency)"
# About 1 CPU-minute: the release build shares the target dir, so only this crate and the few
# dependencies whose features the DDS stack widens (rand, rand_chacha, serde_json) compile again.
cargo build --release --locked --no-default-features
cargo test --release --locked --no-default-features --lib --tests
# Both put the binary without the `node` command at target/release/sorting_line: this relinks the
# full one from the cache (seconds), which the ROS tests below run.
cargo build --release --locked

[[ $RUST_ONLY == 1 ]] && exit 0

step "Ray RLlib for the RLlib tests"
job_join rllib "test.sh: installing Ray RLlib (setup.sh --rllib, launch_scripts/requirements-rllib.txt)"
export SORTING_LINE_RLLIB=1

step "ros2 CLI for the CLI tests"
job_join ros2cli "test.sh: building the ros2 CLI venv from shared/tools/ros2cli"

step "colcon workspace for the ROS 2 package test"
job_join colcon "test.sh: tests/python/colcon_ws.py --build"

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
status=0
unshare -n bash -c '
  set -euo pipefail
  ip link set lo up
  source launch_scripts/env.sh
  # --durations: where the minutes of the suite go, in every CI log (a run must stay well under 20 min).
  python -m pytest tests/python -q -rs -p no:cacheprovider --durations=12 "$@"
' test.sh "$@" || status=$?
shm_clean
rm -rf "$SORTING_LINE_COLCON_WS"
exit "$status"
