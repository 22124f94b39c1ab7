#!/usr/bin/env python3
"""Lock-step benchmark of the `sorting_line` ROS 2 node (release binary) from one rclpy client.

Measures, for 1 line and for 16 lines hosted by one node process:
- lock-step round trips per second (median of RUNS runs of N ticks each): one round trip = publish
  the `cmd/speed` of every line stamped with its current tick, then wait until every line's `state`
  of the next tick has arrived; line-ticks/s = round trips/s * lines;
- p50 / p99 round-trip latency (all runs pooled);
- the node's resident memory (VmRSS from /proc/PID/status) after the runs;
- the node's CPU use while idle in lock-step (utime + stime from /proc/PID/stat over IDLE seconds
  with the client connected and nothing happening);
and compares them with the targets (>= 4,000 ticks/s for one line, < 50 MB RSS with 16 lines, idle
CPU near 0). It also compares ways of waiting for the reply with rclpy (--patterns):
- spin-block (default): the one SingleThreadedExecutor, `spin_once()` without a timeout in a loop that
  checks a counter the subscription callbacks advance; a watchdog thread wakes the executor
  (`executor.wake()`) at the deadline, so every wait is bounded without a timer per wait;
- spin-5ms / spin-poll: `spin_once(timeout_sec=0.005)` / `spin_once(timeout_sec=0)` in the same loop;
- waitset: no executor, one persistent rcl wait set and `take_message` (rclpy internals, as used by
  `rclpy.wait_for_message`): what a Python client can reach, reported for comparison.
The client never uses spin_until_future_complete (it leaks a task per call in rclpy 7.1).

It refuses to run outside an isolated loopback-only network namespace (DDS traffic must stay on this
machine); as root it re-executes itself under `unshare -n` with `lo` up.

    source launch_scripts/env.sh
    python benches/node_lockstep.py                 # N = 5000, 3 runs, 1 and 16 lines
    python benches/node_lockstep.py -n 1000 --lines 1 4 16 --pattern spin-block waitset --patterns
Progress goes to stderr, the tables to stdout.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))

from sorting_line_gym.line.topics import RESET, SPEED_CMD, STATE  # noqa: E402
from support import ros_harness as h  # noqa: E402

REEXEC_MARK = "SORTING_LINE_BENCH_IN_NETNS"
PATTERNS = ["spin-block", "spin-5ms", "spin-poll", "waitset"]
#: The waiting patterns --patterns compares on one line: (pattern, lean entities).
LEAN_PATTERNS = [
    ("spin-block", True),
    ("spin-5ms", True),
    ("spin-poll", True),
    ("spin-block", False),
    ("waitset", True),
]
TARGET_TICKS_1 = 4000.0
TARGET_RSS_16_MB = 50.0
TARGET_IDLE_CPU = 1.0  # percent: "near 0"


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------------
# /proc


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process (all its threads), in seconds."""
    stat = Path(f"/proc/{pid}/stat").read_text()
    fields = stat[stat.rindex(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def idle_cpu_percent(pid: int, seconds: float) -> float:
    c0, t0 = cpu_seconds(pid), time.monotonic()
    time.sleep(seconds)
    c1, t1 = cpu_seconds(pid), time.monotonic()
    return 100.0 * (c1 - c0) / (t1 - t0)


def percentile(sorted_values: list[float], q: float) -> float:
    if not sorted_values:
        return float("nan")
    i = min(len(sorted_values) - 1, max(0, round(q / 100 * (len(sorted_values) - 1))))
    return sorted_values[i]


# ------------------------------------------------------------------------------------------
# The client


class Watchdog(threading.Thread):
    """One long-lived thread: wakes the executor when `deadline` (monotonic) has passed."""

    def __init__(self, executor):
        super().__init__(daemon=True)
        self.executor, self.deadline, self.fired = executor, math.inf, False
        self._halt = threading.Event()
        self.start()

    def run(self) -> None:
        while not self._halt.wait(0.05):
            if time.monotonic() > self.deadline:
                self.fired = True
                self.executor.wake()

    def stop(self) -> None:
        self._halt.set()
        self.join()


class LockstepClient:
    """One rclpy node with a `cmd/speed` publisher and a `state` subscription per line.

    The subscription callbacks only count the lines whose awaited state has arrived; the waiting
    loop spins the single executor until the count is complete."""

    def __init__(self, session: h.RosSession, namespaces: list[str], pattern: str, lean: bool = True):
        import rclpy.node
        from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
        from sorting_line_interfaces.msg import LineState, SpeedCommand
        from sorting_line_interfaces.srv import ResetLine

        self.session, self.executor, self.pattern = session, session.executor, pattern
        # No parameter services, no rosout: fewer entities in every wait set.
        self.node = rclpy.node.Node(
            f"bench_client_{os.getpid()}", context=session.context, start_parameter_services=False, enable_rosout=False
        )
        self.executor.add_node(self.node)
        self.n = len(namespaces)
        self.namespaces = namespaces
        self.expected_sec = [0] * self.n
        self.arrived = 0
        # lean: no QoS event handlers (rclpy's default ones are waitables that every wait set
        # rebuild enters), and the reset clients are destroyed once used.
        self.lean = lean
        pub_events = PublisherEventCallbacks(use_default_callbacks=False) if lean else None
        sub_events = SubscriptionEventCallbacks(use_default_callbacks=False) if lean else None
        self.pubs = [
            self.node.create_publisher(SpeedCommand, h.join_ns(ns, SPEED_CMD), 10, event_callbacks=pub_events)
            for ns in namespaces
        ]
        self.subs = [
            self.node.create_subscription(
                LineState, h.join_ns(ns, STATE), self._callback(k), 10, event_callbacks=sub_events
            )
            for k, ns in enumerate(namespaces)
        ]
        self.resets = [self.node.create_client(ResetLine, h.join_ns(ns, RESET)) for ns in namespaces]
        self.cmds = [SpeedCommand(speed=0.5) for _ in namespaces]
        self._ResetLine = ResetLine
        self.watchdog = Watchdog(self.executor)
        self._waitset = None
        self._callbacks = [self._callback(k) for k in range(self.n)]

    def _callback(self, k: int):
        def on_state(msg) -> None:
            if msg.header.stamp.sec == self.expected_sec[k] and msg.header.stamp.nanosec == 0:
                self.arrived += 1

        return on_state

    def destroy(self) -> None:
        self.watchdog.stop()
        self.executor.remove_node(self.node)
        self.node.destroy_node()

    def connect_and_reset(self, timeout: float = 15.0) -> None:
        """Matches, resets every line (seed 100 + k) and takes the tick each line waits at."""

        def matched():
            return all(p.get_subscription_count() >= 1 for p in self.pubs) and all(
                s.get_publisher_count() >= 1 for s in self.subs
            )

        self.session.spin_until(matched, timeout, "the client's publishers and subscriptions to match the node")
        for k, client in enumerate(self.resets):
            reply = self.session.call_service(
                client, self._ResetLine.Request(has_seed=True, seed=100 + k), f"{self.namespaces[k]}/{RESET}"
            )
            assert reply.success and reply.stamp.nanosec == 0, reply
            self.expected_sec[k] = reply.stamp.sec  # the tick the line waits at
        if self.lean:
            for client in self.resets:
                self.node.destroy_client(client)
            self.resets = []

    def round_trip(self, timeout: float = 5.0) -> None:
        """Answers every line's current tick and waits for every line's next state."""
        self.arrived = 0
        for k in range(self.n):
            cmd = self.cmds[k]
            cmd.header.stamp.sec = self.expected_sec[k]
            self.expected_sec[k] += 1
            self.pubs[k].publish(cmd)
        self.wait_all(timeout)

    def wait_all(self, timeout: float) -> None:
        spin_once, n = self.executor.spin_once, self.n
        deadline = time.monotonic() + timeout
        if self.pattern == "spin-5ms":
            while self.arrived < n:
                spin_once(timeout_sec=0.005)
                if time.monotonic() > deadline:
                    self._timeout(timeout)
        elif self.pattern == "spin-poll":
            while self.arrived < n:
                spin_once(timeout_sec=0.0)
                if time.monotonic() > deadline:
                    self._timeout(timeout)
        elif self.pattern == "spin-block":
            # Blocks in the wait set without a timeout (so no timeout timer is created per wait); the
            # watchdog thread wakes the executor (its guard condition) should a state never come.
            self.watchdog.deadline = deadline
            try:
                while self.arrived < n:
                    spin_once()
                    if self.watchdog.fired:
                        self._timeout(timeout)
            finally:
                self.watchdog.deadline = math.inf
        elif self.pattern == "waitset":
            self._wait_waitset(deadline, timeout)
        else:
            raise ValueError(self.pattern)

    def _wait_waitset(self, deadline: float, timeout: float) -> None:
        """No executor: one persistent rcl wait set over the state subscriptions, and take_message
        on the ready ones (the calls rclpy.wait_for_message makes, but with a wait set kept for the
        whole run). Uses rclpy's implementation module, which is not a public API."""
        if self._waitset is None:
            from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

            self._waitset = _rclpy.WaitSet(self.n, 0, 0, 0, 0, 0, self.session.context.handle)
            self._handles = [sub.handle for sub in self.subs]
            self._pointers = {sub.handle.pointer: k for k, sub in enumerate(self.subs)}
        ws, callbacks = self._waitset, self._callbacks
        while self.arrived < self.n:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                self._timeout(timeout)
            ws.clear_entities()
            for handle in self._handles:
                ws.add_subscription(handle)
            ws.wait(int(remaining * 1e9))
            for pointer in ws.get_ready_entities("subscription"):
                k = self._pointers[pointer]
                sub = self.subs[k]
                while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                    callbacks[k](taken[0])

    def _timeout(self, timeout: float):
        waiting = [self.namespaces[k] for k in range(self.n)]
        raise TimeoutError(
            f"{self.arrived}/{self.n} states within {timeout} s (lines {waiting[:4]}..., "
            f"awaited stamps {self.expected_sec[:4]}...)"
        )


# ------------------------------------------------------------------------------------------
# One configuration


def node_args(lines: int, ns: str) -> list[str]:
    """`sorting_line node` flags of the benchmarks' lock-step node: basic lines, episodes that do not end."""
    flags = f"--variant basic --lines {lines} --max-steps 1000000 --seed 100"
    return [*flags.split(), "--ros-args", "-r", f"__ns:={ns}"]


def start_node(lines: int, ns: str, log_dir: Path) -> h.NodeProcess:
    return h.NodeProcess(node_args(lines, ns), log_dir / f"node_{ns.strip('/')}.log")


def stop_node(node: h.NodeProcess) -> None:
    code = node.stop(signal.SIGINT, timeout=5.0)
    if code != 0:
        progress(f"WARNING: the node exited with {code} after SIGINT\n{node.describe()}")


def line_namespaces(ns: str, lines: int) -> list[str]:
    return [ns] if lines == 1 else [f"{ns}/line_{k}" for k in range(lines)]


def measure(
    session: h.RosSession,
    lines: int,
    ticks: int,
    runs: int,
    pattern: str,
    idle_s: float,
    log_dir: Path,
    tag: str,
    lean: bool = True,
) -> dict:
    ns = f"/bench_{tag}_{os.getpid()}"
    node = start_node(lines, ns, log_dir)
    client = LockstepClient(session, line_namespaces(ns, lines), pattern, lean)
    try:
        client.connect_and_reset()
        rss_start = h.proc_status_mb(node.pid, "VmRSS")
        warmup = min(500, max(50, ticks // 10))
        for _ in range(warmup):
            client.round_trip()
        rates, latencies = [], []
        cpu_before = cpu_times()
        for run in range(runs):
            lat = []
            start = time.perf_counter()
            for i in range(ticks):
                t0 = time.perf_counter()
                client.round_trip()
                lat.append(time.perf_counter() - t0)
                if i and i % 1000 == 0:
                    progress(f"  {tag}: run {run + 1}/{runs}: {i}/{ticks} round trips")
            elapsed = time.perf_counter() - start
            rates.append(ticks / elapsed)
            latencies += lat
            progress(f"  {tag}: run {run + 1}/{runs}: {ticks / elapsed:,.0f} round trips/s")
        latencies.sort()
        steal = steal_percent(cpu_before, cpu_times())
        rss = h.proc_status_mb(node.pid, "VmRSS")
        hwm = h.proc_status_mb(node.pid, "VmHWM")
        idle = None
        if idle_s > 0:
            progress(f"  {tag}: idle CPU over {idle_s:.0f} s ...")
            idle = idle_cpu_percent(node.pid, idle_s)
        return {
            "lines": lines,
            "pattern": pattern + ("" if lean else " (default entities)"),
            "runs": rates,
            "rt_s": statistics.median(rates),
            "line_ticks_s": statistics.median(rates) * lines,
            "p50_ms": percentile(latencies, 50) * 1e3,
            "p99_ms": percentile(latencies, 99) * 1e3,
            "rss_mb": rss,
            "hwm_mb": hwm,
            "rss_start_mb": rss_start,
            "steal": steal,
            "idle_cpu": idle,
        }
    finally:
        client.destroy()
        stop_node(node)


# ------------------------------------------------------------------------------------------


def cpu_times() -> list[int]:
    """The machine's `cpu` line of /proc/stat: user nice system idle iowait irq softirq steal ..."""
    return [int(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]


def steal_percent(before: list[int], after: list[int]) -> float:
    """Share of CPU time the hypervisor took from this VM between two cpu_times() samples."""
    delta = [a - b for a, b in zip(after, before, strict=False)]
    total = sum(delta[:8])
    return 100.0 * delta[7] / total if total else 0.0


def loadavg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", "--ticks", type=int, default=5000, help="round trips per run (default 5000)")
    parser.add_argument("--runs", type=int, default=3, help="runs per configuration; the median is reported")
    parser.add_argument("--lines", type=int, nargs="+", default=[1, 16], help="line counts (default 1 16)")
    parser.add_argument(
        "--pattern",
        nargs="+",
        default=["spin-block"],
        choices=PATTERNS,
        help="how the client waits for the states; several give a row each (default spin-block)",
    )
    parser.add_argument(
        "--patterns",
        action="store_true",
        help="also compare every waiting pattern on one line (N/2 round trips per run)",
    )
    parser.add_argument("--idle", type=float, default=5.0, help="seconds of idle-CPU sampling (0: skip)")
    return parser


def _measure_all(args) -> tuple[list[dict], list[dict]]:
    """(a result per --pattern and --lines, a result per waiting pattern with --patterns)."""
    session = h.RosSession()
    results, pattern_results = [], []
    with tempfile.TemporaryDirectory(prefix="sl_bench_") as tmp:
        log_dir = Path(tmp)
        try:
            if args.patterns:
                n = max(1, args.ticks // 2)
                for pattern, lean in LEAN_PATTERNS:
                    entities = "" if lean else " (default entities)"
                    progress(f"pattern {pattern}{entities}: 1 line, {args.runs} x {n} round trips")
                    name = f"p_{pattern.replace('-', '_')}_{int(lean)}"
                    pattern_results.append(measure(session, 1, n, args.runs, pattern, 0, log_dir, name, lean))
            for pattern in args.pattern:
                for lines in args.lines:
                    progress(f"{lines} line(s): {args.runs} x {args.ticks} round trips, pattern {pattern}")
                    name = f"l{lines}_{pattern.replace('-', '_')}"
                    results.append(measure(session, lines, args.ticks, args.runs, pattern, args.idle, log_dir, name))
        finally:
            session.shutdown()
    return results, pattern_results


def _print_table(results: list[dict]) -> None:
    header = (
        f"{'pattern':<10} | {'lines':>5} | {'round trips/s':>13} | {'line-ticks/s':>12} | {'runs (rt/s)':>23} | "
        f"{'p50 ms':>6} | {'p99 ms':>6} | {'RSS MB start/end':>16} | {'idle CPU %':>10} | {'steal %':>7}"
    )
    print(header)
    print("-" * len(header))
    for r in results:
        runs = "/".join(f"{x:,.0f}" for x in r["runs"])
        idle = f"{r['idle_cpu']:.2f}" if r["idle_cpu"] is not None else "-"
        print(
            f"{r['pattern']:<10} | {r['lines']:>5} | {r['rt_s']:>13,.0f} | {r['line_ticks_s']:>12,.0f} | "
            f"{runs:>23} | {r['p50_ms']:>6.3f} | {r['p99_ms']:>6.3f} | "
            f"{r['rss_start_mb']:>7.1f} / {r['rss_mb']:>6.1f} | {idle:>10} | {r['steal']:>7.0f}"
        )


def _print_targets(results: list[dict], idle_s: float) -> None:
    print("\ntargets")
    for r in results:
        tag = f"{r['pattern']}, {r['lines']} line(s)"
        if r["lines"] == 1:
            ok = r["line_ticks_s"] >= TARGET_TICKS_1
            print(
                f"  {tag}: {r['line_ticks_s']:,.0f} ticks/s vs >= {TARGET_TICKS_1:,.0f} -> "
                f"{r['line_ticks_s'] / TARGET_TICKS_1:.2f}x of the target {'OK' if ok else 'MISSED'}"
            )
        if r["lines"] == 16:
            ok = r["rss_mb"] < TARGET_RSS_16_MB
            print(
                f"  {tag}: RSS {r['rss_mb']:.1f} MB (peak {r['hwm_mb']:.1f}) vs < {TARGET_RSS_16_MB:.0f} MB -> "
                f"{r['rss_mb'] / TARGET_RSS_16_MB:.2f} of the budget {'OK' if ok else 'MISSED'}"
            )
        if r["idle_cpu"] is not None:
            ok = r["idle_cpu"] < TARGET_IDLE_CPU
            print(
                f"  {tag}: idle CPU {r['idle_cpu']:.2f} % over {idle_s:.0f} s (near 0: < {TARGET_IDLE_CPU:.0f} %) "
                f"{'OK' if ok else 'MISSED'}"
            )
    print(
        "  (steal % = CPU time the hypervisor took from this VM during the timed runs; the numbers are only\n"
        "   comparable at low steal.)"
    )
    print(
        "  (RSS start = after connecting, end = after the runs. Under load the node's RSS follows the message\n"
        "   rate (it plateaus; likely RustDDS's cache clean-up period of 4 s): a faster client, a higher plateau.)"
    )


def _print_patterns(pattern_results: list[dict], args) -> None:
    print(f"\nwaiting patterns, 1 line, {max(1, args.ticks // 2)} round trips per run, median of {args.runs} runs")
    for r in pattern_results:
        print(
            f"  {r['pattern']:<31} {r['rt_s']:>7,.0f} round trips/s  p50 {r['p50_ms']:.3f} ms  "
            f"p99 {r['p99_ms']:.3f} ms  (steal {r['steal']:.0f} %)"
        )
    print(
        "  spin-block: executor.spin_once() without timeout + a watchdog thread that calls executor.wake();\n"
        "  spin-5ms:   executor.spin_once(timeout_sec=0.005) in a loop checking a flag;\n"
        "  spin-poll:  executor.spin_once(timeout_sec=0) busy loop (burns a core);\n"
        "  lean (all but 'default entities'): no QoS event handlers, reset clients destroyed after use;\n"
        "  (default entities): rclpy's default event handlers and the reset clients stay in the wait set;\n"
        "  waitset: no executor; one persistent rcl wait set + take_message (rclpy internals, as in\n"
        "           rclpy.wait_for_message): the ceiling for a Python client, not a public-API pattern."
    )


def main() -> int:
    args = _parser().parse_args()
    h.run_isolated(__file__, REEXEC_MARK)
    env = h.ros_environment(default_domain="88")
    h.node_binary()
    progress(f"node {h.node_binary()}; " + ", ".join(f"{k}={v}" for k, v in env.items()))
    load_before, cpu_before = loadavg(), cpu_times()
    results, pattern_results = _measure_all(args)
    print(
        f"\nsorting_line node ({h.node_binary()}), lock-step, basic lines, one rclpy client; "
        f"N = {args.ticks} round trips per run, median of {args.runs} runs; {os.cpu_count()} CPUs; "
        f"load average {load_before} before, {loadavg()} after; CPU steal (hypervisor) during the run "
        f"{steal_percent(cpu_before, cpu_times()):.0f} %"
    )
    _print_table(results)
    _print_targets(results, args.idle)
    if pattern_results:
        _print_patterns(pattern_results, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
