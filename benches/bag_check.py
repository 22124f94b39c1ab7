#!/usr/bin/env python3
"""How fast `sorting-line-bag check` (open loop) tests a controller, against the raw rclpy lock-step
round-trip rate measured in the same run (target: the check within 2x of it).

1. A bag of N ticks (default 1,000: one episode of --max-steps N, setup D, basic line) is recorded
   from a lock-step node driven by `sorting-line-controller` (`sorting-line-bag record`'s function).
2. Raw round trips: one rclpy client against a fresh lock-step node, `cmd/speed` then the next
   `state` (benches/node_lockstep.py's client, spin-block pattern), N per run.
3. The check: `check_controller(bag, controller=...)`, RUNS times with `sorting-line-controller` and
   RUNS times with a lean rclpy controller (a wait set instead of an executor, answering with the
   bag's speeds: what the check itself costs, a controller's own overhead aside). The rate is
   ticks played per second of the play phase (the verdict's ``seconds``: tick by tick, each tick's
   node-side messages, then the controller's answer); the wall time with the controller's
   start-up is printed beside it. Runs are interleaved (raw, then both checks; RUNS times) and the
   ratio raw / check is taken per run: the machine's load moves the figures more than anything.

It refuses to run outside an isolated loopback-only network namespace; as root it re-executes itself
under `unshare -n` with `lo` up. Figures, not assertions: progress on stderr, the table on stdout.

    source launch_scripts/env.sh
    python benches/bag_check.py                 # N = 1000, 3 runs
    python benches/bag_check.py -n 2000 --runs 5
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

from support import ros_harness as h  # noqa: E402

REEXEC_MARK = "SORTING_LINE_BENCH_IN_NETNS"
TARGET_RATIO = 2.0
CONTROLLER = "sorting-line-controller --setup D --variant basic --agent rba"


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def record_bag(out: Path, ticks: int) -> None:
    """One episode of ``ticks`` steps, driven by sorting-line-controller, recorded into ``out``."""
    from sorting_line_gym.bag.check.closed_loop import CheckRecorder, Watch
    from sorting_line_gym.bag.check.controller_process import ControllerProcess
    from sorting_line_gym.bag.format.topics import LINE_TYPES, join
    from sorting_line_gym.bag.storage.schema import decode
    from sorting_line_gym.bag.transport.rosnode import ToolNode
    from sorting_line_gym.line.process import NodeProcess
    from sorting_line_gym.line.topics import INPUT, RESET, SPEED_CMD, STATE
    from sorting_line_gym.ros.links import LineLink

    ns = f"/bench_bag_{os.getpid()}"
    node = NodeProcess(ns, {"setup": "D", "variant": "basic", "max_steps": ticks, "seed": 7, "mode": "lockstep"})
    controller = ControllerProcess(CONTROLLER, ns)
    tool = recorder = None
    try:
        tool = ToolNode("bench_bag_check", Watch(node, controller))
        link = LineLink(tool.node, ns, advanced=False)
        steps: list[int] = [-1]
        tool.raw_subscription(
            join(ns, STATE),
            LINE_TYPES[STATE],
            lambda data, _t: steps.append(decode(data, LINE_TYPES[STATE])["step"]),
        )
        tool.until(
            lambda: link.endpoints_matched(tool.node) and tool.node.count_subscribers(join(ns, INPUT)) > 0,
            60,
            f"the node and the controller in {ns}",
        )
        speed = join(ns, SPEED_CMD)
        recorder = CheckRecorder(ns, out, 30, {speed: tool.node.count_publishers(speed)})
        tool.spin_for(1.0)
        for _attempt in range(3):
            link.send_reset(7)
            tool.until(link.reset_done, 10, f"{ns}/{RESET}")
            link.finish_reset()
            try:
                tool.until(lambda: steps[-1] >= 1, 3, "the controller's first answer")
                break
            except TimeoutError:
                progress("  the controller's first answer was lost while matching: resetting again")
        tool.until(lambda: steps[-1] >= ticks, 300, f"the controller driving {ticks} ticks")
        tool.spin_for(0.3)
    finally:
        if recorder is not None:
            progress(f"  recorded {recorder.stop()}")
        if tool is not None:
            tool.close()
        controller.stop()
        node.stop()


def lean_controller(bag: str) -> int:
    """A controller as lean as rclpy allows, answering each tick with the bag's speed: no executor
    (a wait set on ``input``, messages taken directly), no parameter services, no rosout. Run as
    ``bag_check.py --lean-controller BAG --ros-args -r __ns:=NS``; what the check costs without a
    controller's own overhead."""
    import signal

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sorting_line_interfaces.msg import MaterialInput, SpeedCommand

    from sorting_line_gym.bag import open_bag
    from sorting_line_gym.bag.storage.schema import stamp_ns
    from sorting_line_gym.line.topics import INPUT, SPEED_CMD
    from sorting_line_gym.ros.links import QOS
    from sorting_line_gym.ros.waits import Waiter

    speeds = {stamp_ns(m.plain): m.plain["speed"] for m in open_bag(bag).by_relative_topic()[SPEED_CMD]}
    rclpy.init(args=sys.argv, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    stop: list[int] = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    node = rclpy.create_node("lean_controller", start_parameter_services=False, enable_rosout=False)
    pub = node.create_publisher(SpeedCommand, SPEED_CMD, QOS)
    sub = node.create_subscription(MaterialInput, INPUT, lambda _m: None, QOS)
    waiter = Waiter(SingleThreadedExecutor(), None)

    def answer() -> bool:
        with sub.handle:
            while (taken := sub.handle.take_message(sub.msg_type, False)) is not None:
                stamp = taken[0].header.stamp
                speed = speeds.get(stamp.sec * 1_000_000_000 + stamp.nanosec)
                if speed is not None:
                    command = SpeedCommand(speed=speed)
                    command.header.stamp = stamp
                    pub.publish(command)
        return bool(stop)

    while not stop:
        try:
            waiter.until_received([sub], answer, 1.0, lambda: "input")
        except TimeoutError:
            pass
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def raw_round_trips(ticks: int, runs: int, log_dir: Path) -> dict:
    import node_lockstep

    session = h.RosSession()
    try:
        return node_lockstep.measure(session, 1, ticks, runs, "spin-block", 0, log_dir, "raw")
    finally:
        session.shutdown()


def checks(bag: Path, runs: int, controller: str | list[str], tag: str) -> list[dict]:
    from sorting_line_gym.bag.check.checker import check_controller

    out = []
    for run in range(runs):
        started = time.monotonic()
        namespace = f"/bench_check_{os.getpid()}_{tag.replace('-', '_')}_{run}"
        verdict = check_controller(bag, namespace=namespace, controller=controller)
        wall = time.monotonic() - started
        if not verdict.passed:
            sys.exit(f"the check failed, so its timing means nothing:\n{verdict.summary()}")
        lat = verdict.latency()
        out.append(
            {
                "ticks": verdict.ticks,
                "seconds": verdict.seconds,
                "rate": verdict.ticks / verdict.seconds,
                "wall": wall,
                "p50": lat["p50"],
                "p99": lat["p99"],
            }
        )
        progress(
            f"  {tag} {run + 1}/{runs}: {verdict.ticks} ticks in {verdict.seconds:.2f} s "
            f"({verdict.ticks / verdict.seconds:,.0f} ticks/s), {wall:.1f} s with the controller's start-up"
        )
    return out


def _report(tag: str, results: list[dict], raw: list[float]) -> None:
    rate = statistics.median(r["rate"] for r in results)
    ratios = [r_raw / r["rate"] for r_raw, r in zip(raw, results, strict=True)]
    ratio = statistics.median(ratios)
    print(
        f"  check with {tag}: {rate:,.0f} ticks/s in the play phase (runs "
        + "/".join(f"{r['rate']:,.0f}" for r in results)
        + f"), answer latency p50 {statistics.median(r['p50'] for r in results):.2f} ms, "
        f"p99 {statistics.median(r['p99'] for r in results):.2f} ms; whole command (controller start-up, "
        f"discovery, play, stop) {statistics.median(r['wall'] for r in results):.1f} s"
    )
    print(
        "    raw / check per run " + "/".join(f"{x:.2f}" for x in ratios) + f", median {ratio:.2f}x (target: "
        f"within {TARGET_RATIO:g}x) -> {'OK' if ratio <= TARGET_RATIO else 'MISSED'}"
    )


def main() -> int:
    if sys.argv[1:2] == ["--lean-controller"]:
        return lean_controller(sys.argv[2])
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", "--ticks", type=int, default=1000, help="ticks of the bag (default 1000)")
    parser.add_argument("--runs", type=int, default=3, help="runs of each measurement; the median is reported")
    args = parser.parse_args()
    h.run_isolated(__file__, REEXEC_MARK)
    env = h.ros_environment(default_domain="89")
    os.environ.setdefault("SORTING_LINE_BIN", str(h.node_binary()))
    progress(f"node {h.node_binary()}; " + ", ".join(f"{k}={v}" for k, v in env.items()))
    conditions_before = h.machine_conditions()
    raw, ours, lean = [], [], []
    with tempfile.TemporaryDirectory(prefix="sl_bench_check_") as tmp:
        bag = Path(tmp) / "bag"
        progress(f"recording a {args.ticks}-tick bag ...")
        record_bag(bag, args.ticks)
        # Interleaved, run by run: the machine's load moves the figures more than anything measured.
        for run in range(args.runs):
            progress(f"run {run + 1}/{args.runs}: raw round trips, then the check with each controller")
            raw.append(raw_round_trips(args.ticks, 1, Path(tmp))["rt_s"])
            ours += checks(bag, 1, CONTROLLER, "sorting-line-controller")
            lean += checks(bag, 1, [sys.executable, __file__, "--lean-controller", str(bag)], "lean")
    print(
        f"\nopen-loop check of a {ours[0]['ticks']}-tick bag (setup D, basic line), {args.runs} runs; "
        f"{os.cpu_count()} CPUs; machine before: {conditions_before}, after: {h.machine_conditions()}"
    )
    print(
        f"  raw rclpy lock-step round trips (client <-> node, benches/node_lockstep.py): "
        f"{statistics.median(raw):,.0f}/s (runs " + "/".join(f"{x:,.0f}" for x in raw) + ")"
    )
    _report("sorting-line-controller", ours, raw)
    _report("a lean rclpy controller (wait set, no executor)", lean, raw)
    return 0


if __name__ == "__main__":
    sys.exit(main())
