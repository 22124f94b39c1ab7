#!/usr/bin/env python3
"""Throughput of the Gymnasium bridge (bridge/sorting_line_gym) against the real node, in env-steps/s.

Subjects, timed in interleaved rounds (round r times every subject once), so a change of machine
speed during the benchmark (this VM's swings about 3x with host load) hits every subject alike;
each timed run is a process of its own with a node of its own, started, warmed up, timed and
stopped before the next one starts (idle envs and nodes left alive beside a subject slow it
down, a one-line env by up to 40 %); medians over the rounds:
  (a) the raw lock-step ceiling: a minimal rclpy loop on one line's own topics (publish
      `cmd/speed` stamped with the tick, wait for that line's next `state`), the measurement the
      node's lock-step benchmark (benches/node_lockstep.py) makes;
  (b) the single-line env, `SortingLineEnv`:
        - constructed directly with max_episode_steps=1_000_000 (no episode ends, no resets), and
        - `gymnasium.make("sorting_line_gym:SortingLine-v0")` with its 50-step TimeLimit episodes,
          the resets counted in the time (env-steps/s = steps / time including reset());
  (c) `SortingLineVectorEnv` over 1, 4 and 16 lines of one node (batch topics): with 50-step
      episodes (SAME_STEP autoresets included) and without episode ends (max_episode_steps=1e6);
      env-steps/s = round trips/s x lines.
Then the bridge's speed targets: one line >= 3,000 env-steps/s, and the vectorised env at 16
lines >= 10x the single-line env's env-steps/s, as the median of the per-round ratios (16-line
VectorEnv against SortingLineEnv in the same round, like for like: without episode ends, and with
50-step episodes); the ratios to the 1-line VectorEnv and to the raw ceiling are printed as well.
`--plot FILE.png` also draws the medians as a bar chart (and FILE.svg).

DDS traffic stays on this machine: the script refuses to run outside a loopback-only network
namespace and, as root, re-executes itself under `unshare -n` with `lo` up. It sets what
launch_scripts/env.sh sets and a ROS_DOMAIN_ID of its own (--domain, default 89).

    .venv/bin/python benches/bridge_throughput.py                 # 5 rounds, N = 4000 single, 2000 vector
    .venv/bin/python benches/bridge_throughput.py --rounds 3 --single 2000 --vector 500 \
        --plot docs/results/bridge-throughput/bridge_throughput.png
Progress goes to stderr, the table to stdout; load average and CPU steal are printed with it.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
sys.path.insert(0, str(ROOT / "benches"))
from sorting_line_gym.line.topics import RESET, SPEED_CMD, STATE  # noqa: E402
from support import ros_harness as h  # noqa: E402

TARGET_ONE_LINE = 3000.0
TARGET_SCALING = 10.0
WARMUP = 200


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def node_binary() -> Path:
    return h.node_binary()


# ------------------------------------------------------------------------------------------
# (a) the raw lock-step loop


class RawLine:
    """One line of a node of its own, driven by the smallest rclpy lock-step loop."""

    def __init__(self, log_dir: Path):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sorting_line_interfaces.msg import LineState, SpeedCommand
        from sorting_line_interfaces.srv import ResetLine

        # The node benchmark's node flags and watchdog (imported here, after any re-exec into the venv
        # and netns: node_lockstep imports rclpy).
        from node_lockstep import Watchdog, node_args

        self.ns = f"/bench_raw_{os.getpid()}"
        self.log = open(log_dir / "raw_node.log", "wb")
        self.proc = subprocess.Popen(
            [str(node_binary()), "node", *node_args(1, self.ns)],
            stdin=subprocess.DEVNULL,
            stdout=self.log,
            stderr=subprocess.STDOUT,
        )
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(
            f"bench_raw_client_{os.getpid()}", context=self.context, start_parameter_services=False, enable_rosout=False
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(
            depth=10,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
            history=HistoryPolicy.KEEP_LAST,
        )
        self.pub = self.node.create_publisher(SpeedCommand, f"{self.ns}/{SPEED_CMD}", qos)
        self.sub = self.node.create_subscription(LineState, f"{self.ns}/{STATE}", self._on_state, qos)
        self.reset_client = self.node.create_client(ResetLine, f"{self.ns}/{RESET}")
        self.cmd = SpeedCommand(speed=0.5)
        self.stamp = None  # (sec, nanosec) of the tick we answer
        self.arrived = False
        self._ResetLine = ResetLine
        self.watchdog = Watchdog(self.executor)

    def _on_state(self, msg) -> None:
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if self.stamp is not None and key > self.stamp:
            self.stamp = key
            self.arrived = True

    def _spin_until(self, done, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            if self.proc.poll() is not None:
                raise RuntimeError(f"the node exited with {self.proc.returncode} while waiting for {what}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"timed out after {timeout} s waiting for {what}")
            self.executor.spin_once(timeout_sec=0.05)

    def connect(self) -> None:
        self._spin_until(
            lambda: (
                self.pub.get_subscription_count() > 0
                and self.sub.get_publisher_count() > 0
                and self.reset_client.service_is_ready()
            ),
            20.0,
            f"the node serving {self.ns}",
        )
        for attempt in range(3):
            future = self.reset_client.call_async(self._ResetLine.Request(has_seed=True, seed=100))
            try:
                self._spin_until(future.done, 3.0, f"{self.ns}/{RESET}")
                break
            except TimeoutError:
                self.reset_client.remove_pending_request(future)
                if attempt == 2:
                    raise
        reply = future.result()
        assert reply.success, reply.message
        self.stamp = (reply.stamp.sec, reply.stamp.nanosec)

    def round_trip(self, timeout: float = 5.0) -> None:
        self.arrived = False
        self.cmd.header.stamp.sec, self.cmd.header.stamp.nanosec = self.stamp
        self.pub.publish(self.cmd)
        self.watchdog.deadline = time.monotonic() + timeout
        try:
            while not self.arrived:
                self.executor.spin_once()
                if self.watchdog.fired:
                    raise TimeoutError(f"{self.ns}: no state within {timeout} s of the command for {self.stamp}")
        finally:
            self.watchdog.deadline = math.inf

    def close(self) -> None:
        self.watchdog.stop()
        self.executor.remove_node(self.node)
        self.node.destroy_node()
        self.executor.shutdown(timeout_sec=0.5)
        self.rclpy.shutdown(context=self.context)
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.log.close()


# ------------------------------------------------------------------------------------------
# Subjects: something that makes one call (a step, or a round trip of N lines) at a time


@dataclass
class Subject:
    """What one timed run drives: ``one(i)`` makes call i (a step, or a round trip of
    ``per_call`` lines); ``close`` stops it and its node."""

    label: str
    n: int
    per_call: int
    one: Callable[[int], object]
    close: Callable[[], None]

    def warm_up(self) -> None:
        for i in range(WARMUP):
            self.one(i)

    def timed_run(self) -> float:
        """env-steps/s of n calls."""
        start = time.perf_counter()
        for i in range(self.n):
            self.one(i)
        return self.n * self.per_call / (time.perf_counter() - start)


@dataclass
class Row:
    """One subject's figures over the rounds."""

    key: str
    label: str = ""
    per_call: int = 1
    rates: list[float] = field(default_factory=list)

    @property
    def median(self) -> float:
        return statistics.median(self.rates)


def raw_subject(n: int, log_dir: Path) -> Subject:
    line = RawLine(log_dir)
    try:
        line.connect()
    except BaseException:
        line.close()
        raise
    return Subject(
        "(a) raw rclpy lock-step loop, 1 line (per-line topics)", n, 1, lambda i: line.round_trip(), line.close
    )


def direct_subject(n: int) -> Subject:
    from sorting_line_gym import SortingLineEnv

    env = SortingLineEnv(setup="A", variant="basic", max_episode_steps=1_000_000, node="spawn")
    env.reset(seed=1)

    def one(i):
        _, _, terminated, truncated, _ = env.step(i % 10)
        if terminated or truncated:
            raise RuntimeError("an episode ended during the no-reset measurement")

    return Subject("(b) SortingLineEnv(max_episode_steps=1e6), no resets", n, 1, one, env.close)


def make_subject(n: int) -> Subject:
    import gymnasium

    env = gymnasium.make("sorting_line_gym:SortingLine-v0", setup="A", node="spawn")
    env.reset(seed=1)

    def one(i):
        _, _, terminated, truncated, _ = env.step(i % 10)
        if terminated or truncated:
            env.reset()

    return Subject("(b) gymnasium.make(SortingLine-v0), 50-step episodes", n, 1, one, env.close)


def vector_subject(lines: int, n: int, max_episode_steps: int) -> Subject:
    import numpy as np

    from sorting_line_gym import SortingLineVectorEnv

    env = SortingLineVectorEnv(num_envs=lines, setup="A", variant="basic", max_episode_steps=max_episode_steps)
    env.reset(seed=1)
    actions = [np.full(lines, k % 10, dtype=np.int64) for k in range(10)]
    label = f"(c) SortingLineVectorEnv({lines:>2} lines), " + (
        "50-step episodes" if max_episode_steps == 50 else "no episode ends"
    )
    return Subject(label, n, lines, lambda i: env.step(actions[i % 10]), env.close)


# ------------------------------------------------------------------------------------------
# Report


def paired_ratio(numerator: Row, denominator: Row) -> tuple[float, list[float]]:
    """Median of the per-round ratios, and the ratios."""
    ratios = [a / b for a, b in zip(numerator.rates, denominator.rates, strict=False)]
    return statistics.median(ratios), ratios


def plot(rows: list[Row], by_key: dict[str, Row], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import StrMethodFormatter

    fig, ax = plt.subplots(figsize=(9, 4.8), layout="constrained")
    labels = [
        r.label.split(") ", 1)[1].replace("(max_episode_steps=1e6)", "").replace("SortingLineVectorEnv", "VectorEnv")
        for r in rows
    ]
    colors = ["0.6" if r.key == "raw" else ("tab:blue" if r.key in ("direct", "make") else "tab:orange") for r in rows]
    y = list(range(len(rows)))
    ax.barh(y, [r.median for r in rows], color=colors)
    for yi, r in zip(y, rows, strict=False):
        ax.plot(r.rates, [yi] * len(r.rates), "k|", markersize=9)
        ax.text(max(r.rates), yi, f"   {r.median:,.0f}", va="center", fontsize=8)
    ax.set_yticks(y, labels, fontsize=8)
    ax.invert_yaxis()
    ax.xaxis.set_major_formatter(StrMethodFormatter("{x:,.0f}"))
    bottom = len(rows) - 0.45
    scaled = TARGET_SCALING * by_key["direct"].median
    ax.axvline(scaled, color="tab:red", linestyle="--", linewidth=1)
    ax.text(scaled, bottom, " 10x SortingLineEnv", color="tab:red", fontsize=8, va="bottom")
    ax.axvline(TARGET_ONE_LINE, color="tab:green", linestyle=":", linewidth=1)
    ax.text(TARGET_ONE_LINE, bottom, " 3,000", color="tab:green", fontsize=8, va="bottom")
    ax.set_xlim(0, max(max(r.rates) for r in rows) * 1.15)
    ax.set_xlabel("env-steps/s (bar: median; ticks: the rounds)")
    ax.set_title(title, fontsize=9)
    fig.savefig(path, dpi=120)
    fig.savefig(path.with_suffix(".svg"))
    plt.close(fig)


def build(key: str, single: int, vector: int, log_dir: Path) -> Subject:
    if key == "raw":
        return raw_subject(single, log_dir)
    if key == "direct":
        return direct_subject(single)
    if key == "make":
        return make_subject(single)
    tag, lines = key.split("_")
    return vector_subject(int(lines), vector, 50 if tag == "ep50" else 1_000_000)


def measure_here(key: str, single: int, vector: int) -> None:
    """The child's part (--subject): one subject started, warmed up, timed once and stopped; prints
    ``label<TAB>per_call<TAB>env-steps/s``."""
    with tempfile.TemporaryDirectory(prefix="sl_bridge_bench_") as tmp:
        subject = build(key, single, vector, Path(tmp))
        try:
            subject.warm_up()
            rate = subject.timed_run()
        finally:
            subject.close()
    print(f"{subject.label}\t{subject.per_call}\t{rate!r}", flush=True)


def measure_in_child(key: str, args) -> tuple[str, int, float]:
    command = [
        sys.executable,
        os.path.abspath(__file__),
        "--subject",
        key,
        "--single",
        str(args.single),
        "--vector",
        str(args.vector),
        "--domain",
        str(args.domain),
    ]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600)
    if result.returncode != 0:
        sys.exit(f"bridge_throughput.py: measuring {key} failed (exit {result.returncode}):\n{result.stderr[-3000:]}")
    label, per_call, rate = result.stdout.strip().splitlines()[-1].split("\t")
    return label, int(per_call), float(rate)


def _args():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--single", type=int, default=4000, help="steps per timed run for (a) and (b) (default 4000)")
    parser.add_argument("--vector", type=int, default=2000, help="round trips per timed run for (c) (default 2000)")
    parser.add_argument(
        "--rounds", "--runs", type=int, default=5, help="interleaved rounds; medians reported (default 5)"
    )
    parser.add_argument("--lines", type=int, nargs="+", default=[1, 4, 16], help="vector line counts (default 1 4 16)")
    parser.add_argument("--domain", type=int, default=89, help="ROS_DOMAIN_ID of the benchmark (default 89)")
    parser.add_argument("--plot", type=Path, help="also draw the medians to this PNG (and the same name .svg)")
    parser.add_argument("--subject", help=argparse.SUPPRESS)  # internal: measure one subject once, in this process
    args = parser.parse_args()
    for name in ("single", "vector", "rounds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} {getattr(args, name)} is out of range: allowed >= 1")
    if any(not 1 <= k <= 64 for k in args.lines):
        parser.error(f"--lines {args.lines}: each must be in 1 ..= 64")
    if not 0 <= args.domain <= 232:
        parser.error(f"--domain {args.domain} is out of range: allowed 0 ..= 232")
    return args


def _rounds(args) -> list[Row]:
    """The interleaved rounds: every subject timed once per round, in a child process."""
    keys = ["raw", "direct", "make"] + [f"{tag}_{lines}" for tag in ("ep50", "noend") for lines in args.lines]
    rows = {key: Row(key) for key in keys}
    for r in range(args.rounds):
        progress(f"round {r + 1}/{args.rounds} ({h.machine_conditions()})")
        for key in keys:
            row = rows[key]
            row.label, row.per_call, rate = measure_in_child(key, args)
            row.rates.append(rate)
            progress(f"  {row.label}: {rate:,.0f} env-steps/s")
    return list(rows.values())


def _report(ordered: list[Row], args, before: str, after: str) -> None:
    by_key = {s.key: s for s in ordered}
    print(
        f"\nsorting_line_gym throughput, env-steps/s (median of {args.rounds} interleaved rounds; N = {args.single} "
        f"steps single, {args.vector} round trips vector); {os.cpu_count()} CPUs; {before} before, {after} after"
    )
    width = max(len(s.label) for s in ordered)
    header = f"{'measurement':<{width}} | {'env-steps/s':>11} | {'round trips/s':>13} | rounds (env-steps/s)"
    print(header)
    print("-" * len(header))
    for s in ordered:
        rounds = " / ".join(f"{r:,.0f}" for r in s.rates)
        print(f"{s.label:<{width}} | {s.median:>11,.0f} | {s.median / s.per_call:>13,.0f} | {rounds}")

    print("\ntargets (ratios: median of the per-round ratios)")
    for key, name in (("direct", "SortingLineEnv, no resets"), ("make", "gymnasium.make, 50-step episodes")):
        ok = by_key[key].median >= TARGET_ONE_LINE
        print(
            f"  one line, {name}: {by_key[key].median:,.0f} env-steps/s "
            f"(target >= {TARGET_ONE_LINE:,.0f}) {'OK' if ok else 'MISSED'}"
        )
    for tag, single, name in (("noend", "direct", "no episode ends"), ("ep50", "make", "50-step episodes")):
        if f"{tag}_16" in by_key:
            ratio, ratios = paired_ratio(by_key[f"{tag}_16"], by_key[single])
            print(
                f"  16 lines (VectorEnv) / single-line env ({by_key[single].label[4:].split(',')[0]}), "
                f"{name}: {ratio:.1f}x "
                f"(target >= {TARGET_SCALING:.0f}x) {'OK' if ratio >= TARGET_SCALING else 'MISSED'}; "
                f"rounds {' / '.join(f'{x:.1f}' for x in ratios)}"
            )
    print("\nother ratios")
    for tag, name in (("noend", "no episode ends"), ("ep50", "50-step episodes")):
        if f"{tag}_16" in by_key and f"{tag}_1" in by_key:
            ratio, _ = paired_ratio(by_key[f"{tag}_16"], by_key[f"{tag}_1"])
            print(f"  16 lines / 1 line, both VectorEnv, {name}: {ratio:.1f}x")
    for key in ("direct", "make"):
        ratio, _ = paired_ratio(by_key[key], by_key["raw"])
        print(f"  {by_key[key].label[4:]} / raw lock-step loop (a): {ratio:.2f}")


def main() -> int:
    args = _args()
    h.run_isolated(__file__, "SORTING_LINE_BRIDGE_BENCH_IN_NETNS")
    os.environ["ROS_DOMAIN_ID"] = str(args.domain)
    env = h.ros_environment()
    if args.subject:
        measure_here(args.subject, args.single, args.vector)
        return 0
    progress(f"node {node_binary()}; python {sys.executable}; " + ", ".join(f"{k}={v}" for k, v in env.items()))
    before = h.machine_conditions()
    ordered = _rounds(args)
    after = h.machine_conditions()
    _report(ordered, args, before, after)
    by_key = {s.key: s for s in ordered}
    if args.plot:
        args.plot.parent.mkdir(parents=True, exist_ok=True)
        plot(
            ordered,
            by_key,
            args.plot,
            f"sorting_line_gym env-steps/s, median of {args.rounds} rounds, {os.cpu_count()} CPUs ({after})",
        )
        print(f"\nplot: {args.plot} and {args.plot.with_suffix('.svg')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
