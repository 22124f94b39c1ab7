"""The node's UDP ports under malformed and mutated RTPS datagrams (docs/security.md).

A real node (two basic lock-step lines) and a real rclpy client (the observed one, a participant of
its own, driving line 1) exchange discovery and line traffic, captured on `lo` of the test's own
network namespace; then a seeded fuzzer (rtps_wire.Fuzzer) sends datagrams of every kind to the
node's discovery and user ports on 127.0.0.1 while another rclpy client keeps stepping line 0. What must hold: the
node never panics or aborts (it runs; its log has no panic), its line answers during and after the
fuzzing with the library's trajectory (`sorting_line trace`), and its RSS stays bounded. The node
runs under an address-space limit (NODE_ADDRESS_SPACE), so an allocation run wild aborts the node,
which the test reports, instead of exhausting the machine.

Size: SORTING_LINE_WIRE_FUZZ_DATAGRAMS datagrams (CI: 50,000) within SORTING_LINE_WIRE_FUZZ_SECONDS
(CI: 15); SORTING_LINE_WIRE_FUZZ_SEED picks the datagrams (a failure names its seed). The full run
is launch_scripts/reliability.sh (docs/reliability.md); its figures are in docs/security.md, "The wire fuzz".
"""

from __future__ import annotations

import collections
import os
import resource
import socket
import time
from types import SimpleNamespace

import pytest

from support import ros_harness as h
from support import rtps_wire as w
from support.line_client import LineClient
from support.ros_harness import ns_args
from support.waits import wait_until

DATAGRAMS = int(os.environ.get("SORTING_LINE_WIRE_FUZZ_DATAGRAMS", "50000"))
SECONDS = float(os.environ.get("SORTING_LINE_WIRE_FUZZ_SECONDS", "15"))
SEED = int(os.environ.get("SORTING_LINE_WIRE_FUZZ_SEED", "35"))
#: The node's address-space limit: far above its virtual memory (216 MB idle, measured) plus the
#: reassembly budget, far below what a 4 GB sample or a 2^62-entry list would take.
NODE_ADDRESS_SPACE = 3 << 30
#: RustDDS's budget for incomplete fragmented samples (MAX_REASSEMBLY_BYTES, rustdds patch 10).
REASSEMBLY_BUDGET_MB = 256  # MiB, the unit of ros_harness.rss_mb
#: Datagrams between two steps of the line (the line answers while being fuzzed).
BURST = 250
ACTIONS = [3, 7, 1, 9, 4, 4, 0, 8, 2, 6]


def start_limited_node(start_node, ns: str):
    """Two basic lock-step lines (line_0 for the stepping client, line_1 for the observed one) in a
    node whose address space is limited to NODE_ADDRESS_SPACE from its start."""
    node = start_node(*h.SETUP_FLAGS["A"], "--lines", "2", "--max-steps", "1000000", *ns_args(ns))
    resource.prlimit(node.pid, resource.RLIMIT_AS, (NODE_ADDRESS_SPACE, NODE_ADDRESS_SPACE))
    return node


def node_died(node) -> str | None:
    """Why the node is not well: exited (with its code and log), or panicked while still running."""
    if not node.running():
        return f"the node died (seed {SEED})\n{node.describe()}"
    if "panicked" in node.log():
        return f"the node panicked (seed {SEED})\n{node.describe()}"
    return None


def bound_ports(node, domain: int, timeout: float = 20.0) -> dict[int, str]:
    """The node's UDP ports once it has bound its discovery and its user port. start_node returns
    as soon as the process runs; the node binds one port after the other as its participant starts
    (a fresh run under load once read the discovery port alone)."""
    seen: dict[int, str] = {}

    def both_bound() -> dict[int, str] | None:
        seen.clear()
        seen.update(w.node_udp_ports(node.pid, domain))
        return dict(seen) if {"discovery", "user"} <= set(seen.values()) else None

    return wait_until(
        both_bound,
        timeout,
        "the node to bind its discovery and its user port",
        context=lambda: f"ports bound: {seen}",
        abort=lambda: node_died(node),
    )


def connect_and_capture(client, node, domain: int):
    """The client connects and resets; the datagrams to and from the node meanwhile are the corpus."""
    ports = bound_ports(node, domain)
    with w.LoopbackCapture(set(ports)) as capture:
        client.wait_connected()
        client.reset(1)
        for a in ACTIONS[:3]:
            client.act(a)
        h_time = time.monotonic()
        while time.monotonic() - h_time < 1.0:  # a periodic SPDP/HEARTBEAT round more
            client.session.spin_for(0.1)
    targets = sorted(p for p, name in ports.items() if name != "other")
    return targets, list(capture.datagrams)


@pytest.fixture
def target(start_node, client_factory, namespace):
    """A limited node; the corpus captured between it and an observed client (a participant of its
    own, an rclpy context of its own); the stepping client, another participant, connected.

    The fuzzer speaks with the observed client's GUIDs, never the stepping client's: without DDS
    Security, anyone may claim any GUID prefix, and a GAP in a client's name makes the node drop
    that client's commands (RTPS says so), while a replayed command whose flipped bit only raised
    its sequence number is that client's command, obeyed as such (a reset in the middle of the
    stepping client's episode failed CI once). So the observed client drives a line of its own, and
    what must hold is that nobody else is harmed."""
    ns = namespace("wire")
    node = start_limited_node(start_node, ns)
    session = h.RosSession()
    observed_node = session.make_node("wire_observed")  # a name of its own: the sessions count apart
    observed = LineClient(session, f"{ns}/line_1", "basic", node=observed_node, node_proc=node)
    try:
        targets, corpus = connect_and_capture(observed, node, int(os.environ["ROS_DOMAIN_ID"]))
        matched = w.writer_guids(corpus, set(targets))
        client = client_factory(f"{ns}/line_0", "basic", node_proc=node)
        client.wait_connected()
        yield SimpleNamespace(node=node, client=client, targets=targets, corpus=corpus, matched=matched)
    finally:
        observed.destroy()
        session.destroy_node(observed_node)
        session.shutdown()


def stepped_episode_matches_library(client, seed: int, between=lambda: None) -> None:
    """Resets with `seed`, steps ACTIONS (calling `between()` before each step), and compares every
    state with the library's trajectory."""
    want = h.run_trace("A", "basic", seed, ACTIONS)
    client.reset(seed)
    for k, action in enumerate(ACTIONS, start=1):
        between()
        state = client.act(action, timeout=10.0)
        # Episodes are counted since the node started, the trace's since its seeded reset.
        got, expected = h.state_step_view(state), h.trace_step_view(want[k])
        assert {**got, "episode": 0} == {**expected, "episode": 0}, f"seed {seed}, step {k}"


def test_fuzzed_datagrams_leave_the_node_answering_and_bounded(target, tmp_path):
    node, client, targets, corpus, matched = target.node, target.client, target.targets, target.corpus, target.matched
    assert corpus, "nothing captured between the node and the observed client"
    rss_before, dropped_before = h.rss_mb(node.pid), w.udp_receive_buffer_errors()
    fuzzer = w.Fuzzer(SEED, corpus, matched)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setblocking(False)
    sent, started = 0, time.monotonic()
    per_port: dict[int, int] = {}

    recent = collections.deque(maxlen=2 * BURST)  # what a dead node got last: kept for replay

    def burst():
        nonlocal sent
        for _ in range(BURST):
            if sent >= DATAGRAMS or time.monotonic() - started > SECONDS:
                break
            kind, datagram = fuzzer.next()
            port = targets[sent % len(targets)]
            w.send_to_node(sock, port, datagram)
            recent.append((sent, kind, port, datagram))
            per_port[port] = per_port.get(port, 0) + 1
            sent += 1
        assert not node_died(node), node_died(node)

    episode = 0
    try:
        while sent < DATAGRAMS and time.monotonic() - started < SECONDS:
            episode += 1
            stepped_episode_matches_library(client, 100 + episode, burst)
    except AssertionError as e:
        if node_died(node):
            kept = tmp_path / "last_datagrams.txt"
            kept.write_text("".join(f"{i} {kind} {port} {d.hex()}\n" for i, kind, port, d in recent))
            raise AssertionError(f"{node_died(node)}\nthe last datagrams sent (index kind port hex): {kept}") from e
        raise
    elapsed = time.monotonic() - started
    rss_after = h.rss_mb(node.pid)
    print(
        f"\nwire fuzz (seed {SEED}): {sent} datagrams in {elapsed:.1f} s ({sent / elapsed:.0f}/s) to ports {per_port}; "
        f"by kind {dict(sorted(fuzzer.counts.items()))}; corpus {len(corpus)} captured datagrams, "
        f"{len(matched)} matched writers; {episode} episodes stepped during; "
        f"{w.udp_receive_buffer_errors() - dropped_before} datagrams dropped by full receive buffers; "
        f"node RSS {rss_before:.1f} -> {rss_after:.1f} MB (max {h.proc_status_mb(node.pid, 'VmHWM'):.1f}); "
        f"{h.machine_conditions()}"
    )
    stepped_episode_matches_library(client, 7)
    assert not node_died(node), node_died(node)
    # Bounded by design: what RustDDS may hold of incomplete fragmented samples (the fuzz's DATA_FRAGs
    # fill it), and slack for its caches; not a figure.
    assert rss_after < rss_before + REASSEMBLY_BUDGET_MB + 64, f"node RSS {rss_before:.1f} -> {rss_after:.1f} MB"
    sock.close()


def test_datagrams_that_took_the_node_down_are_survived(target):
    """Regression: a DATA_FRAG announcing a 4 GB sample, and HEARTBEATs and GAPs spanning 2^62
    sequence numbers from writers the node matched (rustdds patch 10, vendor/README.md)."""
    node, client, targets, corpus, matched = target.node, target.client, target.targets, target.corpus, target.matched
    assert matched, "no HEARTBEAT of a matched writer captured"
    rss_before = h.rss_mb(node.pid)
    cases = w.regression_datagrams(corpus[0][1][8:20], matched)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for name, datagram in cases:
            for target in targets:
                w.send_to_node(sock, target, datagram)
            client.session.spin_for(0.3)
            assert not node_died(node), f"after {name} (and the cases before it): {node_died(node)}"
    stepped_episode_matches_library(client, 11)
    rss_after = h.rss_mb(node.pid)
    print(f"\n{len(cases)} regression datagrams; node RSS {rss_before:.1f} -> {rss_after:.1f} MB")
    assert not node_died(node), node_died(node)
    assert rss_after < rss_before + 64, f"node RSS {rss_before:.1f} -> {rss_after:.1f} MB"
