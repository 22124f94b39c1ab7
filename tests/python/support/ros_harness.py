"""Helpers for the Python/ROS integration tests of `sorting_line` (and the node benchmark).

- `check_isolated_network()`: DDS test traffic must stay on this machine. Refuses to run unless the
  process is in a network namespace that has only `lo` (or SORTING_LINE_ALLOW_HOST_NETWORK=1).
- `ros_environment()`: ROS_DOMAIN_ID (default 87 for tests) and the variables of
  launch_scripts/env.sh (Fast DDS, its profile, localhost discovery) for anyone who did not source it.
- `NodeProcess`: the real node binary as a subprocess, stderr captured to a file, stopped with
  SIGINT (exit code 0 within 5 s is part of its contract).
- `RosSession`: rclpy initialised once, ONE SingleThreadedExecutor, and bounded waits that spin it
  with `spin_once(timeout_sec=...)` (never `spin_until_future_complete`, which leaks a task per call
  in rclpy 7.1).
- `LineClient` (line_client.py): one line as a lock-step client sees it: reset via the service, step by publishing
  commands stamped with the current tick and waiting for the next tick's `state`, and every message
  of every topic of the line collected in lists.
- `ScriptProcess`: a console script of the bridge (`sorting-line-controller`, `sorting-line-bag`)
  as a subprocess with its log, stopped with SIGINT.
- `run_trace()`: the simulation library's reference trajectory (`sorting_line trace`), and
  converters so that node states and trace entries compare field by field.

A node that has exited keeps its DDS endpoints visible to rclpy for about 50 s (RustDDS's dispose
is dropped by Fast DDS), so a matched publisher or a ready service is never taken as proof that a
node is up: only a real reply or message is. Tests use a namespace of their own for each node.

Measured trap: `service_is_ready()` is our side's view. The node (RustDDS) may match our reply
reader later than our request writer; a reply written before that is never delivered (volatile),
while the reset itself did happen. So LineClient.wait_connected() also waits for the node's
/diagnostics (1 Hz) to reach this participant, and LineClient.reset() never sends a second reset
unless /diagnostics shows the first one did not happen (generic call_service() retries blindly and
is meant for idempotent services such as GetParameters).
"""

from __future__ import annotations

import itertools
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from sorting_line_gym.line import vocabulary
from sorting_line_gym.line.process import with_parent_death_signal
from sorting_line_gym.line.topics import line_types
from sorting_line_gym.line.vocabulary import CATEGORIES, EPISODE_STEPS, MODES, SETUPS, SPEEDS
from support.waits import WaitTimeout, wait_until

ROOT = Path(__file__).resolve().parents[3]
DEFAULT_TEST_DOMAIN = "87"
NS_PER_S = 1_000_000_000
# How long a wait goes on spinning once its peer is gone, to take what the peer sent before it went.
DRAIN_AFTER_ABORT = 0.5

# Every topic of one line that does not evolve (relative to its namespace) and its type: the
# package's vocabulary (sorting_line_gym.line.topics), tested against the node's by test_topics.py.
LINE_TYPES = line_types(evolving=False)


# --------------------------------------------------------------------------------------------
# Environment


def network_interfaces() -> dict[str, set[str]]:
    """Interfaces of this process's network namespace (`ip -o link`): name -> flags."""
    out = subprocess.run(["ip", "-o", "link"], capture_output=True, text=True, check=True).stdout
    interfaces = {}
    for line in out.splitlines():
        # "1: lo: <LOOPBACK,UP,LOWER_UP> mtu 65536 ..." ; veth names may carry "@ifN"
        parts = line.split(":", 2)
        if len(parts) >= 3:
            flags = parts[2].split("<", 1)[1].split(">", 1)[0].split(",") if "<" in parts[2] else []
            interfaces[parts[1].strip().split("@")[0]] = set(flags)
    return interfaces


def isolation_problem() -> str | None:
    """None when DDS traffic cannot leave this machine; otherwise why we refuse to run."""
    if os.environ.get("SORTING_LINE_ALLOW_HOST_NETWORK") == "1":
        return None
    try:
        interfaces = network_interfaces()
    except (OSError, subprocess.CalledProcessError) as e:
        return f"cannot list network interfaces with `ip -o link` ({e})"
    others = [n for n in interfaces if n != "lo"]
    if others:
        return (
            f"not in an isolated network namespace: interfaces {', '.join(others)} besides lo. "
            "Run inside `unshare -n` with `ip link set lo up` (launch_scripts/test.sh does), "
            "or set SORTING_LINE_ALLOW_HOST_NETWORK=1 to accept DDS traffic on the host network"
        )
    if "UP" not in interfaces.get("lo", set()):
        return "the loopback interface is down in this network namespace: run `ip link set lo up` first"
    return None


def check_isolated_network() -> None:
    problem = isolation_problem()
    if problem:
        raise RuntimeError(problem)


def run_isolated(script: str, mark: str = "SORTING_LINE_IN_NETNS") -> None:
    """For benchmark scripts: returns when DDS traffic cannot leave this machine; otherwise, as
    root, re-executes ``script`` (with the same arguments and interpreter) under ``unshare -n``
    and brings ``lo`` up there; otherwise exits naming the problem."""
    if os.environ.get(mark) == "1":
        subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    problem = isolation_problem()
    if problem is None:
        return
    if os.environ.get(mark) != "1" and os.geteuid() == 0 and shutil.which("unshare") and shutil.which("ip"):
        print(
            "not in an isolated network namespace: re-executing under `unshare -n` (lo up)", file=sys.stderr, flush=True
        )
        env = dict(os.environ, **{mark: "1"})
        os.execvpe("unshare", ["unshare", "-n", "--", sys.executable, os.path.abspath(script), *sys.argv[1:]], env)
    sys.exit(f"{os.path.basename(script)}: refusing to run: {problem}")


def machine_conditions(steal_window: float = 0.5) -> str:
    """Load average and the CPU time the hypervisor took from this VM (steal, sampled over
    ``steal_window`` s), printed beside benchmark figures: they are only comparable at low steal."""

    def sample():
        fields = [int(x) for x in Path("/proc/stat").read_text().splitlines()[0].split()[1:]]
        return sum(fields), fields[7]

    t0, s0 = sample()
    time.sleep(steal_window)
    t1, s1 = sample()
    steal = 100.0 * (s1 - s0) / max(1, t1 - t0)
    return f"load {'/'.join(f'{x:.2f}' for x in os.getloadavg())}, steal {steal:.1f} %"


def proc_status_mb(pid: int, key: str = "VmRSS") -> float:
    """A `kB` field of /proc/PID/status (VmRSS, VmHWM, ...) in MB; 0 if the process is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def rss_mb(*pids: int) -> float:
    """The resident memory of these processes together, in MB (a process that is gone counts 0)."""
    return sum(proc_status_mb(pid) for pid in pids)


def ros_environment(default_domain: str = DEFAULT_TEST_DOMAIN) -> dict[str, str]:
    """Sets (if unset) what launch_scripts/env.sh sets, plus ROS_DOMAIN_ID; returns the values.

    Must run before rclpy is initialised (Fast DDS reads the profile when the participant is made).
    """
    os.environ.setdefault("ROS_DOMAIN_ID", default_domain)
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(ROOT / "launch_scripts" / "fastdds_profile.xml"))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DISTRO", "jazzy")
    keys = ["ROS_DOMAIN_ID", "RMW_IMPLEMENTATION", "FASTRTPS_DEFAULT_PROFILES_FILE", "ROS_AUTOMATIC_DISCOVERY_RANGE"]
    return {k: os.environ[k] for k in keys}


def ns_args(ns: str) -> list[str]:
    """The ROS arguments that put a node (ours or a script's) into namespace ``ns``."""
    return ["--ros-args", "-r", f"__ns:={ns}"]


def node_binary() -> Path:
    """The node binary the bridge uses too (``sorting_line_gym.line.process.find_node_binary``:
    $SORTING_LINE_BIN, else this checkout's release build, else PATH)."""
    from sorting_line_gym.line.process import find_node_binary  # here: rclpy loads after ros_environment()

    return Path(find_node_binary())


def stamp_ns(stamp) -> int:
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def show_ns(ns: int) -> str:
    return f"{ns // NS_PER_S}.{ns % NS_PER_S:09d}"


# --------------------------------------------------------------------------------------------
# The node process


class _LoggedProcess:
    """A subprocess whose stdout and stderr go to `log_path`, with a parent-death signal: a test
    run that is killed does not leave it behind. What NodeProcess and ScriptProcess share."""

    def _start(self, argv: list[str], log_path: Path, env: dict[str, str]) -> None:
        self.argv = argv
        self.log_path = Path(log_path)
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            with_parent_death_signal(argv), stdout=self._log, stderr=subprocess.STDOUT, env=env
        )

    def running(self) -> bool:
        return self.proc.poll() is None

    def log(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")


class NodeProcess(_LoggedProcess):
    """`sorting_line node ARGS` as a subprocess; stderr (and stdout) go to `log_path`."""

    def __init__(self, args: Iterable[str], log_path: Path, env: dict[str, str] | None = None):
        self.args = [str(a) for a in args]
        full_env = dict(os.environ)
        if env:
            full_env.update(env)
        self._start([str(node_binary()), "node", *self.args], log_path, full_env)
        self.pid = self.proc.pid
        self.stopped_by_test = False

    def log(self) -> str:
        try:
            return super().log()
        except OSError:
            return ""

    def log_tail(self, lines: int = 15) -> str:
        return "\n".join(self.log().splitlines()[-lines:])

    def describe(self) -> str:
        state = "running" if self.running() else f"exited with {self.proc.returncode}"
        return f"node pid {self.pid} ({state}): {' '.join(self.argv)}\n--- node log (tail) ---\n{self.log_tail()}"

    def stop(self, sig: int = signal.SIGINT, timeout: float = 5.0) -> int:
        """Sends `sig` and waits up to `timeout` s; returns the exit code (kills and raises on timeout)."""
        self.stopped_by_test = True
        if self.running():
            self.proc.send_signal(sig)
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=5)
            self._log.close()
            raise AssertionError(
                f"node did not exit within {timeout} s of {signal.Signals(sig).name}\n{self.describe()}"
            ) from None
        self._log.close()
        return code

    def kill(self) -> None:
        if self.running():
            self.proc.kill()
            self.proc.wait(timeout=5)
        self._log.close()


class ScriptProcess(_LoggedProcess):
    """A console script of the bridge (`sorting-line-controller`, `sorting-line-bag`, ...) as a
    subprocess, run as a user runs it: stdout and stderr into `log_path`, SORTING_LINE_BIN set to
    the node binary of the tests, a parent-death signal as for NodeProcess."""

    def __init__(self, name: str, args: Iterable[Any], log_path: Path, label: str | None = None):
        script = Path(sys.executable).parent / name
        if not script.is_file():
            script = Path(shutil.which(name) or script)
        assert script.is_file(), (
            f"console script {script} missing: reinstall the bridge "
            "(.venv/bin/pip install --no-deps --no-build-isolation -e bridge)"
        )
        self.label = label or name
        env = dict(os.environ, SORTING_LINE_BIN=str(node_binary()), PYTHONUNBUFFERED="1")
        self._start([str(script), *[str(a) for a in args]], log_path, env)
        self.returncode = None

    def describe(self) -> str:
        state = "running" if self.running() else f"exited with {self.proc.returncode}"
        return f"{self.label} ({state}): {' '.join(self.argv)}\n--- {self.label} log ---\n{self.log()}"

    def wait(self, timeout: float, sig: int | None = None) -> int:
        """Sends `sig` (if any and still running), waits up to `timeout` s for the exit code
        (kills and raises on timeout); a second call returns the same code."""
        if self.returncode is not None:
            return self.returncode
        if sig is not None and self.running():
            self.proc.send_signal(sig)
        try:
            self.returncode = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=5)
            how = f" of {signal.Signals(sig).name}" if sig is not None else ""
            raise AssertionError(f"{self.label} did not exit within {timeout} s{how}\n{self.describe()}") from None
        finally:
            self._log.close()
        return self.returncode

    def stop(self, timeout: float = 10.0) -> int:
        """SIGINT; must exit in time."""
        return self.wait(timeout, signal.SIGINT)


def stop_problems(procs: Iterable, stop: Callable[[Any], str | None]) -> list[str]:
    """At a fixture's teardown: ``stop(p)`` for every process, each a problem (or None); an
    AssertionError (a process that did not exit in time) is a problem too. Every process is
    stopped whatever the others did."""
    problems = []
    for p in procs:
        try:
            problem = stop(p)
        except AssertionError as e:
            problem = str(e)
        if problem:
            problems.append(problem)
    return problems


def run_node_expecting_failure(args: Iterable[str], env: dict[str, str] | None = None, timeout: float = 10.0):
    """Runs `sorting_line node ARGS` that must fail at start; returns (exit code, stderr)."""
    full_env = dict(os.environ)
    if env:
        full_env.update(env)
    argv = [str(node_binary()), "node", *[str(a) for a in args]]
    try:
        r = subprocess.run(argv, capture_output=True, text=True, env=full_env, timeout=timeout)
    except subprocess.TimeoutExpired as e:
        raise AssertionError(f"`{' '.join(argv)}` did not fail at start: still running after {timeout} s") from e
    return r.returncode, r.stderr


# --------------------------------------------------------------------------------------------
# The reference trajectory


def run_trace(
    setup: str, variant: str, seed: int, actions: Iterable[Any], max_steps: int = EPISODE_STEPS
) -> list[dict]:
    """`sorting_line trace`: the pure-library trajectory, one dict per line (first = initial reset)."""
    tokens = [str(a) for a in actions]
    flags = f"--setup {setup} --variant {variant} --seed {seed} --max-steps {max_steps}"
    argv = [str(node_binary()), "trace", *flags.split()]
    if tokens:
        argv += ["--actions", ",".join(tokens)]
    r = subprocess.run(argv, capture_output=True, text=True, timeout=30)
    if r.returncode != 0:
        raise RuntimeError(f"`{' '.join(argv)}` failed ({r.returncode}): {r.stderr}")
    return [json.loads(line) for line in r.stdout.splitlines() if line.strip()]


# Node options equivalent to the trace's --setup (threshold 0.7 is the default of both), spelled
# out as flags: the tests that use them check the node's separate options, not its --setup.
SETUP_FLAGS = {
    name: ["--input", s["input"], "--obs-noise", str(s["obs_noise"]), "--action-penalty", str(s["action_penalty"])]
    for name, s in SETUPS.items()
}


def decode_action(variant: str, action: int) -> tuple[float, int | None]:
    """Gymnasium action -> (speed, mode): basic = speed index, advanced = speed index * 3 + mode."""
    speed_index, mode = vocabulary.decode_action(variant, action)
    return SPEEDS[speed_index], (mode if variant == "advanced" else None)


def trace_observation_view(observation: dict) -> dict:
    """A trace entry's observation as LineState's observation fields."""
    return {
        "observation_quantity": observation["quantity"],
        "observation_category": CATEGORIES[observation["category"]],
    }


def trace_reset_view(entry: dict) -> dict:
    r = entry["reset"]
    return {"seed": r["seed"], "episode": r["episode"], **trace_observation_view(r["observation"])}


def state_reset_view(state) -> dict:
    return {
        "seed": state.seed,
        "episode": state.episode,
        "observation_quantity": state.observation_quantity,
        "observation_category": state.observation_category,
    }


#: The four container counts in the order of the env's info["containers"]: a trace entry's
#: "containers" keys, and LineState's fields with a "container_" prefix.
CONTAINERS = ("a", "a_false", "b", "b_false")


def trace_step_view(entry: dict) -> dict:
    """A trace step entry as the flat fields of the node's LineState (see state_step_view)."""
    s = entry["step"]
    return {
        "episode": entry["episode"],
        "step": s["step"],
        "speed_index": s["action"]["speed_index"],
        "mode": MODES[s["action"]["mode"]],
        "occupancy": s["occupancy"],
        "accuracy": s["accuracy"],
        "reward": s["reward"],
        "cumulative_reward": entry["cumulative_reward"],
        "purity": entry["purity"],
        **{f"container_{k}": entry["containers"][k] for k in CONTAINERS},
        "speed_changes": entry["speed_changes"],
        **trace_observation_view(s["observation"]),
        "terminated": s["terminated"],
        "truncated": s["truncated"],
    }


def state_step_view(state) -> dict:
    keys = [
        "episode",
        "step",
        "speed_index",
        "mode",
        "occupancy",
        "accuracy",
        "reward",
        "cumulative_reward",
        "purity",
        "container_a",
        "container_a_false",
        "container_b",
        "container_b_false",
        "speed_changes",
        "observation_quantity",
        "observation_category",
        "terminated",
        "truncated",
    ]
    return {k: getattr(state, k) for k in keys}


def msg_to_dict(msg) -> Any:
    """Every field of a ROS message, recursively, as plain Python values (for exact comparison)."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {name: msg_to_dict(getattr(msg, name)) for name in msg.get_fields_and_field_types()}
    if isinstance(msg, (list, tuple)):
        return [msg_to_dict(m) for m in msg]
    if isinstance(msg, float) and math.isnan(msg):
        return "nan"
    return msg


# --------------------------------------------------------------------------------------------
# rclpy


class RosSession:
    """rclpy initialised once, with ONE SingleThreadedExecutor shared by every test node."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self._names = itertools.count()

    def make_node(self, prefix: str = "test_client"):
        import rclpy.node

        node = rclpy.node.Node(f"{prefix}_{os.getpid()}_{next(self._names)}", context=self.context)
        self.executor.add_node(node)
        return node

    def destroy_node(self, node) -> None:
        self.executor.remove_node(node)
        node.destroy_node()

    def spin_until(
        self,
        condition: Callable[[], Any],
        timeout: float,
        what: str,
        context: Callable[[], str] = lambda: "",
        step: float = 0.02,
        abort: Callable[[], str | None] = lambda: None,
    ):
        """Spins until `condition()` is truthy (and returns it); raises WaitTimeout naming `what`
        after `timeout` s, or soon after `abort()` says why waiting is pointless (a peer that is
        gone: what it sent before it went is taken first, DRAIN_AFTER_ABORT s at most)."""
        return wait_until(
            condition,
            timeout,
            what,
            poll=step,
            context=context,
            abort=abort,
            pause=lambda seconds: self.executor.spin_once(timeout_sec=seconds),
            drain=DRAIN_AFTER_ABORT,
        )

    def spin_for(self, seconds: float) -> None:
        """Spins for `seconds`, handling whatever arrives."""
        deadline = time.monotonic() + seconds
        while (remaining := deadline - time.monotonic()) > 0:
            self.executor.spin_once(timeout_sec=min(0.02, remaining))

    def wait_future(
        self,
        future,
        timeout: float,
        what: str,
        context: Callable[[], str] = lambda: "",
        abort: Callable[[], str | None] = lambda: None,
    ):
        self.spin_until(future.done, timeout, what, context, abort=abort)
        return future.result()

    def call_service(
        self,
        client,
        request,
        what: str,
        wait: float = 10.0,
        attempt_timeout: float = 3.0,
        attempts: int = 3,
        context: Callable[[], str] = lambda: "",
        abort: Callable[[], str | None] = lambda: None,
    ):
        """Waits (bounded) for the service, then calls it, retrying a call that got no reply."""
        self.spin_until(client.service_is_ready, wait, f"service {what} to be available", context, abort=abort)
        for attempt in range(1, attempts + 1):
            future = client.call_async(request)
            try:
                return self.wait_future(
                    future, attempt_timeout, f"a reply from {what} (attempt {attempt}/{attempts})", context, abort
                )
            except WaitTimeout:
                client.remove_pending_request(future)
                print(
                    f"ros_harness: no reply from {what} within {attempt_timeout} s (attempt {attempt}/{attempts})\n"
                    f"{context()}",
                    file=sys.stderr,
                )
                if attempt == attempts:
                    raise
        raise AssertionError("unreachable")

    def shutdown(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.rclpy.shutdown(context=self.context)


def join_ns(ns: str, rel: str) -> str:
    return f"/{rel}" if ns == "/" else f"{ns}/{rel}"


class TopicRecorder:
    """Records every message of one topic (e.g. /clock, /diagnostics) into `msgs`."""

    def __init__(self, session: RosSession, node, topic: str, msg_type, qos: int = 10):
        self.session, self.topic, self.msgs = session, topic, []
        self.sub = node.create_subscription(msg_type, topic, self.msgs.append, qos)

    def wait_for(
        self, predicate: Callable[[Any], bool], timeout: float, what: str, context: Callable[[], str] = lambda: ""
    ):
        """The first recorded message (old or new) for which `predicate` holds."""

        def found():
            return next((m for m in self.msgs if predicate(m)), None)

        return self.session.spin_until(found, timeout, f"{self.topic}: {what}", context)


def diagnostic_values(array, hardware_id: str) -> dict[str, str] | None:
    """The key/values of the status for `hardware_id` (the line's namespace) in a DiagnosticArray."""
    for status in array.status:
        if status.hardware_id == hardware_id:
            return {kv.key: kv.value for kv in status.values}
    return None


def ratio_rule(amount_a: int, amount_b: int) -> tuple[float, int]:
    """The ratio sensor's rule: A/B rounded to 2 decimals (3.0 when B == 0), positive >= 3, negative <= 1/3."""
    ratio = 3.0 if amount_b == 0 else round(amount_a / amount_b, 2)
    if ratio >= 3.0:
        return ratio, 1
    if ratio <= 1.0 / 3.0:
        return ratio, 2
    return ratio, 0


def sanitize(name: str) -> str:
    """A valid ROS name token from any text (ROS names allow no repeated underscores)."""
    return re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", name)).strip("_")
