"""The node follows ROS 2 Jazzy's discovery environment like an rcl node: seen from another "host"
under the default range (SUBNET) and through ROS_STATIC_PEERS, not seen under LOCALHOST (nor under
the deprecated ROS_LOCALHOST_ONLY=1). Under LOCALHOST, a ros2 daemon and the node find each other
whatever participant ids they hold.

The two hosts are network namespaces this test makes, joined by one veth pair whose two addresses
exist only inside them (tests/python/support/netns_hosts.py). An rclpy node next to ours, under the default
range, is the control: the probes must see it, so a node they do not see is the node's doing.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys

import pytest

from support import netns_hosts, participant_ids
from support import ros_harness as h
from support.ros2_output import poll

# Polls the graph of its own participant until it has seen every name of `want` and at least
# MIN s have passed (a name that is not supposed to appear gets that long), or MAX s; prints
# {name: seconds until first seen}.
PROBE = """
import json, sys, time
import rclpy
rclpy.init()
node = rclpy.create_node("probe")
lo, hi = float(sys.argv[1]), float(sys.argv[2])
want, watch = set(sys.argv[3].split(",")), set(sys.argv[4].split(","))
t0, seen = time.monotonic(), {}
while True:
    rclpy.spin_once(node, timeout_sec=0.05)
    for name, _ in node.get_node_names_and_namespaces():
        if name in watch and name not in seen:
            seen[name] = round(time.monotonic() - t0, 2)
    t = time.monotonic() - t0
    if t > hi or (t > lo and want <= set(seen)):
        break
print(json.dumps(seen))
"""

# An rclpy node that does nothing but exist (and spin, so it answers discovery).
REFERENCE = """
import sys, time
import rclpy
rclpy.init()
node = rclpy.create_node(sys.argv[1])
t0 = time.monotonic()
while time.monotonic() - t0 < float(sys.argv[2]):
    rclpy.spin_once(node, timeout_sec=0.1)
"""

DISCOVERY_VARS = ["ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY"]


def ros_env(**values: str) -> dict[str, str]:
    """This process's environment with the discovery variables replaced by `values` only."""
    env = {k: v for k, v in os.environ.items() if k not in DISCOVERY_VARS}
    env.update(values)
    return env


@pytest.mark.skipif(netns_hosts.problem() is not None, reason=f"two hosts: {netns_hosts.problem()}")
def start_nodes_on_a(hosts, names: dict[str, str], tmp_path) -> dict[str, subprocess.Popen]:
    """The node on host a three times: default discovery range, LOCALHOST, ROS_LOCALHOST_ONLY=1."""
    nodes = {}
    node_envs = {
        "default": ros_env(),
        "localhost": ros_env(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"),
        "legacy": ros_env(ROS_LOCALHOST_ONLY="1"),
    }
    for key, env in node_envs.items():
        log = open(tmp_path / f"{key}.log", "wb")
        argv = [str(h.node_binary()), "node", "--ros-args", "-r", f"__node:={names[key]}"]
        nodes[key] = hosts.popen("a", argv, env=env, stdout=log, stderr=subprocess.STDOUT)
    return nodes


def stop_with_sigint(nodes: dict[str, subprocess.Popen]) -> dict[str, int | str]:
    """SIGINT to every node; each one's exit code (or how it had exited before)."""
    codes = {}
    for key, p in nodes.items():
        running = p.poll() is None
        p.send_signal(signal.SIGINT)
        codes[key] = p.wait(timeout=10) if running else f"exited early with {p.returncode}"
    return codes


def test_discovery_range_and_static_peers_across_a_veth_pair(tmp_path):
    tag = f"{os.getpid()}"
    names = {
        "default": f"sl_default_{tag}",
        "localhost": f"sl_localhost_{tag}",
        "legacy": f"sl_localhost_only_{tag}",
        "reference": f"rclpy_default_{tag}",
    }
    with netns_hosts.TwoHosts() as hosts:
        nodes = start_nodes_on_a(hosts, names, tmp_path)
        hosts.popen("a", [sys.executable, "-c", REFERENCE, names["reference"], "30"], env=ros_env())

        def probe(env: dict[str, str], want: list[str]) -> subprocess.Popen:
            return hosts.popen(
                "b",
                [sys.executable, "-c", PROBE, "5", "12", ",".join(want), ",".join(names.values())],
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )

        a = hosts.address("a")
        probes = {
            "SUBNET": probe(ros_env(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET"), [names["default"], names["reference"]]),
            f"LOCALHOST, ROS_STATIC_PEERS={a}": probe(
                ros_env(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_STATIC_PEERS=a),
                [names["default"], names["reference"]],
            ),
        }
        seen = {}
        for what, p in probes.items():
            out, err = p.communicate(timeout=40)
            assert p.returncode == 0, f"probe ({what}) failed:\n{out}\n{err}"
            seen[what] = json.loads(out.strip().splitlines()[-1])
        codes = stop_with_sigint(nodes)
    logs = {key: (tmp_path / f"{key}.log").read_text(errors="replace") for key in nodes}
    report = f"seen from the other host (s until first seen): {json.dumps(seen, indent=1)}\nnode logs: {logs}"

    for what, got in seen.items():
        # The control: rclpy under the default range reaches the probe, so the network is fine.
        assert names["reference"] in got, f"{what}: the rclpy control node was not seen\n{report}"
    assert names["default"] in seen["SUBNET"], f"the node (default range) is not seen under SUBNET\n{report}"
    assert names["default"] in seen[f"LOCALHOST, ROS_STATIC_PEERS={a}"], (
        f"the node is not seen by a peer that names it in ROS_STATIC_PEERS\n{report}"
    )
    for what, got in seen.items():
        assert names["localhost"] not in got, f"{what}: the LOCALHOST node was seen from another host\n{report}"
        assert names["legacy"] not in got, f"{what}: the ROS_LOCALHOST_ONLY=1 node was seen from another host\n{report}"
    assert codes == {key: 0 for key in nodes}, f"exit codes after SIGINT: {codes}\n{report}"


def test_a_node_and_a_daemon_beyond_the_first_participant_ids_find_each_other(ros2, start_node, namespace):
    """Under LOCALHOST discovery each participant announces itself by unicast to the discovery port
    of each participant id (tests/python/support/participant_ids.py). Fast DDS reaches ids up to 31; RustDDS
    reached 0..11 only, so a ros2 daemon that took id 12 or more (started while a dozen participants
    ran) never heard of a node beyond 31, and `ros2 node list` lacked it for good (one of two nodes in a
    CI run). Now the node announces itself to every id. Here sockets hold ids 0..39 of a domain of
    this test's own, so its daemon and its node both take 40 or more."""
    domain = 100 + (int(ros2.env["ROS_DOMAIN_ID"]) - 100 + 53) % 100
    cli = dataclasses.replace(ros2, env=dict(ros2.env, ROS_DOMAIN_ID=str(domain)))
    held = participant_ids.hold(domain, 40)
    try:
        cli.run("daemon", "start", timeout=30)
        ns = namespace("beyond")
        node = start_node("--ros-args", "-r", f"__ns:={ns}", env={"ROS_DOMAIN_ID": str(domain)})

        def ids() -> str:
            return f"participant ids of domain {domain}: {participant_ids.holders(domain, range(40, 120))}"

        fqn = f"{ns}/sorting_line"
        poll(cli, ["node", "list"], lambda out: fqn in out.split(), f"node {fqn}", timeout=20.0, context=ids)
        # What makes this test mean something: both are beyond Fast DDS's reach and ours of before.
        held_now = participant_ids.holders(domain)
        node_ids = [i for i, who in held_now.items() if who.endswith(f" {node.pid}")]
        others = {i: who for i, who in held_now.items() if not who.endswith((f" {node.pid}", f" {os.getpid()}"))}
        assert node_ids and min(node_ids) >= 40 and others and min(others) >= 40, (node_ids, others)
    finally:
        cli.run("daemon", "stop", timeout=30, check=False)
        for s in held:
            s.close()
