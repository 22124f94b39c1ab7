#!/usr/bin/env bash
# The reliability suite in full size: message-level fuzzing of commands, parameter files
# and --ros-args (proptest, FUZZ_CASES cases per property), the Python/ROS reliability tests
# (faults, bad input at the real node, determinism across paths, a 50,000-tick soak), Ray RLlib
# (tests/python/test_rllib.py: PPO with 2 EnvRunners x 4 envs, and a Ray cluster of a head and a
# worker in two network namespaces; about a minute each, too slow for CI), the wire fuzz
# (tests/python/test_wire_fuzz.py: malformed and mutated RTPS datagrams at the node's UDP ports,
# WIRE_DATAGRAMS datagrams within WIRE_SECONDS s), two 1,000,000-tick soaks through the bridge
# (basic setup A with its plot, advanced setup D), and the close stress (benches/close_stress.py:
# create / step / close cycles of the vectorizers under two CPU hogs, counting hangs). CI runs the
# same tests in reduced size through launch_scripts/test.sh (256 fuzz cases, 50,000 datagrams
# within 15 s, the 50,000-tick soak).
#
# Everything that starts nodes runs in a loopback-only network namespace (unshare -n, as root) on
# a ROS_DOMAIN_ID of its own. Outputs (logs, soak JSON and PNG) go to results/reliability/.
#
# Usage: launch_scripts/reliability.sh [--ticks N] [--fuzz-cases N] [--wire-datagrams N] [--wire-seconds S]
#        [--plot FILE] [--close-cycles N] (defaults: 1000000 ticks, 20000 cases, 2000000 datagrams
#        within 600 s, results/reliability/soak.png, 30 close cycles)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
TICKS=1000000
FUZZ_CASES=20000
CLOSE_CYCLES=30
WIRE_DATAGRAMS=2000000
WIRE_SECONDS=600
OUT=results/reliability
PLOT="$OUT/soak.png"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --ticks) TICKS="$2"; shift 2 ;;
    --fuzz-cases) FUZZ_CASES="$2"; shift 2 ;;
    --wire-datagrams) WIRE_DATAGRAMS="$2"; shift 2 ;;
    --wire-seconds) WIRE_SECONDS="$2"; shift 2 ;;
    --plot) PLOT="$2"; shift 2 ;;
    --close-cycles) CLOSE_CYCLES="$2"; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "reliability.sh: unknown argument '$1' (allowed: --ticks N, --fuzz-cases N, --wire-datagrams N, --wire-seconds S, --plot FILE, --close-cycles N)" >&2; exit 2 ;;
  esac
done
step() { printf '\n== %s\n' "$*"; }

bash launch_scripts/setup.sh --rllib
mkdir -p "$OUT"

step "fuzz: commands, parameter files, --ros-args ($FUZZ_CASES cases per property)"
SORTING_LINE_FUZZ_CASES="$FUZZ_CASES" cargo test --release --locked --test fuzz -- --nocapture 2>&1 | tee "$OUT/fuzz.log"

step "Python/ROS reliability tests (loopback-only network namespace; a 200-tick topic-level flood)"
export SORTING_LINE_FLOOD_TICKS=200
export ROS_DOMAIN_ID="${SORTING_LINE_TEST_DOMAIN:-$((100 + $$ % 100))}"
export SORTING_LINE_BIN="$ROOT/target/release/sorting_line"
unshare -n bash -c '
  set -euo pipefail
  ip link set lo up
  source launch_scripts/env.sh
  python -m pytest tests/python/test_reliability.py -q -p no:cacheprovider -rA
' 2>&1 | tee "$OUT/tests.log"

step "wire fuzz: RTPS datagrams at the node's UDP ports ($WIRE_DATAGRAMS datagrams within $WIRE_SECONDS s)"
SORTING_LINE_WIRE_FUZZ_DATAGRAMS="$WIRE_DATAGRAMS" SORTING_LINE_WIRE_FUZZ_SECONDS="$WIRE_SECONDS" unshare -n bash -c '
  set -euo pipefail
  ip link set lo up
  source launch_scripts/env.sh
  python -m pytest tests/python/test_wire_fuzz.py -q -s -p no:cacheprovider -rA
' 2>&1 | tee "$OUT/wire_fuzz.log"

step "Ray RLlib: PPO on 2 EnvRunners x 4 envs; a Ray cluster of two network-namespace hosts"
unshare -n bash -c '
  set -euo pipefail
  ip link set lo up
  source launch_scripts/env.sh
  SORTING_LINE_RLLIB=1 python -m pytest tests/python/test_rllib.py -q -s -p no:cacheprovider -rA
' 2>&1 | tee "$OUT/rllib.log"

step "soak: $TICKS line-ticks through the bridge, basic line, setup A"
.venv/bin/python benches/soak.py --ticks "$TICKS" --domain "$(( ROS_DOMAIN_ID + 1 ))" \
  --json "$OUT/soak.json" --plot "$PLOT" 2>"$OUT/soak.progress" | tee "$OUT/soak.log"

step "soak: $TICKS line-ticks through the bridge, advanced line, setup D"
.venv/bin/python benches/soak.py --ticks "$TICKS" --setup D --variant advanced --domain "$(( ROS_DOMAIN_ID + 2 ))" \
  --json "$OUT/soak_advanced.json" --plot "$OUT/soak_advanced.png" 2>"$OUT/soak_advanced.progress" \
  | tee "$OUT/soak_advanced.log"

step "close stress: $CLOSE_CYCLES create / step / close cycles of each vectorizer, two CPU hogs"
.venv/bin/python benches/close_stress.py --cycles "$CLOSE_CYCLES" --hogs 2 --domain "$(( ROS_DOMAIN_ID + 3 ))" \
  --logs "$OUT/close_stress" 2>"$OUT/close_stress.progress" | tee "$OUT/close_stress.log"
