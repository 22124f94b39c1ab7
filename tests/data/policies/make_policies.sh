#!/usr/bin/env bash
# Trains, exports and records what the learned-controller tests use (docs/deploying-a-policy.md):
# two small PPO agents on setup B, advanced line (4096 steps each, seeds 42 and 43, the paper's PPO
# hyperparameters otherwise), their ONNX files, and the golden bag of the seed-42 policy driving a
# line (tests/data/bags/ppo_advanced_b). Training is deterministic: the same command gives the
# same weights. In a loopback-only network namespace (needs root), on a domain id of its own.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)"
cd "$ROOT"
bash launch_scripts/setup.sh >/dev/null
OUT=tests/data/policies
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((100 + $$ % 100))}"
# The script is in single quotes on purpose: $seed is the inner shell's; $OUT is spliced in.
# shellcheck disable=SC2016
unshare -n bash -c '
  set -euo pipefail
  ip link set lo up
  source launch_scripts/env.sh
  for seed in 42 43; do
    sorting-line-train --algo ppo --setup B --variant advanced --seed $seed --timesteps 4096 \
      --out '"$OUT"' --tensorboard none --no-progress
    sorting-line-export '"$OUT"'/ppo_B_advanced_seed$seed.zip --out '"$OUT"'/ppo_B_advanced_seed$seed.onnx
  done
'
bash tests/data/bags/record_golden.sh ppo_advanced_b
