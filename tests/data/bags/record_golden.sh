#!/usr/bin/env bash
# Re-records the golden bags of this directory with `sorting-line-bag record` (see
# tests/python/support/bag_golden.py for what is recorded and how): in a loopback-only network namespace
# (needs root), on a domain id of its own. Check the result with
#   bash launch_scripts/test.sh -k bag
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)"
cd "$ROOT"
bash launch_scripts/setup.sh >/dev/null
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((100 + $$ % 100))}"
unshare -n bash -c '
  set -euo pipefail
  ip link set lo up
  source launch_scripts/env.sh
  cd tests/python
  python -m support.bag_golden "$@"
' bash "$@"   # no names: every bag of bag_golden.GOLDEN
