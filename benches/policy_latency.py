#!/usr/bin/env python3
"""Decision latency of the learned controller (`sorting-line-controller --policy POLICY.onnx`, onnxruntime)
against the rule-based one (`--agent rba-hold`), in the same run, and the highest realtime rate at which
the learned controller misses no tick.

1. Latency: two lock-step lines (setup B, advanced), one per controller, both driven at once for N
   ticks (default 10,000: one episode of --max-steps N). Each controller's decision log gives, per
   tick, the time from the reading that completed the tick to the published command
   (``decision_ms``: what the controller itself adds) and from the tick's first reading
   (``latency_ms``). Printed: p50, p99, max of each, and the ratio of the p99s (target: the ONNX
   controller's decision p99 within 1.5x of rba-hold's).
2. Realtime: a realtime node at RATE ticks/s driven by the ONNX controller for N ticks, for RATE =
   25, 50, 100, ... until a rate misses a tick (rba-hold on a line of its own beside it, so that a
   busy machine shows in both). A tick is missed when no command answers it, or
   its command is published after the next tick's first reading arrived (it then applies a tick
   late). The highest rate without a miss is printed.

It refuses to run outside an isolated loopback-only network namespace; as root it re-executes itself
under `unshare -n` with `lo` up. Figures, not assertions: progress on stderr, the table on stdout.

    source launch_scripts/env.sh
    python benches/policy_latency.py                      # N = 10000, the committed PPO policy
    python benches/policy_latency.py -n 2000 --policy policy.onnx --max-rate 3200
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))

from support import ros_harness as h  # noqa: E402

REEXEC_MARK = "SORTING_LINE_BENCH_IN_NETNS"
POLICY = ROOT / "tests" / "data" / "policies" / "ppo_B_advanced_seed42.onnx"
TARGET_P99_RATIO = 1.5


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def percentiles(values: list[float]) -> tuple[float, float, float]:
    v = sorted(values)
    return v[len(v) // 2], v[min(len(v) - 1, int(len(v) * 0.99))], v[-1]


def decisions(path: Path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def run_lines(flags: dict[str, list[str]], node_flags: list[str], ticks: int, workdir: Path) -> dict[str, list[dict]]:
    """One node per controller (namespace = its name), each reset once and driven for ``ticks``
    ticks by its controller; the decision logs."""
    from support.line_client import LineClient

    session = h.RosSession()
    nodes, controllers, clients, logs = [], [], [], {}
    try:
        for name, controller_flags in flags.items():
            ns = f"/bench_{name}_{os.getpid()}"
            nodes.append(
                h.NodeProcess(
                    [*node_flags, "--max-steps", ticks + 1, "--ros-args", "-r", f"__ns:={ns}"], workdir / f"{name}.log"
                )
            )
            clients.append(LineClient(session, ns, "advanced", node_proc=nodes[-1]))
            logs[name] = workdir / f"{name}.jsonl"
            argv = [*controller_flags, "--namespace", ns, "--decision-log", logs[name]]
            controllers.append(h.ScriptProcess("sorting-line-controller", argv, workdir / f"{name}_ctl.log"))
        for client, controller in zip(clients, controllers, strict=True):
            client.wait_connected()
            session.spin_until(lambda c=controller: "connected:" in c.log(), 60.0, "a controller to connect")
        for client in clients:
            client.reset(7, wait_tick=False)
        deadline = time.monotonic() + ticks / 20 + 120
        while any(len(decisions(p)) < ticks for p in logs.values()) and time.monotonic() < deadline:
            session.spin_for(1.0)
        return {name: decisions(path)[:ticks] for name, path in logs.items()}
    finally:
        for p in controllers:
            p.stop()
        for c in clients:
            c.destroy()
        for n in nodes:
            n.stop()
        session.shutdown()


def missed_ticks(rows: list[dict], period_ns: int) -> tuple[int, str]:
    """Ticks without an answer, or answered after the next tick's first reading; and the first."""
    missed, first = 0, ""
    for a, b in zip(rows, rows[1:], strict=False):
        gap = max(0, (b["stamp_ns"] - a["stamp_ns"]) // period_ns - 1)
        late = a["published_monotonic"] > b["first_seen_monotonic"]
        if (gap or late) and not first:
            first = (
                f"after the tick of step {a['step']}: {gap} unanswered"
                if gap
                else f"step {a['step']} answered "
                f"{(a['published_monotonic'] - b['first_seen_monotonic']) * 1e3:.1f} ms after the next tick's reading"
            )
        missed += gap + late
    return missed, first


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("-n", "--ticks", type=int, default=10_000)
    p.add_argument("--policy", type=Path, default=POLICY)
    p.add_argument("--min-rate", type=int, default=25, help="first realtime rate tried (ticks/s), doubled each time")
    p.add_argument("--max-rate", type=int, default=6400, help="highest realtime rate tried (ticks/s)")
    args = p.parse_args()
    h.run_isolated(__file__, REEXEC_MARK)
    h.ros_environment()
    line = ["--setup", "B", "--variant", "advanced", "--seed", "7"]
    before = h.machine_conditions()
    with tempfile.TemporaryDirectory(prefix="policy_latency_") as tmp:
        progress(f"lock-step: {args.ticks} ticks, both controllers at once")
        (Path(tmp) / "lockstep").mkdir()
        rba_hold = ["--setup", "B", "--variant", "advanced", "--agent", "rba-hold"]
        runs = run_lines(
            {"onnx": ["--policy", args.policy], "rba_hold": rba_hold},
            [*line, "--mode", "lockstep"],
            args.ticks,
            Path(tmp) / "lockstep",
        )
        print("| controller | ticks | decision p50 / p99 / max (ms) | first reading -> command p50 / p99 / max (ms) |")
        print("|---|---|---|---|")
        p99 = {}
        for name, rows in runs.items():
            d, f = percentiles([r["decision_ms"] for r in rows]), percentiles([r["latency_ms"] for r in rows])
            p99[name] = d[1]
            show = [" / ".join(f"{x:.3f}" for x in figures) for figures in (d, f)]
            print(f"| {name} | {len(rows)} | {show[0]} | {show[1]} |")
        ratio = p99["onnx"] / p99["rba_hold"]
        print(f"decision p99 ratio onnx / rba-hold: {ratio:.2f} (target <= {TARGET_P99_RATIO})")
        best, rate = None, args.min_rate
        while rate <= args.max_rate:
            progress(f"realtime {rate} ticks/s: {args.ticks} ticks")
            workdir = Path(tmp) / f"rt{rate}"
            workdir.mkdir()
            runs = run_lines(
                {"onnx": ["--policy", args.policy], "rba_hold": rba_hold},
                [*line, "--mode", "realtime", "--rate", rate],
                args.ticks,
                workdir,
            )
            misses = {}
            for name, rows in runs.items():
                missed, first = missed_ticks(rows, 1_000_000_000)  # tick_period: 1 simulated s per tick
                misses[name] = missed + max(0, args.ticks - len(rows))
                print(f"realtime {rate} ticks/s, {name}: {len(rows)} decisions, {misses[name]} missed ticks {first}")
            if misses["onnx"]:
                break
            best, rate = rate, rate * 2
        print(
            f"highest realtime rate without a missed tick over {args.ticks} ticks: {best} ticks/s (tried up to {rate})"
        )
    print(f"{os.cpu_count()} CPUs; machine before: {before}, after: {h.machine_conditions()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
