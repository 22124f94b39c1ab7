#!/usr/bin/env bash
# The Rust checks that cost minutes of CPU and that no later test needs: clippy (three
# configurations), rustdoc, the simulation library alone (no ros feature) and the vendored crates'
# own unit tests. test.sh runs this in the background, niced, beside the Python tiers, which mostly
# wait (nodes starting, DDS discovery, replies): the ROS tier held a 2-core machine's load near 1.
# Run it on its own to check the Rust side before a push.
#
# It never takes target/release's build lock, which the tests' own cargo builds take (run.sh's
# set-up step, the wheel), and never rewrites the node binary the tests run: clippy and rustdoc
# check into target/debug, the library alone builds in target/no-ros, the vendored crates in
# target/vendor.
#
# Usage: launch_scripts/rust_checks.sh   (from a set-up checkout: .venv for PyO3's configuration)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

step() { printf '\n== %s  [rust_checks.sh +%d s]\n' "$*" "$SECONDS"; }

step "Rust lints (clippy, warnings are errors; with and without the ros feature)"
# About 2 CPU-minutes: a metadata-only check of every dependency (clippy cannot reuse the release
# build), then seconds for the crate without the ros feature.
if cargo clippy --version >/dev/null 2>&1; then
  cargo clippy --locked --all-targets -- -D warnings
  cargo clippy --locked --all-targets --no-default-features -- -D warnings
  # The Python extension (native/, PyO3): seconds beyond the lines above; PyO3 asks the venv's
  # Python for its configuration.
  PYO3_PYTHON="$PWD/.venv/bin/python" cargo clippy --locked -p sorting_line_native --all-targets -- -D warnings
else
  echo "rust_checks.sh: clippy is not installed (rustup component add clippy): lints not checked"
fi

step "Rust docs (rustdoc, warnings are errors: a broken intra-doc link fails)"
# Seconds after clippy: the dependencies are checked already, only the crate's own docs are built.
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --locked

step "The simulation library alone (no ros feature: no DDS dependency)"
# Its own target dir: the features the DDS stack widens (rand, rand_chacha, serde_json) are then
# those a user of the library alone gets, and the tests' target/release stays untouched. About
# 5 CPU-minutes (4.7 measured: the library's dependencies and the test dependencies in release).
no_ros=(--release --locked --no-default-features --target-dir target/no-ros)
cargo build "${no_ros[@]}"
cargo test "${no_ros[@]}" --lib --tests

step "Vendored crates' own unit tests (vendor/rustdds, vendor/ros2-client, with our patches)"
# Both copies' library unit tests, those that show our patches among them (vendor/upstream-reports/);
# their tests/ and examples/ are not vendored, and their doc tests are left out (each compiles a
# program of its own). vendor/Cargo.toml makes the two a workspace of their own (ros2-client on our
# rustdds), locked by vendor/Cargo.lock. A debug build in target/vendor: about 7 CPU-minutes cold
# (6.7 measured, the crates' dev-dependencies too), then about 15 s of tests. Built here (crates from the
# registry), run in a network namespace of their own: they open participants and UDP sockets on
# fixed ports, and two need multicast, which that namespace's loopback is given, so nothing leaves
# the machine and the host's network does not matter. Every test passes with our patches; one that
# fails upstream too would be skipped here by name (`--skip PATH`, exact), its reason beside it.
vendor_test_skips=()
if ! unshare -n true 2>/dev/null; then
  echo "rust_checks.sh: cannot create a network namespace for the vendored crates' tests (unshare -n needs root)" >&2
  exit 1
fi
vendor_tests=(--locked --manifest-path vendor/Cargo.toml --target-dir target/vendor --workspace --lib)
cargo test "${vendor_tests[@]}" --no-run
unshare -n bash -c '
  set -euo pipefail
  ip link set lo up
  ip link set lo multicast on
  ip route add 224.0.0.0/4 dev lo
  cargo test --offline "$@"
' rust_checks.sh "${vendor_tests[@]}" -- --exact "${vendor_test_skips[@]}" ||
  { echo "rust_checks.sh: the vendored crates' unit tests failed (above): a patch of vendor/ broke one, see CONTRIBUTING.md" >&2; exit 1; }

step "done"
