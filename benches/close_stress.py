#!/usr/bin/env python3
"""Close never hangs: create / step / close cycles of the vectorizers users bring, under CPU hogs.

Each cycle is a process of its own (this script with ``--child SUBJECT``) that makes its envs,
resets and steps them, closes them and exits; it gets --limit seconds for all of that, and a cycle
still running then is a hang (its process group is killed, its stderr kept). Subjects:
  - async_fork, async_forkserver, async_spawn: Gymnasium's AsyncVectorEnv of 4 envs with that
    multiprocessing context, each env spawning its node in its worker;
  - subproc16: SB3's SubprocVecEnv of 16 workers (start method --subproc-start, fork by default:
    the one whose workers hung in CI), envs on line servers (node="shared");
  - single100: 100 single envs in one process (node="shared"), closed one after another;
  - exit_unclosed, exit_on_exception: one env (its own node) in a script that ends without
    closing it, normally and on an uncaught exception (its exit code must be 1).
Printed per subject: cycles, hangs (target 0), failed cycles, and the close() times (median, p99,
slowest) and how long the process took to end after close() returned (or after its last step).

    .venv/bin/python benches/close_stress.py                  # 30 cycles each, 2 CPU hogs
    .venv/bin/python benches/close_stress.py --cycles 3 --subjects async_spawn,subproc16

Runs itself in a loopback-only network namespace (ros_harness.run_isolated); each subject on a
ROS_DOMAIN_ID of its own from --domain (default 160) up. Progress to stderr, the table to stdout,
with the machine's load. The stderr of a hung or failed cycle is kept in --logs.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
from support import ros_harness as h  # noqa: E402

SUBJECTS = (
    "async_fork",
    "async_forkserver",
    "async_spawn",
    "subproc16",
    "single100",
    "exit_unclosed",
    "exit_on_exception",
)
BASIC = "sorting_line_gym:SortingLine-v0"
#: DDS ports are 7400 + 250 * domain + offsets below 65,536: the highest usable domain id.
MAX_DOMAIN_ID = 232
STEPS = 20


# ------------------------------------------------------------------------------------------------
# the child: one cycle of one subject


def child_async(context: str) -> dict:
    import gymnasium as gym
    import numpy as np
    from gymnasium.vector import AsyncVectorEnv

    make = functools.partial(gym.make, BASIC, setup="B", max_episode_steps=1000)
    envs = AsyncVectorEnv([make] * 4, context=context)
    envs.reset(seed=[7 + k for k in range(4)])
    for t in range(STEPS):
        envs.step(np.full(4, t % 10))
    t0 = time.monotonic()
    envs.close()
    return {"close_s": time.monotonic() - t0}


def child_subproc(start_method: str) -> dict:
    import numpy as np
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    import sorting_line_gym  # noqa: F401 (registers the ids)

    vec = make_vec_env(
        BASIC,
        n_envs=16,
        seed=7,
        vec_env_cls=SubprocVecEnv,
        env_kwargs={"setup": "B", "node": "shared"},
        vec_env_kwargs={"start_method": start_method},
    )
    vec.reset()
    for t in range(STEPS):
        vec.step(np.full(16, t % 10))
    t0 = time.monotonic()
    vec.close()
    return {"close_s": time.monotonic() - t0}


def child_single100() -> dict:
    import gymnasium as gym

    import sorting_line_gym  # noqa: F401

    envs = [gym.make(BASIC, setup="B", node="shared") for _ in range(100)]
    for k, env in enumerate(envs):
        env.reset(seed=7 + k)
        env.step(k % 10)
    closes = []
    for env in envs:
        t0 = time.monotonic()
        env.close()
        closes.append(time.monotonic() - t0)
    return {"close_s": max(closes), "closes": closes}


def child_exit(raise_at_end: bool) -> dict | None:
    import gymnasium as gym

    import sorting_line_gym  # noqa: F401

    env = gym.make(BASIC, setup="B")
    env.reset(seed=7)
    for t in range(STEPS):
        env.step(t % 10)
    print(json.dumps({"ended_at": time.monotonic()}), flush=True)
    if raise_at_end:
        raise RuntimeError("close_stress: the script ends on an uncaught exception, its env open")
    return None  # the env is never closed: the interpreter ends with it open


def run_child(subject: str, subproc_start: str) -> None:
    if subject.startswith("async_"):
        result = child_async(subject.removeprefix("async_"))
    elif subject == "subproc16":
        result = child_subproc(subproc_start)
    elif subject == "single100":
        result = child_single100()
    else:
        child_exit(raise_at_end=subject == "exit_on_exception")
        return
    print(json.dumps({**result, "ended_at": time.monotonic()}), flush=True)


# ------------------------------------------------------------------------------------------------
# the parent: cycles, hangs, figures


def one_cycle(subject: str, args, env: dict, log: Path) -> dict:
    """Runs one cycle; returns its figures or {"hang": True} / {"failed": exit code}."""
    cmd = [sys.executable, __file__, "--child", subject, "--subproc-start", args.subproc_start]
    with open(log, "w") as err:
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, text=True, env=env, start_new_session=True)
        try:
            out, _ = p.communicate(timeout=args.limit)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.communicate()
            return {"hang": True}
    exited_at = time.monotonic()
    expected = 1 if subject == "exit_on_exception" else 0
    lines = [line for line in out.splitlines() if line.startswith("{")]
    if p.returncode != expected or not lines:
        return {"failed": p.returncode}
    figures = json.loads(lines[-1])
    figures["exit_s"] = exited_at - figures.pop("ended_at")
    log.unlink()
    return figures


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q * (len(ordered) - 1))))]


def summary(subject: str, results: list[dict]) -> str:
    hangs = sum(1 for r in results if r.get("hang"))
    failed = sum(1 for r in results if "failed" in r)
    closes = [c for r in results for c in r.get("closes", [r["close_s"]] if "close_s" in r else [])]
    exits = [r["exit_s"] for r in results if "exit_s" in r]

    def figures(values):
        if not values:
            return f"{'-':>7} {'-':>7} {'-':>7}"
        return f"{statistics.median(values):7.3f} {percentile(values, 0.99):7.3f} {max(values):7.3f}"

    return f"{subject:<18} {len(results):>6} {hangs:>5} {failed:>6}   {figures(closes)}   {figures(exits)}"


def start_hogs(n: int) -> list[subprocess.Popen]:
    """Busy loops that end with this process, however it ends (parent-death signal)."""
    from sorting_line_gym.line.process import with_parent_death_signal

    return [subprocess.Popen(with_parent_death_signal(["sh", "-c", "while :; do :; done"], "KILL")) for _ in range(n)]


def run_subject(subject: str, domain: int, args) -> list[dict]:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    results = []
    for cycle in range(args.cycles):
        log = Path(args.logs) / f"{subject}-{cycle}.stderr"
        result = one_cycle(subject, args, env, log)
        results.append(result)
        state = "HANG" if result.get("hang") else f"failed ({result['failed']})" if "failed" in result else "ok"
        kept = f", stderr kept in {log}" if log.exists() else ""
        h_close = f" close {result['close_s']:.3f} s" if "close_s" in result else ""
        print(f"[{subject} {cycle + 1}/{args.cycles}] {state}{h_close}{kept}", file=sys.stderr, flush=True)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", type=int, default=30, help="cycles per subject (default 30)")
    parser.add_argument("--subjects", default=",".join(SUBJECTS), help="comma-separated, of: " + ", ".join(SUBJECTS))
    parser.add_argument("--hogs", type=int, default=2, help="busy-looping processes beside the cycles (default 2)")
    parser.add_argument("--limit", type=float, default=180.0, help="seconds a cycle may take before it is a hang")
    parser.add_argument("--subproc-start", default="fork", choices=("fork", "forkserver", "spawn"))
    parser.add_argument("--domain", type=int, default=160, help="ROS_DOMAIN_ID of the first subject (default 160)")
    parser.add_argument("--logs", default=None, help="folder for the stderr of hung or failed cycles")
    parser.add_argument("--child", choices=SUBJECTS, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        run_child(args.child, args.subproc_start)
        return
    subjects = [s for s in args.subjects.split(",") if s]
    unknown = sorted(set(subjects) - set(SUBJECTS))
    if not 0 <= args.domain <= MAX_DOMAIN_ID - len(subjects) + 1:
        highest = MAX_DOMAIN_ID - len(subjects) + 1
        parser.error(f"--domain {args.domain}: allowed 0 ..= {highest} (a domain per subject)")
    if unknown or args.cycles < 1 or args.hogs < 0 or args.limit <= 0:
        parser.error(
            f"--subjects {unknown} unknown (allowed {', '.join(SUBJECTS)}), or --cycles < 1, --hogs < 0, --limit <= 0"
        )
    h.run_isolated(__file__)
    args.logs = args.logs or tempfile.mkdtemp(prefix="close_stress_")
    Path(args.logs).mkdir(parents=True, exist_ok=True)
    hogs = start_hogs(args.hogs)
    try:
        before = h.machine_conditions()
        table = [summary(s, run_subject(s, args.domain + i, args)) for i, s in enumerate(subjects)]
        after = h.machine_conditions()
    finally:
        for hog in hogs:
            hog.kill()
    print(f"close_stress: {args.cycles} cycles per subject, {args.hogs} CPU hogs, limit {args.limit:.0f} s a cycle")
    print(f"machine: {os.cpu_count()} CPUs; before: {before}; after: {after}")
    print(f"command: {' '.join([os.path.relpath(__file__, ROOT), *sys.argv[1:]])}")
    header = f"{'subject':<18} {'cycles':>6} {'hangs':>5} {'failed':>6}"
    print(f"{header}   close s: median  p99  max   exit s: median  p99  max")
    print("\n".join(table))


if __name__ == "__main__":
    main()
