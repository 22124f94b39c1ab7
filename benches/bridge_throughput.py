#!/usr/bin/env python3
"""Throughput of the Gymnasium bridge (bridge/sorting_line_gym) against the real node, in env-steps/s.

Measures, each as the median of RUNS timed runs (after a warm-up) on a node of its own:
  (a) the raw lock-step ceiling: a minimal rclpy loop on one line's own topics (publish
      `cmd/speed` stamped with the tick, wait for that line's next `state`), the measurement the
      node's lock-step benchmark (benches/node_lockstep.py) makes;
  (b) `SortingLineEnv`, one line:
        - constructed directly with max_episode_steps=1_000_000 (no episode ends, no resets), and
        - `gymnasium.make("sorting_line_gym:SortingLine-v0")` with its 50-step TimeLimit episodes,
          the resets counted in the time (env-steps/s = steps / time including reset());
  (c) `SortingLineVectorEnv` over 1, 4 and 16 lines of one node (batch topics): with 50-step
      episodes (SAME_STEP autoresets included) and without episode ends (max_episode_steps=1e6);
      env-steps/s = round trips/s x lines.
Then prints a table, the ratio of (b) to (a), the ratio of 16-line to 1-line env-steps/s
(target >= 10x) and the one-line target (>= 3,000 env-steps/s).

DDS traffic must stay on this machine: the script refuses to run outside an isolated (loopback-only)
network namespace; as root it re-executes itself under `unshare -n` with `lo` up. It sets what
launch_scripts/env.sh sets (Fast DDS, the project's profile, localhost discovery), uses the
project's .venv interpreter and a ROS_DOMAIN_ID of its own (--domain, default 89).

    .venv/bin/python benches/bridge_throughput.py                 # N = 5000 single, 1000 vector
    .venv/bin/python benches/bridge_throughput.py --single 2000 --vector 500 --runs 3
Progress goes to stderr, the table to stdout. The machine may be shared: the load average is
printed with the figures.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VENV = ROOT / ".venv"
REEXEC_MARK = "SORTING_LINE_BRIDGE_BENCH_IN_NETNS"
TARGET_ONE_LINE = 3000.0
TARGET_SCALING = 10.0
WARMUP = 200


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------------
# Isolation and environment


def interfaces() -> list[tuple[str, bool]]:
    """(name, is up) of every interface of this network namespace."""
    out = subprocess.run(["ip", "-o", "link"], capture_output=True, text=True, check=True).stdout
    result = []
    for line in out.splitlines():
        parts = line.split(":", 2)
        if len(parts) >= 3:
            flags = parts[2].split(">")[0]
            result.append((parts[1].strip().split("@")[0], "UP" in flags.split("<")[-1].split(",")))
    return result


def ensure_isolated() -> None:
    """Returns only inside a loopback-only network namespace with lo up; re-execs under unshare -n
    (as root) or exits otherwise."""
    if shutil.which("ip") is None:
        sys.exit("bridge_throughput.py: refusing to run: `ip` (iproute2) is needed to check the network namespace")
    links = interfaces()
    others = [name for name, _ in links if name != "lo"]
    if not others:
        if not all(up for name, up in links if name == "lo"):
            if os.geteuid() != 0:
                sys.exit("bridge_throughput.py: refusing to run: lo is down in this network namespace (not root)")
            subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
        return
    if os.environ.get(REEXEC_MARK) == "1":
        sys.exit(f"bridge_throughput.py: refusing to run: still not isolated after unshare -n ({', '.join(others)})")
    if os.geteuid() == 0 and shutil.which("unshare"):
        progress(f"not in an isolated network namespace (interfaces {', '.join(others)}): "
                 "re-executing under `unshare -n` with lo up")
        env = dict(os.environ, **{REEXEC_MARK: "1"})
        argv = ["unshare", "-n", "--", python_for_run(), os.path.abspath(__file__), *sys.argv[1:]]
        os.execvpe("unshare", argv, env)
    sys.exit(f"bridge_throughput.py: refusing to run: not in an isolated network namespace (interfaces "
             f"{', '.join(others)} besides lo) and cannot create one (needs root and unshare). Run it inside "
             "`unshare -n` with `ip link set lo up`.")


def python_for_run() -> str:
    """The project's .venv interpreter (what `source launch_scripts/env.sh` activates), if it exists."""
    venv_python = VENV / "bin" / "python"
    return str(venv_python) if venv_python.exists() else sys.executable


def ensure_venv() -> None:
    if Path(sys.prefix).resolve() != VENV.resolve() and (VENV / "bin" / "python").exists():
        progress(f"re-executing with {VENV / 'bin' / 'python'}")
        os.execv(str(VENV / "bin" / "python"), [str(VENV / "bin" / "python"), os.path.abspath(__file__), *sys.argv[1:]])


def ros_environment(domain: int) -> dict[str, str]:
    """What launch_scripts/env.sh exports, plus our own ROS_DOMAIN_ID; before rclpy is imported."""
    os.environ["RMW_IMPLEMENTATION"] = "rmw_fastrtps_cpp"
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(ROOT / "launch_scripts" / "fastdds_profile.xml")
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    keys = ["ROS_DOMAIN_ID", "RMW_IMPLEMENTATION", "FASTRTPS_DEFAULT_PROFILES_FILE", "ROS_AUTOMATIC_DISCOVERY_RANGE"]
    return {k: os.environ[k] for k in keys}


def node_binary() -> Path:
    path = Path(os.environ.get("SORTING_LINE_BIN") or ROOT / "target" / "release" / "sorting_line")
    if not path.is_file():
        sys.exit(f"bridge_throughput.py: {path} not found: build it with `cargo build --release`")
    return path


def load() -> str:
    return "/".join(f"{x:.2f}" for x in os.getloadavg())


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

        self.ns = f"/bench_raw_{os.getpid()}"
        self.log = open(log_dir / "raw_node.log", "wb")
        self.proc = subprocess.Popen(
            [str(node_binary()), "node", "--variant", "basic", "--lines", "1", "--max-steps", "1000000",
             "--seed", "100", "--ros-args", "-r", f"__ns:={self.ns}"],
            stdin=subprocess.DEVNULL, stdout=self.log, stderr=subprocess.STDOUT)
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f"bench_raw_client_{os.getpid()}", context=self.context,
                                      start_parameter_services=False, enable_rosout=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE,
                         history=HistoryPolicy.KEEP_LAST)
        self.pub = self.node.create_publisher(SpeedCommand, f"{self.ns}/cmd/speed", qos)
        self.sub = self.node.create_subscription(LineState, f"{self.ns}/state", self._on_state, qos)
        self.reset_client = self.node.create_client(ResetLine, f"{self.ns}/reset")
        self.cmd = SpeedCommand(speed=0.5)
        self.stamp = None  # (sec, nanosec) of the tick we answer
        self.arrived = False
        self._ResetLine = ResetLine
        # The node benchmark's watchdog (imported here, after any re-exec into the venv and netns:
        # node_lockstep imports rclpy).
        from node_lockstep import Watchdog

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
        self._spin_until(lambda: self.pub.get_subscription_count() > 0 and self.sub.get_publisher_count() > 0
                         and self.reset_client.service_is_ready(), 20.0, f"the node serving {self.ns}")
        for attempt in range(3):
            future = self.reset_client.call_async(self._ResetLine.Request(has_seed=True, seed=100))
            try:
                self._spin_until(future.done, 3.0, f"{self.ns}/reset")
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
# Measurements


def timed_runs(label: str, runs: int, n: int, one, per_unit: int = 1) -> list[float]:
    """`runs` timed runs of `n` calls of one(i); the rate of each run in units (x per_unit) per s."""
    rates = []
    for run in range(runs):
        start = time.perf_counter()
        for i in range(n):
            one(i)
        elapsed = time.perf_counter() - start
        rates.append(n * per_unit / elapsed)
        progress(f"  {label}: run {run + 1}/{runs}: {rates[-1]:,.0f} env-steps/s ({n} calls in {elapsed:.2f} s, "
                 f"load {load()})")
    return rates


def measure_raw(n: int, runs: int, log_dir: Path) -> list[float]:
    line = RawLine(log_dir)
    try:
        line.connect()
        for _ in range(WARMUP):
            line.round_trip()
        return timed_runs("(a) raw rclpy lock-step", runs, n, lambda i: line.round_trip())
    finally:
        line.close()


def measure_env_direct(n: int, runs: int) -> list[float]:
    from sorting_line_gym import SortingLineEnv

    env = SortingLineEnv(setup="A", variant="basic", max_episode_steps=1_000_000)
    try:
        env.reset(seed=1)
        for i in range(WARMUP):
            env.step(i % 10)

        def one(i):
            _, _, terminated, truncated, _ = env.step(i % 10)
            if terminated or truncated:
                raise RuntimeError("an episode ended during the no-reset measurement")

        return timed_runs("(b) SortingLineEnv direct, no episode ends", runs, n, one)
    finally:
        env.close()


def measure_env_make(n: int, runs: int) -> list[float]:
    import gymnasium

    env = gymnasium.make("sorting_line_gym:SortingLine-v0", setup="A")
    try:
        env.reset(seed=1)

        def one(i):
            _, _, terminated, truncated, _ = env.step(i % 10)
            if terminated or truncated:
                env.reset()

        for i in range(WARMUP):
            one(i)
        return timed_runs("(b) gymnasium.make, 50-step episodes", runs, n, one)
    finally:
        env.close()


def measure_vector(lines: int, n: int, runs: int, max_episode_steps: int) -> list[float]:
    import numpy as np
    from sorting_line_gym.vector import SortingLineVectorEnv

    env = SortingLineVectorEnv(num_envs=lines, setup="A", variant="basic", max_episode_steps=max_episode_steps)
    try:
        env.reset(seed=1)
        actions = [np.full(lines, k % 10, dtype=np.int64) for k in range(10)]

        def one(i):
            env.step(actions[i % 10])

        for i in range(WARMUP):
            one(i)
        label = f"(c) VectorEnv {lines:>2} lines, " + ("50-step episodes" if max_episode_steps == 50 else "no episode ends")
        return timed_runs(label, runs, n, one, per_unit=lines)
    finally:
        env.close()


# ------------------------------------------------------------------------------------------


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--single", type=int, default=5000, help="steps per run for (a) and (b) (default 5000)")
    parser.add_argument("--vector", type=int, default=1000, help="round trips per run for (c) (default 1000)")
    parser.add_argument("--runs", type=int, default=3, help="timed runs per measurement; the median is reported")
    parser.add_argument("--lines", type=int, nargs="+", default=[1, 4, 16], help="vector line counts (default 1 4 16)")
    parser.add_argument("--domain", type=int, default=89, help="ROS_DOMAIN_ID of the benchmark (default 89)")
    args = parser.parse_args()

    ensure_venv()
    ensure_isolated()
    env = ros_environment(args.domain)
    node_binary()
    progress(f"node {node_binary()}; python {sys.executable}; " + ", ".join(f"{k}={v}" for k, v in env.items()))
    load_before = load()

    rows: list[tuple[str, str, list[float]]] = []  # (key, label, rates)
    with tempfile.TemporaryDirectory(prefix="sl_bridge_bench_") as tmp:
        progress(f"(a) raw lock-step ceiling: {args.runs} x {args.single} round trips")
        rows.append(("raw", "(a) raw rclpy lock-step loop, 1 line (per-line topics)", measure_raw(args.single, args.runs, Path(tmp))))
    progress(f"(b) SortingLineEnv: {args.runs} x {args.single} steps")
    rows.append(("direct", "(b) SortingLineEnv(max_episode_steps=1e6), no resets", measure_env_direct(args.single, args.runs)))
    rows.append(("make", "(b) gymnasium.make(SortingLine-v0), 50-step episodes", measure_env_make(args.single, args.runs)))
    for steps, tag in ((50, "ep50"), (1_000_000, "noend")):
        for lines in args.lines:
            progress(f"(c) SortingLineVectorEnv, {lines} lines, max_episode_steps={steps}: "
                     f"{args.runs} x {args.vector} round trips")
            label = f"(c) SortingLineVectorEnv({lines:>2} lines), " + ("50-step episodes" if steps == 50 else "no episode ends")
            rows.append((f"{tag}_{lines}", label, measure_vector(lines, args.vector, args.runs, steps)))
    load_after = load()

    med = {key: statistics.median(rates) for key, _, rates in rows}
    print(f"\nsorting_line_gym throughput, env-steps/s (median of {args.runs} runs; N = {args.single} steps single, "
          f"{args.vector} round trips vector); {os.cpu_count()} CPUs; load average (1/5/15 min) "
          f"{load_before} before, {load_after} after")
    width = max(len(label) for _, label, _ in rows)
    header = f"{'measurement':<{width}} | {'env-steps/s':>11} | {'round trips/s':>13} | {'runs (env-steps/s)':>26}"
    print(header)
    print("-" * len(header))
    for key, label, rates in rows:
        lines = int(key.split("_")[1]) if "_" in key else 1
        runs_text = " / ".join(f"{r:,.0f}" for r in rates)
        print(f"{label:<{width}} | {med[key]:>11,.0f} | {med[key] / lines:>13,.0f} | {runs_text:>26}")

    print("\nratios and targets")
    raw = med["raw"]
    for key, name in (("direct", "SortingLineEnv direct"), ("make", "gymnasium.make, 50-step episodes")):
        print(f"  (b) / (a): {name}: {med[key]:,.0f} / {raw:,.0f} = {med[key] / raw:.2f} of the raw lock-step ceiling")
    for tag, name in (("ep50", "50-step episodes"), ("noend", "no episode ends")):
        if f"{tag}_1" in med and f"{tag}_16" in med:
            ratio = med[f"{tag}_16"] / med[f"{tag}_1"]
            print(f"  16 lines / 1 line, VectorEnv, {name}: {med[f'{tag}_16']:,.0f} / {med[f'{tag}_1']:,.0f} = "
                  f"{ratio:.1f}x (target >= {TARGET_SCALING:.0f}x) {'OK' if ratio >= TARGET_SCALING else 'MISSED'}")
    for key, name in (("direct", "SortingLineEnv direct"), ("make", "gymnasium.make, 50-step episodes"),
                      ("ep50_1", "VectorEnv 1 line, 50-step episodes")):
        if key in med:
            ok = med[key] >= TARGET_ONE_LINE
            print(f"  one line, {name}: {med[key]:,.0f} env-steps/s (target >= {TARGET_ONE_LINE:,.0f}) "
                  f"{'OK' if ok else 'MISSED'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
