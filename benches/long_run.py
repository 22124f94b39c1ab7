#!/usr/bin/env python3
"""How a long lock-step run behaves tick after tick: one line (`SortingLineEnv`, its own node), N
steps with random actions and 250-step episodes, as a one-line training drives it.

Prints, per window of 8,192 ticks (the node's DDS writers keep at most 8,192 unacknowledged
samples: a writer whose readers stop acknowledging is cut there, all at once), the median and
the slowest step, the steps over 30 ms with their tick, and the node's resident memory. A healthy
node has no window whose slowest step stands out and a flat memory after warm-up; a step that
times out ends the run with the bridge's error, naming the tick.

It refuses to run outside an isolated loopback-only network namespace; as root it re-executes itself
under `unshare -n` with `lo` up. Figures, not assertions.

    source launch_scripts/env.sh
    python benches/long_run.py                 # 100,000 steps, setup B, advanced line
    python benches/long_run.py -n 50000 --seed 3
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))

from support import ros_harness as h  # noqa: E402

WINDOW = 8192
SLOW_S = 0.030
EPISODE_STEPS = 250


def run(steps: int, seed: int) -> None:
    import numpy as np

    from sorting_line_gym.envs.env import SortingLineEnv

    env = SortingLineEnv(setup="B", variant="advanced", max_episode_steps=EPISODE_STEPS, node="spawn")
    rng = np.random.default_rng(seed)
    try:
        env.reset(seed=seed)
        node_pid = env.bank.process.process.pid  # the env's own node (node="spawn")
        window, slow, first, resets = [], [], 0, 1
        print(f"{'ticks':>14} | median ms | slowest ms | node RSS MB", flush=True)
        for i in range(steps):
            start = time.perf_counter()
            _, _, terminated, truncated, _ = env.step(int(rng.integers(env.action_space.n)))
            seconds = time.perf_counter() - start
            tick = i + resets  # a reset starts a tick too
            if not window:
                first = tick
            window.append(seconds)
            if seconds > SLOW_S:
                slow.append((tick, seconds))
            if terminated or truncated:
                env.reset()
                resets += 1
            if len(window) == WINDOW or i == steps - 1:
                print(
                    f"{first:>6}-{tick:<7} | {statistics.median(window) * 1e3:9.2f} | "
                    f"{max(window) * 1e3:10.1f} | {h.rss_mb(node_pid):.1f}",
                    flush=True,
                )
                window = []
        print(f"steps over {SLOW_S * 1e3:.0f} ms: {len(slow)}", flush=True)
        for t, s in slow:
            print(f"  near tick {t}: {s * 1e3:.1f} ms (tick mod {WINDOW} = {t % WINDOW})")
    finally:
        env.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", "--steps", type=int, default=100_000, help="steps to run (default 100000)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the first episode and the actions (default 1)")
    args = parser.parse_args()
    if args.steps < 1:
        parser.error(f"--steps = {args.steps} is not valid: allowed 1 or more")
    h.run_isolated(__file__, "SORTING_LINE_LONG_RUN_IN_NETNS")
    env = h.ros_environment(default_domain="88")
    os.environ.setdefault("SORTING_LINE_BIN", str(h.node_binary()))
    print(f"node {h.node_binary()}; {', '.join(f'{k}={v}' for k, v in env.items())}; {h.machine_conditions()}")
    run(args.steps, args.seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
