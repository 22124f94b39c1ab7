#!/usr/bin/env bash
# The main job on a fresh machine: set up what is missing, then, through ROS 2 (every agent drives
# a real sorting_line node over DDS):
#   1. evaluate random, rba and rba-hold on the paper's 8 setups (seeds 42..51, 50 steps)
#      -> results/baselines/ (table.md, table.json, figure7, figure3, dashboards/)
#   2. train a quick PPO on setup B advanced (the paper's hyperparameters, a short budget) and
#      evaluate it beside the rule-based agents -> results/quick_ppo/
#   3. print both tables; results/summary.md holds them.
# About 4 minutes after set-up on 2 cores. DDS stays on this machine: as root the job runs in a
# loopback-only network namespace, otherwise with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST.
#
# Usage: launch_scripts/run.sh [--quick-steps N] [--full|--smoke [--jobs J] [--train-seeds S...] [--timesteps N]
#                               [--n-envs N] [--lines-mapping M] [--heldout-episodes N]] [--backend ros|native] [--out DIR]
#   --quick-steps N   PPO budget of step 2 (default 20000)
#   --full            instead: the whole study of docs/benchmark.md (Table 1: 8 lines x random, rba,
#                     rba-hold, and DQN, PPO, A2C at 100k steps for each of 5 training seeds on 8 lines
#                     of one node; every agent on seeds 42..51 and 100 held-out seeds, the oracle, IQM
#                     with CIs; DQN, PPO and A2C on B advanced and D basic also on one line, for the
#                     per-algorithm --n-envs check) -> results/benchmark/; resumable (finished cells are
#                     kept), progress shown
#   --smoke           the same pipeline at CI size (B advanced: random, rba-hold, PPO at 512 steps, 2
#                     seeds, 2 lines and 1 line, 5 held-out seeds) -> results/smoke/; a few minutes
#   --jobs J          cells at once in --full/--smoke (default 2)
#   --train-seeds S.. training seeds (default 42 43 44 45 46; --smoke 42 43)
#   --timesteps N     training budget per RL cell (default 100000; --smoke 512)
#   --n-envs N        lines of one node per training, a power of two (default 8; --smoke 2)
#   --lines-mapping M how the one-line hyperparameters go to N lines: same-rollout (default) or
#                     same-line-rollout (see bridge/sorting_line_gym/training/hyperparams.py)
#   --heldout-episodes N  held-out evaluation seeds from 10000 (default 100; --smoke 5)
#   --backend B       ros (default: every agent drives a node over DDS) or native (the line in-process,
#                     docs/native.md: the same cells, without the round trips)
#   --out DIR         results directory (default results)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
QUICK_STEPS=20000
FULL=0
SMOKE=0
JOBS=2
SEEDS=()
TIMESTEPS=""
N_ENVS=""
MAPPING=same-rollout
HELDOUT=""
OUT=results
BACKEND=ros
usage() { sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --quick-steps) QUICK_STEPS="$2"; shift 2 ;;
    --full) FULL=1; shift ;;
    --smoke) SMOKE=1; shift ;;
    --timesteps) TIMESTEPS="$2"; shift 2 ;;
    --n-envs) N_ENVS="$2"; shift 2 ;;
    --lines-mapping) MAPPING="$2"; shift 2 ;;
    --heldout-episodes) HELDOUT="$2"; shift 2 ;;
    --jobs) JOBS="$2"; shift 2 ;;
    --train-seeds) shift; SEEDS=(); while [[ $# -gt 0 && "$1" != --* ]]; do SEEDS+=("$1"); shift; done ;;
    --out) OUT="$2"; shift 2 ;;
    --backend) BACKEND="$2"; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "run.sh: unknown argument '$1' (allowed: --quick-steps N, --full, --smoke, --jobs J, --train-seeds S..., --timesteps N, --n-envs N, --lines-mapping M, --heldout-episodes N, --backend B, --out DIR)" >&2; exit 2 ;;
  esac
done
if [[ $FULL == 1 && $SMOKE == 1 ]]; then echo "run.sh: --full and --smoke exclude each other" >&2; exit 2; fi
if [[ $SMOKE == 1 ]]; then
  [[ ${#SEEDS[@]} -gt 0 ]] || SEEDS=(42 43)
  TIMESTEPS="${TIMESTEPS:-512}" N_ENVS="${N_ENVS:-2}" HELDOUT="${HELDOUT:-5}"
else
  [[ ${#SEEDS[@]} -gt 0 ]] || SEEDS=(42 43 44 45 46)
  TIMESTEPS="${TIMESTEPS:-100000}" N_ENVS="${N_ENVS:-8}" HELDOUT="${HELDOUT:-100}"
fi
case "$BACKEND" in
  ros|native) ;;
  *) echo "run.sh: --backend '$BACKEND' is not valid: allowed ros, native" >&2; exit 2 ;;
esac
case "$MAPPING" in
  same-rollout|same-line-rollout) ;;
  *) echo "run.sh: --lines-mapping '$MAPPING' is not valid: allowed same-rollout, same-line-rollout" >&2; exit 2 ;;
esac
for value in "$QUICK_STEPS" "$JOBS" "$TIMESTEPS" "$N_ENVS" "$HELDOUT" "${SEEDS[@]}"; do
  if ! [[ "$value" =~ ^[0-9]+$ ]]; then echo "run.sh: '$value' is not valid: allowed a whole number" >&2; exit 2; fi
done

# Every mode trains (PPO, DQN, A2C): the training stack too (setup.sh --train).
bash launch_scripts/setup.sh --train
mkdir -p "$OUT"
OUT="$(cd "$OUT" && pwd)"

# The job itself, run below in a loopback-only namespace when we can make one.
job() {
  source launch_scripts/env.sh
  export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((150 + $$ % 50))}"
  if [[ $FULL == 1 || $SMOKE == 1 ]]; then
    local -a seeds selection=()
    read -ra seeds <<< "$SEEDS_LIST"
    local dir="$OUT/benchmark"
    if [[ $SMOKE == 1 ]]; then
      dir="$OUT/smoke"
      selection=(--setups B --variants advanced --agents random rba-hold ppo)
    fi
    local start=$SECONDS
    sorting-line-benchmark --out "$dir" --jobs "$JOBS" --train-seeds "${seeds[@]}" --timesteps "$TIMESTEPS" \
      --n-envs "$N_ENVS" --lines-mapping "$MAPPING" --check-n-envs --heldout-episodes "$HELDOUT" --backend "$BACKEND" \
      "${selection[@]}"
    echo "run.sh: the study took $(( (SECONDS - start) / 60 )) min $(( (SECONDS - start) % 60 )) s (cells already done were not rerun) -> $dir" >&2
    return
  fi
  echo "== 1/2: random, rba, rba-hold on the 8 setups through ROS" >&2
  sorting-line-benchmark --agents random rba rba-hold --out "$OUT/baselines" --backend "$BACKEND" > /dev/null
  echo "== 2/2: PPO on setup B advanced, $QUICK_STEPS steps, beside the rule-based agents" >&2
  sorting-line-benchmark --setups B --variants advanced --agents rba rba-hold ppo --timesteps "$QUICK_STEPS" \
    --out "$OUT/quick_ppo" --backend "$BACKEND" > /dev/null
  {
    echo "# sorting_line: the default job of launch_scripts/run.sh"
    echo
    echo "## Built-in agents through ROS (seeds 42..51, 50 steps)"
    echo
    sed '1,2d' "$OUT/baselines/table.md"
    echo
    echo "## A quick PPO ($QUICK_STEPS steps) on setup B advanced"
    echo
    sed '1,2d' "$OUT/quick_ppo/table.md"
    echo
    echo "Figures: baselines/figure7.png, baselines/figure3.png; episode dashboards in */dashboards/."
    echo "The full benchmark (100k steps per RL agent): launch_scripts/run.sh --full"
  } > "$OUT/summary.md"
  cat "$OUT/summary.md"
  echo "written: $OUT/summary.md, $OUT/baselines/, $OUT/quick_ppo/" >&2
}
export -f job
export FULL SMOKE JOBS QUICK_STEPS TIMESTEPS N_ENVS MAPPING HELDOUT OUT
export SEEDS_LIST="${SEEDS[*]}"

if [[ $(id -u) == 0 ]] && command -v unshare >/dev/null && unshare -n true 2>/dev/null; then
  unshare -n bash -c 'ip link set lo up; job'
else
  echo "run.sh: not root: running on the host network with discovery limited to this machine" >&2
  job
fi
