#!/usr/bin/env python3
"""Many envs on one host through the vectorizers users bring, against the real node.

Subjects, each a process of its own (started, warmed up, timed, stopped) on a ROS_DOMAIN_ID of its
own (so it starts its own line servers instead of reusing the previous subject's):
  - raw: the raw one-line rclpy lock-step loop (benches/bridge_throughput.py's (a)), round trips/s;
  - sync N (N = 1, 8, 32, 64): `gymnasium.make_vec(id, N, vectorization_mode="sync", node="shared")`,
    envs on line servers (16 lines per node process), 50-step episodes (TimeLimit; resets timed);
  - async N (N = 4, 8): the same with vectorization_mode="async" (Gymnasium's default context: fork);
  - ours N (N = 1, 4, 8, 32, 64): `SortingLineVectorEnv`, N lines of one node, batch topics.
For each: env-steps/s and its ratio to the raw loop's round trips/s (each env step of a
SyncVectorEnv is one round trip), start-up time (construction to the end of the first reset)
and resident memory: the subject's own process, its workers, and the node processes and
supervisors serving it. Memory per env beyond the first = (total(N) - total(1)) / (N - 1) for
the sync subjects. Targets: sync 64 starts in < 10 s, costs < 30 MB per env beyond the first, and
reaches >= 60 % of the raw loop's round trips/s.

    .venv/bin/python benches/vector_scaling.py                    # 300 vector steps per subject
    .venv/bin/python benches/vector_scaling.py --steps 500 --raw-steps 4000

Runs itself in a loopback-only network namespace (ros_harness.run_isolated); domains from
--domain (default 150) upwards. Progress to stderr, the table to stdout, with load and CPU steal.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
sys.path.insert(0, str(ROOT / "benches"))
from support import ros_harness as h  # noqa: E402

SUBJECTS = (
    ["raw"]
    + [f"sync_{n}" for n in (1, 8, 32, 64)]
    + [f"async_{n}" for n in (4, 8)]
    + [f"ours_{n}" for n in (1, 4, 8, 32, 64)]
)
#: The raw loop is measured again next to these subjects (the machine's speed drifts during a run):
#: its figure is the median of all its measurements.
RAW_AGAIN_AFTER = ("sync_1", "sync_64", "async_8", "ours_64")
TARGET_START_S, TARGET_MB_PER_ENV, TARGET_RAW_SHARE = 10.0, 30.0, 0.60
WARMUP = 50


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def descendants(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-e", "-o", "pid=,ppid="], capture_output=True, text=True).stdout
    children: dict[int, list[int]] = {}
    for line in out.splitlines():
        p, pp = map(int, line.split())
        children.setdefault(pp, []).append(p)
    found, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            found.append(c)
            todo.append(c)
    return found


def server_pids() -> list[int]:
    """Supervisors and nodes of the line servers in this network namespace (the subject's)."""
    from sorting_line_gym.line.host import host_state_directory, network_namespace

    pids = []
    for info in host_state_directory().glob("*/s*.json"):
        try:
            data = json.loads(info.read_text())
        except (OSError, ValueError):
            continue
        for pid in (data["pid"], data["node_pid"]):
            try:
                if os.readlink(f"/proc/{pid}/ns/net") == network_namespace():
                    pids.append(pid)
            except OSError:
                pass
    return pids


def measure_here(key: str, steps: int, raw_steps: int) -> dict:
    import gymnasium
    import numpy as np

    if key == "raw":
        from bridge_throughput import raw_subject

        with tempfile.TemporaryDirectory(prefix="sl_scaling_") as tmp:
            subject = raw_subject(raw_steps, Path(tmp))
            try:
                subject.warm_up()
                rate = subject.timed_run()
            finally:
                subject.close()
        return {"rate": rate, "envs": 1}
    kind, n = key.split("_")
    n = int(n)
    started = time.perf_counter()
    if kind == "ours":
        from sorting_line_gym import SortingLineVectorEnv

        env = SortingLineVectorEnv(num_envs=n, setup="A", variant="basic", max_episode_steps=50)
    else:
        env = gymnasium.make_vec(
            "sorting_line_gym:SortingLine-v0", num_envs=n, vectorization_mode=kind, setup="A", node="shared"
        )
    try:
        env.reset(seed=1)
        start_s = time.perf_counter() - started
        actions = [np.full(n, k % 10, dtype=np.int64) for k in range(10)]
        for i in range(WARMUP):
            env.step(actions[i % 10])
        t0 = time.perf_counter()
        for i in range(steps):
            env.step(actions[i % 10])
        rate = steps * n / (time.perf_counter() - t0)
        me = os.getpid()
        memory = h.rss_mb(*sorted({me, *descendants(me), *server_pids()}))  # servers may be our descendants too
    finally:
        env.close()
    return {"rate": rate, "envs": n, "start_s": start_s, "rss_mb": memory}


def measure_in_child(key: str, domain: int, args) -> dict:
    command = [
        sys.executable,
        os.path.abspath(__file__),
        "--subject",
        key,
        "--steps",
        str(args.steps),
        "--raw-steps",
        str(args.raw_steps),
        "--domain",
        str(domain),
    ]
    result = subprocess.run(command, capture_output=True, text=True, timeout=900)
    if result.returncode != 0:
        sys.exit(f"vector_scaling.py: measuring {key} failed (exit {result.returncode}):\n{result.stderr[-3000:]}")
    return json.loads(result.stdout.strip().splitlines()[-1])


def _measure_all(args) -> tuple[dict, list[float]]:
    """Every subject once, each in a child process on a domain of its own; the raw loop again after
    the subjects in RAW_AGAIN_AFTER: (results by subject, the raw loop's rates)."""
    results, raws = {}, []
    for i, key in enumerate(SUBJECTS):
        results[key] = r = measure_in_child(key, args.domain + i, args)
        extra = f", start {r['start_s']:.2f} s, {r['rss_mb']:.0f} MB" if "start_s" in r else ""
        progress(f"  {key}: {r['rate']:,.0f} {'round trips' if key == 'raw' else 'env-steps'}/s{extra}")
        if key == "raw":
            raws.append(r["rate"])
        if key in RAW_AGAIN_AFTER:
            raws.append(measure_in_child("raw", args.domain + len(SUBJECTS) + len(raws), args)["rate"])
            progress(f"  raw again: {raws[-1]:,.0f} round trips/s")
    return results, raws


def _print_table(results: dict, raw: float, raws: list[float]) -> None:
    header = (
        f"{'subject':<48} | {'env-steps/s':>11} | {'/ raw':>6} | {'start-up s':>10} | {'RSS MB':>7} | {'MB/env':>6}"
    )
    print(header)
    print("-" * len(header))
    names = {
        "sync": "SyncVectorEnv, node='shared'",
        "async": "AsyncVectorEnv (fork), node='shared'",
        "ours": "SortingLineVectorEnv (one node)",
    }
    base = results["sync_1"]["rss_mb"]
    for key, r in results.items():
        if key == "raw":
            print(
                f"{'raw one-line rclpy lock-step loop (round trips)':<48} | {raw:>11,.0f} "
                f"| {1:>6.2f} | {'':>10} | {'':>7} | {'':>6}"
                f"  (median of {' / '.join(f'{x:,.0f}' for x in raws)})"
            )
            continue
        kind, n = key.split("_")
        per_env = f"{(r['rss_mb'] - base) / (int(n) - 1):>6.1f}" if kind == "sync" and int(n) > 1 else f"{'':>6}"
        print(
            f"{names[kind] + f', {n} envs':<48} | {r['rate']:>11,.0f} | {r['rate'] / raw:>6.2f} | "
            f"{r['start_s']:>10.2f} | {r['rss_mb']:>7.0f} | {per_env}"
        )


def _print_targets(results: dict, raw: float) -> None:
    base = results["sync_1"]["rss_mb"]
    s64 = results["sync_64"]
    mb = (s64["rss_mb"] - base) / 63
    print("\ntargets (SyncVectorEnv of 64, node='shared')")
    print(
        f"  start-up {s64['start_s']:.1f} s (target < {TARGET_START_S:g} s) "
        f"{'OK' if s64['start_s'] < TARGET_START_S else 'MISSED'}"
    )
    print(
        f"  memory {mb:.1f} MB per env beyond the first (target < {TARGET_MB_PER_ENV:g}) "
        f"{'OK' if mb < TARGET_MB_PER_ENV else 'MISSED'}"
    )
    share = s64["rate"] / raw
    print(
        f"  {s64['rate']:,.0f} env-steps/s = {share:.0%} of the raw loop's round trips/s (target >= "
        f"{TARGET_RAW_SHARE:.0%}) {'OK' if share >= TARGET_RAW_SHARE else 'MISSED'}"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=300, help="timed vector steps per subject (default 300)")
    ap.add_argument("--raw-steps", type=int, default=3000, help="timed round trips of the raw loop (default 3000)")
    ap.add_argument("--domain", type=int, default=150, help="first ROS_DOMAIN_ID; one per subject (default 150)")
    ap.add_argument("--subject", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.steps < 1 or args.raw_steps < 1:
        ap.error("--steps and --raw-steps must be >= 1")
    domains = len(SUBJECTS) + len(RAW_AGAIN_AFTER) + 1
    if not 0 <= args.domain <= 232 - domains:
        ap.error(f"--domain {args.domain} is out of range: allowed 0 ..= {232 - domains}")
    h.run_isolated(__file__, "SORTING_LINE_SCALING_BENCH_IN_NETNS")
    if args.subject:
        os.environ["ROS_DOMAIN_ID"] = str(args.domain)
        h.ros_environment()
        os.environ.setdefault("SORTING_LINE_BIN", str(h.node_binary()))
        print(json.dumps(measure_here(args.subject, args.steps, args.raw_steps)), flush=True)
        return 0
    before = h.machine_conditions()
    results, raws = _measure_all(args)
    after = h.machine_conditions()
    raw = statistics.median(raws)
    results["raw"]["rate"] = raw
    print(
        f"\nsorting_line_gym, many envs on one host ({args.steps} vector steps per subject, 50-step episodes; "
        f"raw loop {args.raw_steps} round trips); {os.cpu_count()} CPUs; {before} before, {after} after"
    )
    _print_table(results, raw, raws)
    _print_targets(results, raw)
    return 0


if __name__ == "__main__":
    sys.exit(main())
