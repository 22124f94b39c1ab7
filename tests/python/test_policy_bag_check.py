"""`sorting-line-bag check` against the golden bag of a learned controller (tests/data/bags/ppo_advanced_b:
the PPO policy of tests/data/policies driving a lock-step line, setup B advanced; made by
tests/data/policies/make_policies.sh), as CI runs it, with the real `sorting-line-controller --policy`.

What must hold: the policy the bag was recorded with passes open and closed loop; a policy trained
with another seed (43) fails open loop, the message naming the tick and the field. About 40 s
(three controller start-ups, each waiting --line-timeout for a line node the open loop has not).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from support import ros_harness as h

BAG = h.ROOT / "tests" / "data" / "bags" / "ppo_advanced_b"
POLICIES = h.ROOT / "tests" / "data" / "policies"


pytestmark = pytest.mark.usefixtures("same_binary")  # conftest: the tools start the tests' binary


def check(controller_policy: Path, namespace: str, *flags: str) -> subprocess.CompletedProcess:
    controller = f"{Path(sys.executable).parent / 'sorting-line-controller'} --policy {controller_policy}"
    argv = [str(Path(sys.executable).parent / "sorting-line-bag"), "check", str(BAG), "--controller", controller]
    argv += ["--namespace", namespace, *flags]
    env = dict(os.environ, **h.ros_environment(), SORTING_LINE_BIN=str(h.node_binary()))
    return subprocess.run(argv, capture_output=True, text=True, timeout=300, env=env, stdin=subprocess.DEVNULL)


@pytest.mark.parametrize("loop", ["open", "closed"])
def test_the_recorded_policy_passes(loop, namespace):
    flags = ["--closed-loop"] if loop == "closed" else []
    r = check(POLICIES / "ppo_B_advanced_seed42.onnx", namespace(loop), *flags)
    assert r.returncode == 0, f"exit {r.returncode}\n{r.stdout}\n{r.stderr}"


def test_a_policy_trained_with_another_seed_fails_naming_tick_and_field(namespace):
    r = check(POLICIES / "ppo_B_advanced_seed43.onnx", namespace("seed43"))
    assert r.returncode == 1, f"exit {r.returncode}\n{r.stdout}\n{r.stderr}"
    out = r.stdout + r.stderr
    named = (
        r"cmd/(speed|sort_mode) at tick \d+ \(stamp [\d.]+ s, episode \d+ step \d+\), "
        r"field (speed|mode): bag \S+, controller"
    )
    assert re.search(named, out), out
