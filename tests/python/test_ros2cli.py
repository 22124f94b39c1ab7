"""The node as a ROS 2 Jazzy user meets it: the real `ros2` command line and `ros2 launch`
(tests/python/support/ros2_cli.py says where they come from), not our own clients.

Every command runs with a timeout. Graph queries (`node list`, `topic list`, `topic info`) go
through the ros2 daemon (the `ros2_daemon` fixture runs it in this test network namespace for this
module) and are repeated until the answer appears or their time is up, because
discovery is asynchronous for every ROS client. Checks on the answers are exact.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time

import pytest
import yaml

from support import participant_ids
from support import ros_harness as h
from support.ros2_output import poll, yaml_docs
from support.ros_harness import LINE_TYPES
from support.waits import wait_until

pytestmark = pytest.mark.usefixtures("ros2_daemon")

RATE = 10.0  # ticks per second of the realtime lines here
REPORTS = 3  # rates `ros2 topic hz` reports (one a second) before the last one is judged
NODE_TYPES = {"/clock": "rosgraph_msgs/msg/Clock", "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}
PARAMETERS = [
    "action_penalty",
    "evolution_file",
    "foxglove",
    "input",
    "lines",
    "max_steps",
    "mode",
    "obs_noise",
    "rate",
    "seed",
    "setup",
    "threshold",
    "tick_period",
    "use_sim_time",
    "variant",
]
HASH = re.compile(r"RIHS01_[0-9a-f]{64}")


class Line:
    """A node started for a module of tests: namespace, full node name, process."""

    def __init__(self, ns: str, node: h.NodeProcess, node_name: str = "sorting_line"):
        self.ns, self.node = ns, node
        self.fqn = f"{ns}/{node_name}"

    def name(self, rel: str) -> str:
        return h.join_ns(self.ns, rel)


@pytest.fixture(scope="module")
def rt_line(tmp_path_factory):
    """One advanced realtime line at RATE Hz for the read-only checks (it never gets a command)."""
    ns = f"/cli_rt_{os.getpid()}"
    log = tmp_path_factory.mktemp("rt_line") / "node.log"
    node = h.NodeProcess(
        [
            "--variant",
            "advanced",
            "--mode",
            "realtime",
            "--rate",
            str(RATE),
            "--seed",
            "5",
            "--max-steps",
            "1000000",
            "--ros-args",
            "-r",
            f"__ns:={ns}",
        ],
        log,
    )
    line = Line(ns, node)
    yield line
    alive = node.running()
    code = node.stop(signal.SIGINT, timeout=5.0)
    assert alive and code == 0, f"the realtime node exited with {code} (alive at the end: {alive})\n{node.describe()}"


# ------------------------------------------------------------------------------------------
# Graph: node, topics, interfaces


def node_info_sections(info: str) -> dict[str, dict[str, str]]:
    """`ros2 node info` parsed: section ("Subscribers", ...) -> {name: types}."""
    section: dict[str, dict[str, str]] = {}
    current = None
    for line in info.splitlines():
        if line.startswith("  ") and not line.startswith("    ") and line.strip().endswith(":"):
            current = line.strip()[:-1]
            section[current] = {}
        elif current and line.startswith("    "):
            name, _, types = line.strip().partition(": ")
            section[current][name] = types
    return section


def test_node_list_and_info(ros2, rt_line):
    poll(ros2, ["node", "list"], lambda out: rt_line.fqn in out.split(), f"node {rt_line.fqn}")
    published = ["input", "belt/occupancy", "sensors/ratio", "state", "events/reset"]
    parameter_services = ["describe_parameters", "get_parameters", "list_parameters", "set_parameters"]
    expected = {
        "Subscribers": [rt_line.name("cmd/speed"), rt_line.name("cmd/sort_mode")],
        "Publishers": [rt_line.name(rel) for rel in published] + list(NODE_TYPES),
        "Service Servers": [rt_line.name("reset")] + [f"{rt_line.fqn}/{s}" for s in parameter_services],
    }

    def complete(out):
        found = node_info_sections(out)
        return all(name in found.get(kind, {}) for kind, names in expected.items() for name in names)

    info = poll(ros2, ["node", "info", rt_line.fqn], complete, "the node's endpoints")
    section = node_info_sections(info)
    subs, pubs, servers = section["Subscribers"], section["Publishers"], section["Service Servers"]
    for rel in ["cmd/speed", "cmd/sort_mode"]:
        assert subs.get(rt_line.name(rel)) == LINE_TYPES[rel], f"{rel} in\n{info}"
    for rel in published:
        assert pubs.get(rt_line.name(rel)) == LINE_TYPES[rel], f"{rel} in\n{info}"
    for topic, type_name in NODE_TYPES.items():
        assert pubs.get(topic) == type_name, f"{topic} (exactly one type) in\n{info}"
    # Nothing of the node announces /clock with another type (a subscription included).
    assert subs.get("/clock", NODE_TYPES["/clock"]) == NODE_TYPES["/clock"], f"/clock subscription in\n{info}"
    assert servers.get(rt_line.name("reset")) == "sorting_line_interfaces/srv/ResetLine", info
    for srv in parameter_services:
        assert servers[f"{rt_line.fqn}/{srv}"].startswith("rcl_interfaces/srv/"), f"{srv} in\n{info}"


def test_topic_list_with_types(ros2, rt_line):
    want = {rt_line.name(rel): f"[{t}]" for rel, t in LINE_TYPES.items()}
    want.update({topic: f"[{t}]" for topic, t in NODE_TYPES.items()})

    def listed(out):
        return dict(line.split(" ", 1) for line in out.splitlines() if " " in line)

    out = poll(ros2, ["topic", "list", "-t"], lambda out: all(k in listed(out) for k in want), "every topic")
    got = listed(out)
    assert {k: got[k] for k in want} == want, out


def test_interface_show(ros2):
    """Our interface package as the CLI finds it: every field and constant line of the definition, in
    order, and the nested std_msgs/Header resolved (the CLI found the dependency too)."""
    shown = {}
    for name in ["msg/LineState", "srv/ResetLine"]:
        out = ros2.run("interface", "show", f"sorting_line_interfaces/{name}", timeout=20).stdout
        shown[name] = out
        definition = (h.ROOT / "msg" / f"{name}.{name[:3]}").read_text().splitlines()
        fields = [f for f in (re.sub(r"\s*#.*", "", line).strip() for line in definition) if f]
        top = [
            f
            for f in (
                re.sub(r"\s*#.*", "", line).strip() for line in out.splitlines() if not line.startswith(("\t", " "))
            )
            if f
        ]
        assert top == fields, f"{name}:\n{out}"
    assert "\tbuiltin_interfaces/Time stamp" in shown["msg/LineState"], shown["msg/LineState"]
    assert "\tstring frame_id" in shown["msg/LineState"], shown["msg/LineState"]


# ------------------------------------------------------------------------------------------
# Topics: echo, hz, type hashes


def echo_once_each(ros2, topics: list[str]) -> dict[str, dict]:
    """`ros2 topic echo --once` of each topic, all at once (they are independent): topic -> its
    first message as YAML; fails naming every topic without one."""
    procs = {
        t: subprocess.Popen(
            ros2.argv("topic", "echo", "--once", t),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=ros2.env,
            stdin=subprocess.DEVNULL,
        )
        for t in topics
    }
    results, problems = {}, []
    for topic, p in procs.items():
        try:
            out, err = p.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            out, err = p.communicate()
            problems.append(f"{topic}: no message within 30 s\n{out}\n{err}")
            continue
        if p.returncode != 0:
            problems.append(f"{topic}: exit {p.returncode}\n{out}\n{err}")
            continue
        docs = yaml_docs(out)
        if not docs or not isinstance(docs[0], dict):
            problems.append(f"{topic}: no YAML message in\n{out}\n{err}")
            continue
        results[topic] = docs[0]
    assert not problems, "\n\n".join(problems)
    return results


def test_echo_once_every_topic(ros2, rt_line):
    """`ros2 topic echo --once` of each published topic, all at once (they are independent)."""
    topics = [rt_line.name(rel) for rel in ["state", "input", "belt/occupancy", "sensors/ratio"]]
    topics += ["/clock", "/diagnostics"]
    poll(ros2, ["topic", "list"], lambda out: all(t in out.split() for t in topics), "every published topic")
    results = echo_once_each(ros2, topics)
    state = results[rt_line.name("state")]
    keys = "header episode step seed speed mode occupancy reward purity container_a terminated truncated"
    assert set(state) >= set(keys.split()), state
    assert state["seed"] == 5 and state["speed"] == 0.6, state  # nobody commands this line
    assert state["step"] == state["header"]["stamp"]["sec"], state  # first episode: tick k = step k, 1 s a tick
    assert 0.0 <= state["occupancy"] <= 1.0 and state["mode"] in (0, 1, 2), state
    sample = results[rt_line.name("input")]
    assert 0.0 <= sample["quantity"] <= 1.0 and sample["occupancy"] == (sample["amount_a"] + sample["amount_b"]) / 100
    belt = results[rt_line.name("belt/occupancy")]
    assert 0.0 <= belt["occupancy"] <= 1.0 and belt["speed"] == 0.6, belt
    ratio = results[rt_line.name("sensors/ratio")]
    assert ratio["category"] in (0, 1, 2) and ratio["ratio"] >= 0.0, ratio
    for topic in topics[:4]:  # stamped with simulated time: one tick = 1 s here
        stamp = results[topic]["header"]["stamp"]
        assert stamp["nanosec"] == 0 and stamp["sec"] >= 0, (topic, stamp)
    clock = results["/clock"]
    assert set(clock) == {"clock"} and set(clock["clock"]) == {"sec", "nanosec"}, clock
    statuses = {s["hardware_id"]: s for s in results["/diagnostics"]["status"]}
    assert rt_line.ns in statuses, results["/diagnostics"]
    assert {kv["key"] for kv in statuses[rt_line.ns]["values"]} >= {"episodes", "sim_time"}, statuses[rt_line.ns]


def test_topic_hz_in_realtime_mode(ros2, rt_line, tmp_path):
    """`ros2 topic hz` of the realtime state: about RATE (generous bounds; a busy machine is no failure).

    The CLI's output is read until it has reported REPORTS rates, not for a fixed time: its own start
    (the interpreter, discovery of the topic) can take seconds under load before its first report."""
    topic = rt_line.name("state")
    log_path = tmp_path / "hz.log"
    with open(log_path, "w") as log:
        p = subprocess.Popen(
            ros2.argv("topic", "hz", "--window", "20", topic),
            stdout=log,
            stderr=subprocess.STDOUT,
            text=True,
            env=ros2.env,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
    try:
        wait_until(
            lambda: log_path.read_text().count("average rate") >= REPORTS,
            60,
            f"{REPORTS} rates reported by `ros2 topic hz`",
            poll=0.1,
            context=log_path.read_text,
        )
    finally:
        os.killpg(p.pid, signal.SIGINT)
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
            raise AssertionError(f"`ros2 topic hz` did not stop on SIGINT\n{log_path.read_text()}") from None
    out = log_path.read_text()
    rates = [float(x) for x in re.findall(r"average rate: ([0-9.]+)", out)]
    assert len(rates) >= REPORTS, f"{len(rates)} of {REPORTS} rates reported in 60 s:\n{out}"
    assert 0.5 * RATE <= rates[-1] <= 1.5 * RATE, f"rate {rates[-1]} Hz, node ticks at {RATE} Hz:\n{out}"


def endpoint_hashes(info: str) -> list[tuple[str, str, str]]:
    """(node name, endpoint type, type hash) of every endpoint in `ros2 topic info -v` output."""
    blocks = info.split("Node name: ")[1:]
    out = []
    for b in blocks:
        name = b.splitlines()[0].strip()
        kind = re.search(r"Endpoint type: (\w+)", b).group(1)
        type_hash = re.search(r"Topic type hash: (\S+)", b).group(1)
        out.append((name, kind, type_hash))
    return out


def test_type_hashes_equal_rclpy_endpoints(ros2, rt_line, ros, probe):
    """`ros2 topic info -v`: each of the node's endpoints announces the RIHS01 hash an rclpy endpoint
    of the same type announces (publishers and subscriptions, our types and ROS's)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock
    from sorting_line_interfaces.msg import LineState, MaterialRatio, SortModeCommand, SpeedCommand

    # rclpy endpoints opposite the node's: subscriptions to what it publishes, publishers to what it reads.
    subs = [
        probe.create_subscription(LineState, rt_line.name("state"), lambda m: None, 10),
        probe.create_subscription(MaterialRatio, rt_line.name("sensors/ratio"), lambda m: None, 10),
        probe.create_subscription(Clock, "/clock", lambda m: None, 10),
        probe.create_subscription(DiagnosticArray, "/diagnostics", lambda m: None, 10),
    ]
    pubs = [
        probe.create_publisher(SpeedCommand, rt_line.name("cmd/speed"), 10),
        probe.create_publisher(SortModeCommand, rt_line.name("cmd/sort_mode"), 10),
    ]
    ros.spin_for(0.2)
    me = probe.get_name()
    try:
        for topic in [
            rt_line.name("state"),
            rt_line.name("sensors/ratio"),
            "/clock",
            "/diagnostics",
            rt_line.name("cmd/speed"),
            rt_line.name("cmd/sort_mode"),
        ]:
            out = poll(
                ros2,
                ["topic", "info", "-v", topic],
                lambda out: {n for n, _, _ in endpoint_hashes(out)} >= {"sorting_line", me},
                f"the node's and the test's endpoints on {topic}",
            )
            ends = endpoint_hashes(out)
            node_hashes = {hsh for n, _, hsh in ends if n == "sorting_line"}
            rclpy_hashes = {hsh for n, _, hsh in ends if n == me}
            assert len(rclpy_hashes) == 1 and HASH.fullmatch(next(iter(rclpy_hashes))), out
            assert node_hashes == rclpy_hashes, (
                f"{topic}: the node's endpoint announces {sorted(node_hashes)}, rclpy's {sorted(rclpy_hashes)}\n{out}"
            )
    finally:
        for sub in subs:
            probe.destroy_subscription(sub)
        for pub in pubs:
            probe.destroy_publisher(pub)


def test_service_endpoint_type_hashes_equal_rclpy_clients(rt_line, ros, probe):
    """The node's service endpoints (request reader, reply writer) announce the hash rclpy's client
    endpoints of the same service announce. The CLI has no verbose service info, so this asks the
    graph through rclpy, by DDS topic name (rq/...Request, rr/...Reply)."""
    from rcl_interfaces.srv import DescribeParameters, GetParameters
    from sorting_line_interfaces.srv import ResetLine

    services = {
        rt_line.name("reset"): ResetLine,
        f"{rt_line.fqn}/get_parameters": GetParameters,
        f"{rt_line.fqn}/describe_parameters": DescribeParameters,
    }
    clients = [probe.create_client(kind, name) for name, kind in services.items()]
    me, problems = probe.get_name(), []
    try:
        for name in services:
            for dds_topic, role in [(f"rq{name}Request", "subscriptions"), (f"rr{name}Reply", "publishers")]:
                opposite = "publishers" if role == "subscriptions" else "subscriptions"

                def endpoints():
                    node_side = [
                        e
                        for e in getattr(probe, f"get_{role}_info_by_topic")(dds_topic, no_mangle=True)
                        if e.node_name == "sorting_line"
                    ]
                    ours = [
                        e
                        for e in getattr(probe, f"get_{opposite}_info_by_topic")(dds_topic, no_mangle=True)
                        if e.node_name == me
                    ]
                    return (node_side, ours) if node_side and ours else None

                node_side, ours = ros.spin_until(endpoints, 15.0, f"the node's and our endpoints on {dds_topic}")
                want = {str(e.topic_type_hash) for e in ours}
                got = {str(e.topic_type_hash) for e in node_side}
                if got != want or not all(HASH.search(x) for x in want):
                    problems.append(f"{dds_topic}: node {sorted(got)}, rclpy {sorted(want)}")
    finally:
        for c in clients:
            probe.destroy_client(c)
    assert not problems, "\n".join(problems)


# ------------------------------------------------------------------------------------------
# Parameters


def test_param_list_get_dump(ros2, rt_line):
    out = poll(ros2, ["param", "list", rt_line.fqn], lambda out: "rate" in out.split(), "the parameters")
    assert sorted(out.split()[1:] if out.split()[0].endswith(":") else out.split()) == PARAMETERS, out
    got = ros2.run("param", "get", rt_line.fqn, "rate", timeout=20).stdout.strip()
    assert got == f"Double value is: {RATE}", got
    dump = yaml.safe_load(ros2.run("param", "dump", rt_line.fqn, timeout=20).stdout)
    assert dump == {
        rt_line.fqn: {
            "ros__parameters": {
                "action_penalty": 0.0,
                "evolution_file": "",
                "foxglove": "",
                "input": "random",
                "lines": 1,
                "max_steps": 1000000,
                "mode": "realtime",
                "obs_noise": 0.0,
                "rate": RATE,
                "seed": 5,
                "setup": "",
                "threshold": 0.7,
                "tick_period": 1.0,
                "use_sim_time": False,
                "variant": "advanced",
            }
        }
    }, dump


def describe(ros2, node: str, names: list[str]) -> dict[str, dict[str, str]]:
    """`ros2 param describe` parsed: name -> {"Type": ..., "Description": ..., "Read only": ..., ...}."""
    out = ros2.run("param", "describe", node, *names, timeout=20).stdout
    found: dict[str, dict[str, str]] = {}
    current = None
    for line in out.splitlines():
        key, _, value = line.strip().partition(":")
        if key == "Parameter name":
            current = found.setdefault(value.strip(), {})
        elif current is not None and value.strip():
            current[key] = value.strip()
    assert set(found) == set(names), out
    return found


def test_param_describe_shows_description_read_only_and_ranges(ros2, rt_line):
    described = describe(ros2, rt_line.fqn, PARAMETERS)
    problems = []
    for name, d in described.items():
        if not d.get("Description") or "description missing" in d["Description"]:
            problems.append(f"{name}: no description ({d})")
        if d.get("Read only") != "true":
            problems.append(f"{name}: not declared read-only ({d})")
    # The ranges validation enforces (src/ros/params.rs), as ROS ranges.
    ranges = {
        "lines": ("1", "64"),
        "max_steps": ("1", "1000000"),
        "obs_noise": ("0.0", "1.0"),
        "action_penalty": ("0.0", "10.0"),
    }
    for name, (low, high) in ranges.items():
        got = (described[name].get("Min value"), described[name].get("Max value"))
        if got != (low, high):
            problems.append(f"{name}: range {got}, want {(low, high)} ({described[name]})")
    for name in ["threshold", "rate", "tick_period", "seed"]:
        if "Min value" not in described[name] or "Max value" not in described[name]:
            problems.append(f"{name}: no range ({described[name]})")
    assert not problems, "\n".join(problems)


def test_param_set_is_refused_with_the_reason(ros2, rt_line):
    r = ros2.run("param", "set", rt_line.fqn, "rate", "5.0", timeout=20, check=False)
    text = r.stdout + r.stderr
    assert "Setting parameter failed" in text and "rate" in text, text
    reason = text.split("Setting parameter failed", 1)[1].strip(": \n")
    assert reason, f"refused without a reason:\n{text}"
    got = ros2.run("param", "get", rt_line.fqn, "rate", timeout=20).stdout.strip()
    assert got == f"Double value is: {RATE}", got


# ------------------------------------------------------------------------------------------
# The reset service and a command


RESPONSE = re.compile(r"ResetLine_Response\((.*)\)", re.S)


def parse_response(out: str) -> dict:
    m = RESPONSE.search(out)
    assert m, f"no ResetLine response in:\n{out}"
    body = m.group(1)
    fields = {}
    for key in ["success", "seed", "episode", "quantity", "category"]:
        fm = re.search(rf"\b{key}=([^,()]+)", body)
        assert fm, f"{key} missing in {body}"
        fields[key] = fm.group(1).strip()
    fields["message"] = re.search(r"message='([^']*)'", body).group(1)
    stamp = re.search(r"stamp=builtin_interfaces\.msg\.Time\(sec=(\d+), nanosec=(\d+)\)", body)
    fields["stamp"] = (int(stamp.group(1)), int(stamp.group(2)))
    return fields


def test_service_call_reset_with_and_without_seed(ros2, start_node, namespace):
    """`ros2 service call .../reset`: the seeded reply's first observation is the library's for that seed."""
    ns = namespace("reset")
    node = start_node("--variant", "advanced", *h.SETUP_FLAGS["C"], "--seed", "11", "--ros-args", "-r", f"__ns:={ns}")
    service = h.join_ns(ns, "reset")
    seeded = ros2.run(
        "service", "call", service, "sorting_line_interfaces/srv/ResetLine", "{has_seed: true, seed: 1234}", timeout=40
    ).stdout
    got = parse_response(seeded)
    first = h.run_trace("C", "advanced", 1234, [])[0]["reset"]
    assert got["success"] == "True" and got["seed"] == "1234", seeded
    assert float(got["quantity"]) == first["observation"]["quantity"], (seeded, first)
    assert int(got["category"]) == h.CATEGORIES[first["observation"]["category"]], (seeded, first)

    unseeded = ros2.run(
        "service", "call", service, "sorting_line_interfaces/srv/ResetLine", "{has_seed: false}", timeout=40
    ).stdout
    again = parse_response(unseeded)
    assert again["success"] == "True", unseeded
    assert int(again["episode"]) == int(got["episode"]) + 1, (seeded, unseeded)
    assert again["stamp"] > got["stamp"], (seeded, unseeded)
    assert node.running(), node.describe()


def test_topic_pub_speed_command_on_a_realtime_line(ros2, ros, start_node, client_factory, namespace):
    """`ros2 topic pub --once` of a SpeedCommand (zero stamp: a realtime line takes lagging stamps)."""
    ns = namespace("pub")
    # One long episode: a realtime line's own restart shows the start speed again at step 0.
    node = start_node(
        "--mode", "realtime", "--rate", str(RATE), "--max-steps", "1000000", "--ros-args", "-r", f"__ns:={ns}"
    )
    c = client_factory(ns, "basic", node_proc=node, topics=["state"])
    first = ros.spin_until(lambda: c.msgs["state"], 10.0, f"{ns}/state", c.context)[0]
    assert first.speed == 0.6, first  # the start speed, before anyone commands
    seen = len(c.msgs["state"])
    r = ros2.run(
        "topic",
        "pub",
        "--once",
        "-w",
        "1",
        "--keep-alive",
        "2",
        h.join_ns(ns, "cmd/speed"),
        "sorting_line_interfaces/msg/SpeedCommand",
        "{speed: 0.3}",
        timeout=30,
    )
    assert "publishing #1" in r.stdout, r.stdout
    ros.spin_until(
        lambda: any(s.speed == 0.3 for s in c.msgs["state"][seen:]),
        5.0,
        "a state with speed 0.3 after `ros2 topic pub`",
        c.context,
    )
    ros.spin_for(0.5)  # and it holds: a realtime line keeps the last valid command
    speeds = [s.speed for s in c.msgs["state"]]
    changed = speeds.index(0.3)
    assert set(speeds[:changed]) == {0.6} and set(speeds[changed:]) == {0.3}, speeds


def test_the_daemon_stops_listing_a_stopped_node_at_once(ros2, start_node, namespace):
    """A peer that was already running (the ros2 daemon) drops the node soon after SIGINT or
    SIGTERM, not after the DDS lease (tens of seconds). The goal is 2 s; the bound here
    adds the start of a `ros2` process on a busy machine and still cannot be met by the lease."""
    ns = namespace("leave")
    nodes = {
        sig: (
            start_node("--ros-args", "-r", f"__ns:={ns}", "-r", f"__node:=by_{sig.name.lower()}"),
            f"{ns}/by_{sig.name.lower()}",
        )
        for sig in (signal.SIGINT, signal.SIGTERM)
    }
    names = {fqn for _, fqn in nodes.values()}
    domain = int(ros2.env["ROS_DOMAIN_ID"])
    poll(
        ros2,
        ["node", "list"],
        lambda out: names <= set(out.split()),
        f"nodes {sorted(names)}",
        context=lambda: f"participant ids of domain {domain}: {participant_ids.holders(domain)}",
    )
    for sig, (node, _) in nodes.items():
        assert node.stop(sig, timeout=5.0) == 0, node.describe()
    stopped = time.monotonic()
    poll(ros2, ["node", "list"], lambda out: not names & set(out.split()), "the stopped nodes gone", timeout=6.0)
    print(f"the daemon dropped both nodes {time.monotonic() - stopped:.1f} s after they exited")


# ------------------------------------------------------------------------------------------
# ros2 launch


def stop_launch(launch: subprocess.Popen) -> int | str:
    """SIGINT to a `ros2 launch` started in a session of its own; its exit code ("killed after
    15 s" if it did not exit)."""
    if launch.poll() is None:
        os.killpg(launch.pid, signal.SIGINT)
    try:
        return launch.wait(timeout=15)
    except subprocess.TimeoutExpired:
        os.killpg(launch.pid, signal.SIGKILL)
        launch.wait(timeout=5)
        return "killed after 15 s"


def start_launch(ros2, log_path, *launch_args: str) -> subprocess.Popen:
    """`ros2 launch` of the clone's launch file with ``launch_args`` (realtime lines at RATE, the
    tests' node binary), in a session of its own (stop_launch), its output into ``log_path``."""
    argv = [
        "setsid",
        "env",
        "--default-signal=INT",
        *ros2.argv(
            "launch",
            str(h.ROOT / "launch_scripts" / "sorting_line.launch.py"),
            *launch_args,
            f"rate:={RATE}",
            f"sorting_line_bin:={h.node_binary()}",
        ),
    ]
    with open(log_path, "wb") as log:
        return subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=ros2.env, stdin=subprocess.DEVNULL)


def test_ros2_launch_params_file_namespace_lines_and_overrides(ros2, tmp_path, namespace):
    ns = namespace("launch")
    params = tmp_path / "line.yaml"
    params.write_text(
        "/**:\n  ros__parameters:\n    variant: advanced\n    obs_noise: 0.3\n    max_steps: 20\n    seed: 7\n"
    )
    log_path = tmp_path / "launch.log"
    launch = start_launch(
        ros2, log_path, f"namespace:={ns}", "lines:=2", f"params_file:={params}", "max_steps:=9", "mode:=realtime"
    )
    fqn = f"{ns}/sorting_line"
    try:
        poll(ros2, ["node", "list"], lambda out: fqn in out.split(), f"node {fqn}", timeout=30)
        dump = yaml.safe_load(ros2.run("param", "dump", fqn, timeout=20).stdout)[fqn]["ros__parameters"]
        # The params file, the launch overrides (max_steps over the file's 20) and lines:=2.
        assert (
            dump["variant"],
            dump["obs_noise"],
            dump["seed"],
            dump["max_steps"],
            dump["lines"],
            dump["mode"],
            dump["rate"],
        ) == ("advanced", 0.3, 7, 9, 2, "realtime", RATE), dump
        # Two lines, line k in <ns>/line_k with seed 7 + k, episodes of 9 steps.
        out = poll(
            ros2,
            ["topic", "list", "-t"],
            lambda out: all(f"{ns}/line_{k}/state" in out for k in (0, 1)),
            "both lines' topics",
        )
        assert f"{ns}/line_1/sensors/ratio [sorting_line_interfaces/msg/MaterialRatio]" in out, out
        state = yaml_docs(ros2.run("topic", "echo", "--once", f"{ns}/line_1/state", timeout=30).stdout)[0]
        assert state["seed"] == 8 and 0 <= state["step"] <= 9, state
    finally:
        code = stop_launch(launch)
    log = log_path.read_text(errors="replace")
    assert code == 0, f"ros2 launch exited with {code} after SIGINT:\n{log}"
    assert "shut down cleanly" in log and "process has finished cleanly" in log, log


def test_ros2_launch_policy_starts_a_learned_controller_beside_the_node(ros2, tmp_path, namespace):
    """`policy:=POLICY.onnx` (docs/deploying-a-policy.md): the controller runs beside the node in its
    namespace, reads the node's parameters, decides on the realtime line and stops with the launch."""
    ns = namespace("launch_policy")
    policy = h.ROOT / "tests" / "data" / "policies" / "ppo_B_advanced_seed42.onnx"
    log_path = tmp_path / "launch.log"
    launch = start_launch(
        ros2, log_path, f"namespace:={ns}", "setup:=B", "variant:=advanced", "mode:=realtime", f"policy:={policy}"
    )
    try:
        wait_until(
            lambda: "first decision" in log_path.read_text(errors="replace"),
            90,
            "'first decision' from the controller",
            poll=0.5,
            context=lambda: log_path.read_text(errors="replace"),
            abort=lambda: None if launch.poll() is None else f"ros2 launch exited with {launch.returncode}",
        )
        # One `ros2 node list` can answer before the CLI's participant has discovered the controller's
        # (CI saw only the node's): discovery is eventually consistent, so ask until it shows.
        poll(
            ros2,
            ["node", "list"],
            lambda out: f"{ns}/sorting_line_controller" in out.split(),
            f"node {ns}/sorting_line_controller",
            timeout=30,
        )
    finally:
        code = stop_launch(launch)
    log = log_path.read_text(errors="replace")
    assert code == 0, f"ros2 launch exited with {code} after SIGINT:\n{log}"
    assert f"line: setup B advanced (parameters of {ns}/sorting_line)" in log, log
    assert "first decision" in log and "SIGINT: stopping" in log, log
