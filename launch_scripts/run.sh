#!/usr/bin/env bash
# The main job on a fresh machine: set up what is missing, then evaluate the built-in agents
# (random, rba, rba-hold) on the paper's 8 setups with the paper's protocol (seeds 42..51,
# 50-step episodes) and write the table to results/baselines.md (and .json).
#
# Usage: launch_scripts/run.sh [--episodes N] [--seed S]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
EPISODES=10
SEED=42
while [[ $# -gt 0 ]]; do
  case "$1" in
    --episodes) EPISODES="$2"; shift 2 ;;
    --seed) SEED="$2"; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "run.sh: unknown argument '$1' (allowed: --episodes N, --seed S)" >&2; exit 2 ;;
  esac
done

bash launch_scripts/setup.sh
BIN="$ROOT/target/release/sorting_line"
mkdir -p results
OUT=results/baselines.md
JSON=results/baselines.json
# The reference implementation's RBA on seeds 42..51 (shared/reference/dynamics-of-the-reference.md).
declare -A REF=([A,basic]=27.02 [A,advanced]=36.71 [B,basic]=12.55 [B,advanced]=22.58
                [C,basic]=21.07 [C,advanced]=30.18 [D,basic]=6.41 [D,advanced]=16.28)
{
  echo "# Built-in agents, $EPISODES episodes from seed $SEED (episode reward: mean +- population std)"
  echo
  echo "| setup | variant | reference RBA | random | rba | rba-hold | rba-hold speed changes |"
  echo "|---|---|---|---|---|---|---|"
} > "$OUT"
echo "[" > "$JSON"
first=1
total=8; done_=0
for setup in A B C D; do
  for variant in basic advanced; do
    row="| $setup | $variant | ${REF[$setup,$variant]}"
    for agent in random rba rba-hold; do
      json=$("$BIN" eval --agent "$agent" --setup "$setup" --variant "$variant" --episodes "$EPISODES" --seed "$SEED" --json)
      [[ $first == 1 ]] && first=0 || echo "," >> "$JSON"
      echo "$json" >> "$JSON"
      cell=$(python3 -c 'import json,sys; d=json.loads(sys.argv[1]); print("%.2f +- %.2f" % (d["reward_mean"], d["reward_std"]))' "$json")
      row="$row | $cell"
      changes=$(python3 -c 'import json,sys; print("%.1f" % json.loads(sys.argv[1])["speed_changes_mean"])' "$json")
    done
    echo "$row | $changes |" >> "$OUT"
    done_=$((done_ + 1))
    printf '\r[run] evaluated %d/%d setups' "$done_" "$total" >&2
  done
done
echo "]" >> "$JSON"
echo >&2
cat "$OUT"
echo
echo "written: $OUT, $JSON"
