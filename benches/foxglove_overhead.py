#!/usr/bin/env python3
"""What the Foxglove live view costs the node (docs/foxglove.md): lock-step round trips of one
rclpy client (benches/node_lockstep.py's client) against a node without the live view, with it
and no viewer, and with it and one viewer subscribed to every channel (tests/foxglove/live.mjs in
its `count` mode: Foxglove's own client decoding every message, on the same two cores). Reports
per configuration the round trips per second, the p50/p99 round-trip latency and the node's CPU
time per round trip (utime + stime of the node's process, all its threads: the live view's
forwarding and server threads included).

Like node_lockstep.py it refuses to run outside an isolated loopback-only network namespace, and
as root re-executes itself under `unshare -n` with `lo` up.

    source launch_scripts/env.sh
    python benches/foxglove_overhead.py            # 1 line, N = 2000, 3 runs
    python benches/foxglove_overhead.py --lines 16 -n 1000
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
sys.path.insert(0, str(ROOT / "benches"))

import node_lockstep as bench  # noqa: E402
from support import ros_harness as h  # noqa: E402
from support.foxglove_viewer import Viewer, live_view_url  # noqa: E402

CONFIGS = ["off", "on, no viewer", "on, one viewer"]


def measure(session: h.RosSession, config: str, lines: int, ticks: int, runs: int, log_dir: Path) -> dict:
    ns = f"/fox_bench_{CONFIGS.index(config)}_{os.getpid()}"
    args = bench.node_args(lines, ns)
    if config != "off":
        args = ["--foxglove", "0", *args]
    node = h.NodeProcess(args, log_dir / f"node_{ns.strip('/')}.log")
    viewer = None
    client = bench.LockstepClient(session, bench.line_namespaces(ns, lines), "spin-block", True)
    try:
        if config == "on, one viewer":
            viewer = Viewer("count", live_view_url(node), log_dir / f"viewer_{ns.strip('/')}.log")
            viewer.wait_for(lambda: viewer.of("subscribed"), 10.0, "a subscription")
        client.connect_and_reset()
        for _ in range(min(500, max(50, ticks // 10))):
            client.round_trip()
        rates, latencies, cpu = [], [], []
        for run in range(runs):
            c0, start = bench.cpu_seconds(node.pid), time.perf_counter()
            for _ in range(ticks):
                t0 = time.perf_counter()
                client.round_trip()
                latencies.append(time.perf_counter() - t0)
            elapsed = time.perf_counter() - start
            cpu.append((bench.cpu_seconds(node.pid) - c0) / ticks)
            rates.append(ticks / elapsed)
            bench.progress(f"  {config}: run {run + 1}/{runs}: {ticks / elapsed:,.0f} round trips/s")
        latencies.sort()
        return {
            "config": config,
            "rt_s": statistics.median(rates),
            "p50_ms": bench.percentile(latencies, 50) * 1e3,
            "p99_ms": bench.percentile(latencies, 99) * 1e3,
            "cpu_us": statistics.median(cpu) * 1e6,
        }
    finally:
        client.destroy()
        if viewer is not None:
            viewer.close(timeout=30.0)
        bench.stop_node(node)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", "--ticks", type=int, default=2000, help="round trips per run (default 2000)")
    parser.add_argument("--runs", type=int, default=3, help="runs per configuration; the median is reported")
    parser.add_argument("--lines", type=int, default=1, help="lines of the node (default 1)")
    args = parser.parse_args()
    h.run_isolated(__file__, bench.REEXEC_MARK)
    session = h.RosSession()
    results = []
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="sl_fox_bench_") as tmp:
        try:
            for config in CONFIGS:
                results.append(measure(session, config, args.lines, args.ticks, args.runs, Path(tmp)))
        finally:
            session.shutdown()
    print(f"\n{args.lines} line(s), N = {args.ticks} round trips per run, median of {args.runs} runs; "
          f"load average {load:.1f} before, {os.getloadavg()[0]:.1f} after; {os.cpu_count()} CPUs")  # fmt: skip
    print("| live view | round trips/s | p50 ms | p99 ms | node CPU per round trip (us) |")
    print("|---|---|---|---|---|")
    for r in results:
        print(f"| {r['config']} | {r['rt_s']:,.0f} | {r['p50_ms']:.2f} | {r['p99_ms']:.2f} | {r['cpu_us']:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
