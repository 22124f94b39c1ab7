#!/usr/bin/env python3
"""Lines on several hosts, one vector env driving them all: what a round trip costs as
hosts are added, and a soak across hosts.

The hosts are network namespaces made here (tests/python/support/netns_hosts.py: veth pairs into a Linux
bridge, addresses 192.168.77.x that exist only inside them; nothing is sent anywhere else). Each
host runs one `sorting_line node --lines 16` (/h<i>/plant) under ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET;
a "trainer" host runs a ``SortingLineVectorEnv`` over all of them (``namespace=[...]``,
``node="attach"``): one round trip per node per step, all in flight at once.

- scaling: for 1, 2 and 4 hosts (``--hosts``), ``--round-trips`` timed steps after a warm-up:
  round trips/s, p50/p99 latency, and the CPU time per round trip of the trainer and of each
  node (the hosts share this machine's cores, so their CPU adds to the trainer's), ``--rounds``
  interleaved rounds (the median of each figure over the rounds is reported); the target is a
  4-host round trip at most 1.5x a 1-host one (p50);
- soak: ``--soak-ticks`` line-ticks (default 100,000) over ``--soak-hosts`` hosts (default 3) through
  benches/soak.py's checks: nothing lost, nothing misaligned, every value equal to the library's.

    .venv/bin/python benches/multihost.py                    # both (about 3 min on 2 shared cores)
    .venv/bin/python benches/multihost.py --soak-ticks 0     # scaling only
    .venv/bin/python benches/multihost.py --json r.json --plot docs/results/scaling/scaling.png

Needs root (network namespaces), except with --attach. Exit code 1 when the soak lost, misaligned or
mismatched anything.

On real machines (where the 1.5x target can be measured fairly: here the "hosts" share the
trainer's 2 cores), start on each machine K a node of 16 lines,

    sorting_line node --setup A --lines 16 --max-steps 50 --ros-args -r __ns:=/hK/plant

in one ROS domain the trainer's machine reaches (ROS_DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET
or ROS_STATIC_PEERS), then on the trainer's machine, in that ROS environment:

    .venv/bin/python benches/multihost.py --attach /h1/plant /h2/plant /h3/plant /h4/plant

``--hosts`` then counts how many of the attached nodes each measurement uses, in the order given
(the soak uses the first ``--soak-hosts``). The nodes' CPU is not measured there (they run elsewhere).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
sys.path.insert(0, str(ROOT / "benches"))

LINES = 16


def measure(cfg: dict) -> dict:
    """In the trainer host: round trips over the nodes of ``cfg["namespaces"]``."""
    import numpy as np

    from node_lockstep import cpu_seconds
    from sorting_line_gym import SortingLineVectorEnv

    n = LINES * len(cfg["namespaces"])
    env = SortingLineVectorEnv(
        num_envs=n,
        setup="A",
        namespace=cfg["namespaces"],
        node="attach",
        max_episode_steps=50,
        step_timeout=10.0,
        startup_timeout=60.0,
    )
    rng = np.random.default_rng(1)
    env.reset(seed=1)
    for _ in range(100):
        env.step(rng.integers(0, 10, size=n))
    times = []
    cpu0 = time.process_time()  # all the trainer's threads: rclpy's, Fast DDS's and the env's
    nodes0 = [cpu_seconds(pid) for pid in cfg["node_pids"]]
    t0 = time.perf_counter()
    for _ in range(cfg["round_trips"]):
        actions = rng.integers(0, 10, size=n)
        t = time.perf_counter()
        env.step(actions)
        times.append(time.perf_counter() - t)
    total = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    nodes = [cpu_seconds(pid) - c for pid, c in zip(cfg["node_pids"], nodes0, strict=False)]
    env.close()
    times.sort()
    row = {
        "hosts": len(cfg["namespaces"]),
        "lines": n,
        "round_trips_per_s": round(len(times) / total, 1),
        "line_ticks_per_s": round(n * len(times) / total, 1),
        "trainer_cpu_ms": round(1e3 * cpu / len(times), 3),
        "p50_ms": round(1e3 * times[len(times) // 2], 3),
        "p99_ms": round(1e3 * times[int(len(times) * 0.99)], 3),
    }
    if nodes:  # nodes on this machine (not --attach)
        row["node_cpu_ms"] = round(1e3 * sum(nodes) / len(nodes) / len(times), 3)
    return row


def soak(cfg: dict) -> dict:
    """In the trainer host: benches/soak.py's soak over the nodes of ``cfg["namespaces"]``."""
    from soak import report, run_soak

    r = run_soak(
        cfg["ticks"],
        lines=LINES * len(cfg["namespaces"]),
        setup="A",
        seed=11,
        window=25_000,
        namespace=cfg["namespaces"],
        node="attach",
        step_timeout=10.0,
        show_progress=False,
    )
    print(report(r), file=sys.stderr, flush=True)
    return {
        "ticks": r.ticks,
        "lines": r.config["lines"],
        "hosts": len(cfg["namespaces"]),
        "lost": r.lost,
        "misaligned": r.misaligned,
        "values_compared": r.verified,
        "mismatched": r.mismatched,
        "seconds": round(r.seconds, 1),
        "line_ticks_per_s": round(r.ticks / max(r.seconds, 1e-9), 1),
        "ok": r.ok(),
    }


def ros_env(**values: str) -> dict[str, str]:
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY")
    }
    env.setdefault("ROS_DOMAIN_ID", "93")
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(ROOT / "launch_scripts" / "fastdds_profile.xml"))
    env.update(values, PYTHONUNBUFFERED="1")
    return env


def on_hosts(count: int, role: str, cfg: dict, log_dir: Path) -> dict:
    """Builds ``count`` node hosts and a trainer host, runs ``role`` in the trainer, tears down."""
    from support import netns_hosts
    from support import ros_harness as h

    names = [f"h{i + 1}" for i in range(count)]
    env = ros_env(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", SORTING_LINE_BIN=str(h.node_binary()))
    with netns_hosts.Hosts([*names, "trainer"]) as hosts:
        namespaces = [f"/{name}/plant" for name in names]
        pids = []
        for name, ns in zip(names, namespaces, strict=False):
            log = open(log_dir / f"node_{role}_{count}_{name}.log", "wb")
            pids += [
                hosts.popen(
                    name,
                    [
                        str(h.node_binary()),
                        "node",
                        "--setup",
                        "A",
                        "--lines",
                        str(LINES),
                        "--max-steps",
                        "50",
                        "--ros-args",
                        "-r",
                        f"__ns:={ns}",
                    ],
                    env=env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                ).pid
            ]
        cfg = dict(cfg, namespaces=namespaces, node_pids=pids)
        return run_role(hosts.argv("trainer", role_argv(role, cfg)), env, f"{role} on {count} hosts")


def on_attached(count: int, role: str, cfg: dict, namespaces: list[str]) -> dict:
    """Runs ``role`` in a process of its own over the first ``count`` of the running nodes
    ``namespaces`` (--attach), in this process's ROS environment."""
    cfg = dict(cfg, namespaces=namespaces[:count], node_pids=[])
    return run_role(role_argv(role, cfg), dict(os.environ, PYTHONUNBUFFERED="1"), f"{role} over {namespaces[:count]}")


def role_argv(role: str, cfg: dict) -> list[str]:
    return [sys.executable, os.path.abspath(__file__), "--role", role, json.dumps(cfg)]


def run_role(argv: list[str], env: dict[str, str], what: str) -> dict:
    """Runs a role's process and returns the row it prints last; its stderr is passed on."""
    r = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=3600)
    if r.returncode != 0:
        raise SystemExit(f"{what} failed ({r.returncode}):\n{r.stderr[-4000:]}")
    if r.stderr.strip():
        print(r.stderr.strip(), file=sys.stderr, flush=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hosts = [r["hosts"] for r in rows]
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.4))
    a.bar([str(x) for x in hosts], [r["round_trips_per_s"] for r in rows], color="#4c72b0")
    a.set_xlabel("hosts (16 lines each)")
    a.set_ylabel("round trips/s")
    a.set_title("one vector env over K hosts")
    b.plot(hosts, [r["p50_ms"] for r in rows], "o-", label="p50")
    b.plot(hosts, [r["p99_ms"] for r in rows], "s--", label="p99")
    b.set_xticks(hosts)
    b.set_xlabel("hosts (16 lines each)")
    b.set_ylabel("round trip, ms")
    b.legend()
    b.set_title("latency of one step (all hosts)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    if path.suffix == ".png":
        fig.savefig(path.with_suffix(".svg"))


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--role", help=argparse.SUPPRESS)
    p.add_argument("cfg", nargs="?", help=argparse.SUPPRESS)
    p.add_argument("--hosts", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--round-trips", type=int, default=2000)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--soak-ticks", type=int, default=100_000)
    p.add_argument("--soak-hosts", type=int, default=3)
    p.add_argument("--json", type=Path)
    p.add_argument("--plot", type=Path)
    p.add_argument("--logs", type=Path, default=Path("/tmp/sorting_line_multihost"))
    p.add_argument(
        "--attach",
        nargs="+",
        metavar="NS",
        help="measure over running nodes of these namespaces, 16 lines each, in this ROS environment, "
        "instead of making network namespaces (see below)",
    )
    return p


def _runner(args):
    """run(count, role, cfg): a role's process over ``count`` nodes, --attach's or network namespaces'."""
    from support import netns_hosts

    if args.attach:
        most = max(args.hosts + ([args.soak_hosts] if args.soak_ticks > 0 else []))
        if most > len(args.attach):
            sys.exit(f"multihost.py: --hosts/--soak-hosts ask for {most} nodes, --attach names {len(args.attach)}")
        return lambda count, role, cfg: on_attached(count, role, cfg, args.attach)
    if netns_hosts.problem():
        sys.exit(f"multihost.py: {netns_hosts.problem()}")
    args.logs.mkdir(parents=True, exist_ok=True)
    return lambda count, role, cfg: on_hosts(count, role, cfg, args.logs)


def _scaling(run, args) -> list[dict]:
    """Each host count measured once per round; each figure the median of its rounds (the rounds
    swing with the machine's load)."""
    runs: dict[int, list[dict]] = {k: [] for k in args.hosts}
    for round_ in range(args.rounds):
        for k in args.hosts:
            row = run(k, "measure", {"round_trips": args.round_trips})
            runs[k].append(row)
            print(f"round {round_ + 1}, {k} host(s): {row}", file=sys.stderr, flush=True)
    rows = []
    for k in args.hosts:
        row = {key: statistics.median(r[key] for r in runs[k]) for key in runs[k][0] if key not in ("hosts", "lines")}
        row.setdefault("node_cpu_ms", None)  # not measured for --attach
        rows.append(dict(row, hosts=k, lines=runs[k][0]["lines"], rounds=[r["p50_ms"] for r in runs[k]]))
    return rows


def _print_scaling(rows: list[dict]) -> None:
    print(
        "\n| hosts | lines | round trips/s | line-ticks/s | p50 ms | p99 ms | trainer CPU ms per round trip |"
        " each node's CPU ms per round trip | p50 of each round (ms) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        node = "n/a" if r["node_cpu_ms"] is None else f"{r['node_cpu_ms']:.2f}"
        print(
            f"| {r['hosts']} | {r['lines']} | {r['round_trips_per_s']:,.0f} | {r['line_ticks_per_s']:,.0f} | "
            f"{r['p50_ms']:.2f} | {r['p99_ms']:.2f} | {r['trainer_cpu_ms']:.2f} | "
            f"{node} | {', '.join(f'{x:.2f}' for x in r['rounds'])} |"
        )
    by = {r["hosts"]: r for r in rows}
    if 1 in by and max(by) > 1:
        ratio = by[max(by)]["p50_ms"] / by[1]["p50_ms"]
        print(f"\n{max(by)} hosts / 1 host, p50 round trip: {ratio:.2f}x (target <= 1.5x)")


def main() -> int:
    args = _parser().parse_args()
    if args.role:
        print(json.dumps({"measure": measure, "soak": soak}[args.role](json.loads(args.cfg))))
        return 0

    from node_lockstep import loadavg

    run = _runner(args)
    print(f"load before: {loadavg()}", flush=True)
    rows = _scaling(run, args)
    _print_scaling(rows)
    result = {"scaling": rows, "load_after_scaling": loadavg()}
    ok = True
    if args.soak_ticks > 0:
        s = run(args.soak_hosts, "soak", {"ticks": args.soak_ticks})
        print(
            f"\nsoak: {s['ticks']:,} line-ticks over {s['hosts']} hosts ({s['lines']} lines): lost {s['lost']}, "
            f"misaligned {s['misaligned']}, values compared with the library {s['values_compared']:,}, "
            f"mismatched {s['mismatched']}; {s['line_ticks_per_s']:,.0f} line-ticks/s"
        )
        result["soak"] = s
        ok = s["ok"]
    print(f"load after: {loadavg()}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))
    if args.plot:
        plot(rows, args.plot)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
