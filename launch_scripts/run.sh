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
# Each step's output goes to results/logs/STEP.log (its progress to the terminal too); a step that
# fails ends run.sh at once with exit 1, naming the step and its log. Bad arguments: exit 2.
#
# Usage: launch_scripts/run.sh [--quick-steps N] [--full|--smoke [--jobs J] [--train-seeds S...] [--timesteps N]
#                               [--n-envs N] [--lines-mapping M]] [--heldout-episodes N] [--backend ros|native] [--out DIR]
#   --quick-steps N   PPO budget of step 2 (default 20000)
#   --full            instead: the whole study of docs/results/benchmark.md (Table 1: 8 lines x random, rba,
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
#   --heldout-episodes N  held-out evaluation seeds from 10000, in every step (default 100; --smoke 5)
#   --backend B       ros (default: every agent drives a node over DDS) or native (the line in-process,
#                     docs/native.md: the same cells, without the round trips)
#   --out DIR         results directory (default results), relative to the directory run.sh is called from
set -euo pipefail
CALLER_DIR="$PWD"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
ARGS=("$@")
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
bad() { echo "run.sh: $*" >&2; exit 2; }
ALLOWED="--quick-steps N, --full, --smoke, --jobs J, --train-seeds S..., --timesteps N, --n-envs N, --lines-mapping M, --heldout-episodes N, --backend B, --out DIR"
# The value of option $1, or exit 2 when it has none.
value_of() { [[ $# -ge 2 && "$2" != --* ]] || bad "$1 needs a value (allowed: $ALLOWED)"; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --quick-steps) value_of "$@"; QUICK_STEPS="$2"; shift 2 ;;
    --full) FULL=1; shift ;;
    --smoke) SMOKE=1; shift ;;
    --timesteps) value_of "$@"; TIMESTEPS="$2"; shift 2 ;;
    --n-envs) value_of "$@"; N_ENVS="$2"; shift 2 ;;
    --lines-mapping) value_of "$@"; MAPPING="$2"; shift 2 ;;
    --heldout-episodes) value_of "$@"; HELDOUT="$2"; shift 2 ;;
    --jobs) value_of "$@"; JOBS="$2"; shift 2 ;;
    --train-seeds) value_of "$@"; shift; SEEDS=(); while [[ $# -gt 0 && "$1" != --* ]]; do SEEDS+=("$1"); shift; done ;;
    --out) value_of "$@"; OUT="$2"; shift 2 ;;
    --backend) value_of "$@"; BACKEND="$2"; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) bad "unknown argument '$1' (allowed: $ALLOWED)" ;;
  esac
done
if [[ $FULL == 1 && $SMOKE == 1 ]]; then bad "--full and --smoke exclude each other"; fi
if [[ $SMOKE == 1 ]]; then
  [[ ${#SEEDS[@]} -gt 0 ]] || SEEDS=(42 43)
  TIMESTEPS="${TIMESTEPS:-512}" N_ENVS="${N_ENVS:-2}" HELDOUT="${HELDOUT:-5}"
else
  [[ ${#SEEDS[@]} -gt 0 ]] || SEEDS=(42 43 44 45 46)
  TIMESTEPS="${TIMESTEPS:-100000}" N_ENVS="${N_ENVS:-8}" HELDOUT="${HELDOUT:-100}"
fi
case "$BACKEND" in
  ros|native) ;;
  *) bad "--backend '$BACKEND' is not valid: allowed ros, native" ;;
esac
case "$MAPPING" in
  same-rollout|same-line-rollout) ;;
  *) bad "--lines-mapping '$MAPPING' is not valid: allowed same-rollout, same-line-rollout" ;;
esac
count() { [[ "$2" =~ ^[1-9][0-9]*$ ]] || bad "$1 '$2' is not valid: allowed a whole number from 1"; }
count --quick-steps "$QUICK_STEPS"
count --jobs "$JOBS"
count --timesteps "$TIMESTEPS"
count --n-envs "$N_ENVS"
count --heldout-episodes "$HELDOUT"
for value in "${SEEDS[@]}"; do
  [[ "$value" =~ ^[0-9]+$ ]] || bad "--train-seeds '$value' is not valid: allowed a whole number from 0"
done
[[ "$OUT" == /* ]] || OUT="$CALLER_DIR/$OUT"
LOGS="$OUT/logs"

# step NAME WHAT CMD...: runs CMD, its standard output into $LOGS/NAME.log and its standard error
# (progress, warnings) to the terminal and into the log; ends run.sh when it fails.
step() {
  local name="$1" what="$2" status=0
  shift 2
  local log="$LOGS/$name.log"
  printf '== %s (log: %s)\n' "$what" "$log" >&2
  : >"$log"
  # shellcheck disable=SC2094 # both write the log in append mode; nothing in the pipeline reads it
  { "$@" 2>&1 >>"$log" | tee -a "$log" >&2; } || status=$?
  if [[ $status != 0 ]]; then
    printf 'run.sh: step %s (%s) failed with exit %s; its log: %s\n' "$name" "$what" "$status" "$log" >&2
    exit 1
  fi
}

# The results must be writable before anything runs for minutes.
if ! mkdir -p "$LOGS" 2>/dev/null || ! [[ -w "$LOGS" ]]; then
  bad "--out '$OUT' cannot be written (its logs/ folder could not be made there)"
fi

# Stage 1 (outside the namespace: it needs the package registries): the set-up, then the job below,
# as root in a loopback-only network namespace of its own. The job runs this script again there with
# the same arguments, so it sees every option it was given (a list of variables to hand over to a
# child shell is how an option once got lost).
if [[ "${_SORTING_LINE_RUN_JOB:-}" != 1 ]]; then
  # Every mode trains (PPO, DQN, A2C): the training stack too (setup.sh --train).
  step setup "set-up: launch_scripts/setup.sh --train" bash launch_scripts/setup.sh --train
  if [[ $(id -u) == 0 ]] && command -v unshare >/dev/null && unshare -n true 2>/dev/null; then
    exec unshare -n env _SORTING_LINE_RUN_JOB=1 bash "${BASH_SOURCE[0]}" "${ARGS[@]}" --out "$OUT"
  fi
  echo "run.sh: not root: running on the host network with discovery limited to this machine" >&2
else
  ip link set lo up || { echo "run.sh: cannot bring up the loopback interface in the job's network namespace" >&2; exit 1; }
fi

# Stage 2: the job.
# shellcheck source=launch_scripts/env.sh
source launch_scripts/env.sh
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((150 + $$ % 50))}"

if [[ $FULL == 1 || $SMOKE == 1 ]]; then
  dir="$OUT/benchmark" name=full selection=()
  if [[ $SMOKE == 1 ]]; then
    dir="$OUT/smoke" name=smoke
    selection=(--setups B --variants advanced --agents random rba-hold ppo)
  fi
  start=$SECONDS
  step "$name" "the study of docs/results/benchmark.md ($name) -> $dir" \
    sorting-line-benchmark --out "$dir" --jobs "$JOBS" --train-seeds "${SEEDS[@]}" --timesteps "$TIMESTEPS" \
    --n-envs "$N_ENVS" --lines-mapping "$MAPPING" --check-n-envs --heldout-episodes "$HELDOUT" --backend "$BACKEND" \
    "${selection[@]}"
  [[ -s "$dir/table.md" ]] || { echo "run.sh: step $name ended without writing $dir/table.md" >&2; exit 1; }
  cat "$dir/table.md"
  echo "run.sh: the study took $(( (SECONDS - start) / 60 )) min $(( (SECONDS - start) % 60 )) s (cells already done were not rerun) -> $dir" >&2
  exit 0
fi

step baselines "1/2: random, rba, rba-hold on the 8 setups, backend $BACKEND" \
  sorting-line-benchmark --agents random rba rba-hold --heldout-episodes "$HELDOUT" --out "$OUT/baselines" \
  --backend "$BACKEND"
step quick_ppo "2/2: PPO on setup B advanced, $QUICK_STEPS steps, beside the rule-based agents, backend $BACKEND" \
  sorting-line-benchmark --setups B --variants advanced --agents rba rba-hold ppo --timesteps "$QUICK_STEPS" \
  --heldout-episodes "$HELDOUT" --out "$OUT/quick_ppo" --backend "$BACKEND"
# The summary is made only of what the steps wrote.
figures=()
for table in "$OUT/baselines/table.md" "$OUT/quick_ppo/table.md"; do
  [[ -s "$table" ]] || { echo "run.sh: $table is missing or empty although its step passed" >&2; exit 1; }
done
for figure in baselines/figure7.png baselines/figure3.png quick_ppo/figure7.png; do
  [[ -s "$OUT/$figure" ]] && figures+=("$figure")
done
{
  echo "# sorting_line: the default job of launch_scripts/run.sh"
  echo
  echo "## Built-in agents, backend $BACKEND (seeds 42..51, 50 steps)"
  echo
  sed '1,2d' "$OUT/baselines/table.md"
  echo
  echo "## A quick PPO ($QUICK_STEPS steps) on setup B advanced"
  echo
  sed '1,2d' "$OUT/quick_ppo/table.md"
  echo
  echo "Figures: ${figures[*]/%/,}" | sed 's/,$/./'
  if compgen -G "$OUT/*/dashboards/*.png" >/dev/null; then echo "Episode dashboards: baselines/dashboards/, quick_ppo/dashboards/."; fi
  echo "Logs of each step: logs/. The full benchmark (100k steps per RL agent): launch_scripts/run.sh --full"
} >"$OUT/summary.md"
cat "$OUT/summary.md"
echo "written: $OUT/summary.md, $OUT/baselines/, $OUT/quick_ppo/" >&2
