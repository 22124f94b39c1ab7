#!/usr/bin/env python3
"""The recorder's memory over a long recording: `sorting-line-bag record` of a 64-line realtime
node (every line's input, belt/occupancy, state and events/reset, and /clock) for 10 minutes.

It prints the recorder's RSS at the start (once it says ``recording``), after the first minute
and at the end (target: the end within 20 % of the first minute's: memory does not grow with the
recording), a sample every ``--every`` seconds, the messages the recorder stored against those
the node published (each line's ``messages_published`` on /diagnostics, compared over the window
between the first and last report with :class:`sorting_line_gym.bag.storage.losses.LossCounter`, the
recorder's own check, for every line), and the bag's bytes per message. Figures only, no
assertion (the machine may be shared: load average and steal are printed too).

    .venv/bin/python benches/record_memory.py                         # 64 lines at 10 Hz, 10 min
    .venv/bin/python benches/record_memory.py --minutes 2 --rate 50   # the same message count, 5x the rate
    .venv/bin/python benches/record_memory.py --compression zstd

Like the other benchmarks it refuses to run outside a loopback-only network namespace and, as root,
re-executes itself under ``unshare -n``; ROS_DOMAIN_ID is its own (--domain, default 96).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
sys.path.insert(0, str(ROOT / "bridge"))
sys.path.insert(0, str(ROOT / "benches"))

from node_lockstep import cpu_seconds  # noqa: E402
from sorting_line_gym.line.topics import BELT_OCCUPANCY, CLOCK, DIAGNOSTICS, INPUT, RESET_EVENT, STATE  # noqa: E402
from support import ros_harness as h  # noqa: E402

LINE_TOPICS = (INPUT, BELT_OCCUPANCY, STATE, RESET_EVENT)
NAMESPACE = "/recbench"
#: The node's default simulated seconds per tick (its stamps), whatever the realtime rate.
TICK_PERIOD = 1.0


def _args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--lines", type=int, default=64, help="lines of the node (all recorded)")
    p.add_argument("--rate", type=float, default=10.0, help="the node's realtime ticks per second")
    p.add_argument("--minutes", type=float, default=10.0, help="how long to record")
    p.add_argument("--every", type=float, default=30.0, help="seconds between RSS samples")
    p.add_argument("--compression", default="none", help="the recorder's --compression")
    p.add_argument("--domain", default="96", help="ROS_DOMAIN_ID of the run")
    p.add_argument("--out", default=None, help="keep the bag here (default: a temporary directory)")
    return p.parse_args()


def _recorder(args, out: Path, log: Path) -> subprocess.Popen:
    topics = [f"{NAMESPACE}/line_{k}/{t}" for k in range(args.lines) for t in LINE_TOPICS] + [CLOCK]
    argv = [
        sys.executable,
        "-m",
        "sorting_line_gym.bag.cli",
        "record",
        "--namespace",
        f"{NAMESPACE}/line_0",
        "-o",
        str(out),
        "--compression",
        args.compression,
        "--wait",
        "60",
    ]
    for t in topics:
        argv += ["--topic", t]
    return subprocess.Popen(
        argv,
        stdout=open(log, "wb"),
        stderr=subprocess.STDOUT,
        env=dict(os.environ, PYTHONUNBUFFERED="1", PYTHONPATH=str(ROOT / "bridge")),
    )


def _wait_for(log: Path, text: str, proc: subprocess.Popen, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while text not in log.read_text(errors="replace"):
        if proc.poll() is not None or time.monotonic() > deadline:
            sys.exit(f"the recorder did not print {text!r}:\n{log.read_text(errors='replace')}")
        time.sleep(0.2)


def _compare(bag_path: Path, statuses: dict[str, list[dict]], lines: int) -> dict:
    """Per line, the recorder's own check (LossCounter) over the bag, streamed; summed."""
    from rosbags.rosbag2 import Reader

    from sorting_line_gym.bag.storage.losses import LossCounter

    namespaces = [f"{NAMESPACE}/line_{k}" for k in range(lines)]
    counters = {}
    for ns in namespaces:
        recorded = [f"{ns}/{t}" for t in LINE_TOPICS]
        counters[ns] = LossCounter(ns, recorded, "basic", False, TICK_PERIOD)
        for values in statuses.get(ns, []):
            counters[ns].on_status(values)
    messages = 0
    with Reader(bag_path) as reader:
        for connection, _, raw in reader.messages():
            messages += 1
            ns = "/".join(connection.topic.split("/")[:3])  # /recbench/line_k
            if ns in counters:
                counters[ns].on_message(connection.topic, raw)
    reports = [c.report() for c in counters.values()]
    compared = [r for r in reports if r.get("compared")]
    return {
        "messages": messages,
        "lines_compared": len(compared),
        "published": sum(r["published"] for r in compared),
        "received": sum(r["received"] for r in compared),
        "missing": sum(r["missing"] for r in compared),
        "not_compared": [r.get("why") for r in reports if not r.get("compared")][:3],
    }


def _diagnostics(session, statuses: dict[str, list[dict]]):
    from diagnostic_msgs.msg import DiagnosticArray

    def on(array):
        for s in array.status:
            statuses.setdefault(s.hardware_id, []).append({kv.key: kv.value for kv in s.values})

    node = session.make_node("record_memory_probe")
    node.create_subscription(DiagnosticArray, DIAGNOSTICS, on, 100)
    return node


def _sample(proc, started: float, samples: list) -> None:
    samples.append((time.monotonic() - started, h.rss_mb(proc.pid)))
    print(f"  t = {samples[-1][0]:6.0f} s  recorder RSS {samples[-1][1]:7.1f} MB", file=sys.stderr, flush=True)


def main() -> int:
    args = _args()
    h.run_isolated(__file__, "SORTING_LINE_RECBENCH_IN_NETNS")
    os.environ["ROS_DOMAIN_ID"] = args.domain
    h.ros_environment(args.domain)
    work = Path(tempfile.mkdtemp(prefix="record_memory_"))
    out = Path(args.out) if args.out else work / "bag"
    node = h.NodeProcess(
        ["--lines", args.lines, "--mode", "realtime", "--rate", args.rate, "--ros-args", "-r", f"__ns:={NAMESPACE}"],
        work / "node.log",
    )
    session = h.RosSession()
    statuses: dict[str, list[dict]] = {}
    probe = _diagnostics(session, statuses)
    log = work / "record.log"
    recorder = _recorder(args, out, log)
    try:
        samples, minute, cpu, statuses = _measure(args, session, recorder, log, statuses)
    finally:
        if recorder.poll() is None:
            recorder.kill()
        node.stop(signal.SIGINT, timeout=10.0)
        session.destroy_node(probe)
        session.shutdown()
    _print_figures(args, out, log, _compare(out, statuses, args.lines), samples, minute, cpu)
    return 0


def _measure(args, session, recorder, log: Path, statuses: dict[str, list[dict]]):
    """Samples the recorder's RSS for ``args.minutes`` once it records, then stops it with SIGINT:
    the RSS samples (s, MB), the RSS after the first minute (None if shorter), its CPU seconds and
    the node's reports over the window."""
    _wait_for(log, "recording", recorder, 120.0)
    started, samples = time.monotonic(), []
    statuses.clear()  # the window starts once the recorder records
    _sample(recorder, started, samples)
    cpu_start = cpu_seconds(recorder.pid)
    next_sample, minute = started + args.every, None
    while (now := time.monotonic()) < started + 60 * args.minutes:
        session.spin_for(0.5)
        if minute is None and now >= started + 60:
            minute = h.rss_mb(recorder.pid)
        if now >= next_sample:
            next_sample += args.every
            _sample(recorder, started, samples)
    _sample(recorder, started, samples)
    cpu = cpu_seconds(recorder.pid) - cpu_start
    # The reports up to now: the recorder stops listening after SIGINT (and its drain).
    statuses = {ns: list(values) for ns, values in statuses.items()}
    recorder.send_signal(signal.SIGINT)
    session.spin_until(lambda: recorder.poll() is not None, 120.0, "the recorder to stop")
    return samples, minute, cpu, statuses


def _print_figures(args, out: Path, log: Path, figures: dict, samples: list, minute: float | None, cpu: float) -> None:
    end_rss = samples[-1][1]
    size = sum(f.stat().st_size for f in out.glob("*.mcap"))
    seconds = 60 * args.minutes
    print(
        f"record_memory: {args.lines} lines at {args.rate:g} Hz, {args.minutes:g} min, compression "
        f"{args.compression}; {h.machine_conditions()}"
    )
    print(
        f"  recorder RSS: start {samples[0][1]:.1f} MB, after the first minute {minute or 0:.1f} MB, end "
        f"{end_rss:.1f} MB ({(end_rss / minute - 1) * 100 if minute else 0:+.1f} % against the first minute)"
    )
    print(
        f"  messages: the bag holds {figures['messages']:,} ({figures['messages'] / seconds:,.0f}/s); over the "
        f"report window of {figures['lines_compared']} lines the node published {figures['published']:,} and the "
        f"recorder stored {figures['received']:,}: missing {figures['missing']:,}"
    )
    if figures["not_compared"]:
        print(f"  not compared: {figures['not_compared']}")
    print(
        f"  recorder CPU: {cpu:.1f} s over {seconds:.0f} s ({100 * cpu / seconds:.0f} % of a core), "
        f"{1e6 * cpu / max(1, figures['messages']):.0f} us per message stored"
    )
    print(
        f"  bag: {size / 1e6:.1f} MB in {len(list(out.glob('*.mcap')))} file(s), "
        f"{size / max(1, figures['messages']):.1f} bytes per message"
    )
    summary = log.read_text(errors="replace").strip().splitlines()
    print(f"  the recorder's own summary: {summary[-2].split(' (')[0]} | {summary[-1]}")
    print(f"  RSS samples (s, MB): {[(round(t), round(m, 1)) for t, m in samples]}")


if __name__ == "__main__":
    sys.exit(main())
