#!/usr/bin/env python3
"""Who discovers whom when many DDS participants share one host and domain: N `sorting_line node`
processes (RustDDS) and M rclpy client processes (Fast DDS), each client counting, after a wait,
whether it has matched what a bridge needs of every node: the `state` writer, a reader of
`cmd/speed` and the `reset` service (request reader and reply writer), and how soon.

Printed: each process's DDS participant id (from its SPDP unicast port, `ss -uanp`: port = 7410 +
250 * domain + 2 * id), and for each client the nodes it sees and does not see. This is how the
many-envs-per-host failures were traced to their cause (docs/many-envs.md).

    .venv/bin/python benches/discovery.py --nodes 16 --clients 1            # SyncVectorEnv(16 spawned envs)
    .venv/bin/python benches/discovery.py --nodes 16 --clients 16 --pairs   # 16 worker processes
    .venv/bin/python benches/discovery.py --nodes 1 --clients 20 --order nodes-first

Runs itself in a loopback-only network namespace (ros_harness.run_isolated) on --domain (default 93).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
from sorting_line_gym.line.topics import RESET, SPEED_CMD, STATE  # noqa: E402
from support import ros_harness as h  # noqa: E402

CLIENT = r"""
import json, os, sys, time
import rclpy
from sorting_line_interfaces.msg import SpeedCommand
from sorting_line_interfaces.srv import ResetLine
rclpy.init()
node = rclpy.create_node(f"probe_client_{os.getpid()}")
spaces = sys.argv[2].split(",")
# What a bridge needs of its node: the state writer, a reader of its commands, the reset service.
pubs = {ns: node.create_publisher(SpeedCommand, f"{ns}/@SPEED_CMD@", 10) for ns in spaces}
resets = {ns: node.create_client(ResetLine, f"{ns}/@RESET@") for ns in spaces}
def seen(ns):
    return [
        node.count_publishers(f"{ns}/@STATE@") > 0,
        pubs[ns].get_subscription_count() > 0,
        resets[ns].service_is_ready(),
    ]
start = time.monotonic()
first = {}
while time.monotonic() - start < float(sys.argv[1]):
    rclpy.spin_once(node, timeout_sec=0.05)
    for ns in spaces:
        if ns not in first and all(seen(ns)):
            first[ns] = round(time.monotonic() - start, 2)
print(json.dumps({ns: {"seen": seen(ns), "after": first.get(ns)} for ns in spaces}), flush=True)
node.destroy_node()
rclpy.shutdown()
"""
# The line's endpoints by the package's names (sorting_line_gym.line.topics).
for _marker, _name in (("@SPEED_CMD@", SPEED_CMD), ("@RESET@", RESET), ("@STATE@", STATE)):
    CLIENT = CLIENT.replace(_marker, _name)


def participant_ids(domain: int) -> dict[int, list[int]]:
    """pid -> DDS participant ids, from the SPDP unicast ports each process has bound."""
    out = subprocess.run(["ss", "-uanpH"], capture_output=True, text=True).stdout
    base = 7410 + 250 * domain
    ids: dict[int, set[int]] = {}
    for line in out.splitlines():
        m = re.search(r":(\d+)\s", line)
        pids = [int(p) for p in re.findall(r"pid=(\d+)", line)]
        if not m:
            continue
        port = int(m.group(1))
        if base <= port < base + 2 * 240 and (port - base) % 2 == 0:
            for p in pids:
                ids.setdefault(p, set()).add((port - base) // 2)
    return {p: sorted(v) for p, v in ids.items()}


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=16)
    ap.add_argument("--clients", type=int, default=1)
    ap.add_argument("--order", choices=["nodes-first", "clients-first"], default="nodes-first")
    ap.add_argument("--wait", type=float, default=8.0, help="seconds each client waits before counting")
    ap.add_argument("--domain", type=int, default=93)
    ap.add_argument("--env", action="append", default=[], help="KEY=VALUE for the clients (repeatable)")
    return ap


def _start_nodes(names: list[str], logs: Path, nodes: list) -> None:
    for i, ns in enumerate(names):
        log = open(logs / f"node{i}.log", "wb")
        argv = [str(h.node_binary()), "node", "--ros-args", "-r", f"__ns:={ns}"]
        nodes.append(subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT))
        time.sleep(0.05)


def _start_clients(args, topics: str, client_env: dict, clients: list) -> None:
    for _ in range(args.clients):
        argv = [sys.executable, "-c", CLIENT, str(args.wait), topics]
        clients.append(subprocess.Popen(argv, stdout=subprocess.PIPE, text=True, env=client_env))
        time.sleep(0.05)


def _report(names: list[str], nodes: list, clients: list, results: list, ids: dict) -> None:
    print("node participant ids:  ", [ids.get(n.pid, ["?"])[0] for n in nodes])
    print("client participant ids:", [ids.get(c.pid, ["?"])[0] for c in clients])
    total = 0
    for c, seen in zip(clients, results, strict=False):
        missing = [i for i, ns in enumerate(names) if not all(seen[ns]["seen"])]
        total += len(names) - len(missing)
        cid = ids.get(c.pid, ["?"])[0]
        slowest = max((v["after"] for v in seen.values() if v["after"] is not None), default=None)
        detail = {ids.get(nodes[i].pid, ["?"])[0]: seen[names[i]]["seen"] for i in missing}
        print(
            f"client id {cid}: sees {len(names) - len(missing)}/{len(names)} nodes completely (slowest after "
            f"{slowest} s); incomplete (node id: [state writer, command reader, reset service]): {detail}"
        )
    print(f"pairs discovered: {total}/{len(names) * len(clients)}")


def main() -> None:
    args = _parser().parse_args()
    h.run_isolated(__file__)
    os.environ["ROS_DOMAIN_ID"] = str(args.domain)
    h.ros_environment()
    client_env = dict(os.environ, **dict(kv.split("=", 1) for kv in args.env))
    logs = Path(tempfile.mkdtemp(prefix="discovery_"))
    names = [f"/probe/n{i}" for i in range(args.nodes)]
    nodes, clients = [], []
    t0 = time.monotonic()
    start = [
        lambda: _start_nodes(names, logs, nodes),
        lambda: _start_clients(args, ",".join(names), client_env, clients),
    ]
    for step in reversed(start) if args.order == "clients-first" else start:
        step()
    time.sleep(args.wait / 2)  # every process has its participant by now
    ids = participant_ids(args.domain)
    results = [json.loads(c.communicate(timeout=args.wait + 30)[0]) for c in clients]
    for n in nodes:
        n.terminate()
    for n in nodes:
        n.wait(10)
    print(
        f"{args.nodes} nodes, {args.clients} clients ({args.order}), wait {args.wait:g} s, domain {args.domain}; "
        f"{h.machine_conditions()}; took {time.monotonic() - t0:.1f} s"
    )
    _report(names, nodes, clients, results, ids)


if __name__ == "__main__":
    main()
