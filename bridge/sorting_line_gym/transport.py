"""The rclpy side of the bridge: the node process, one line's endpoints, and waiting.

Rules this module keeps (shared/platform/ros2-without-a-ros-install.md explains why):
- one executor per bridge, owned by it; no ``spin_until_future_complete`` (it leaks a task per
  call in rclpy 7.1): every wait is ``executor.spin_once`` in a loop with a deadline;
- every wait has a timeout and fails with an error naming the namespace, the topic or service and
  the tick it waited for, and fails at once if the node process it owns has died;
- QoS is explicit (reliable, volatile, keep-last 10, as the node);
- the first exchange is a handshake: a reset whose step-0 ``state`` must arrive, which proves
  that commands and states flow before the first step (volatile samples sent before matching
  are lost, and graph counts can lie for a while after a node dies).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import itertools
import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
import warnings
from array import array
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Callable

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from builtin_interfaces.msg import Time
from sorting_line_interfaces.msg import LineCommands, LineState, LineStates, SortModeCommand, SpeedCommand
from sorting_line_interfaces.srv import ResetLine, ResetLines

from .batch_codec import BatchCodec, from_message
from .vocabulary import SPEEDS  # a speed index i commands SPEEDS[i]

#: The node's QoS for commands and state.
QOS = QoSProfile(
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
    history=HistoryPolicy.KEEP_LAST,
)


class BridgeError(RuntimeError):
    """The node or the link to it failed (the node exited, a reset was refused, ...)."""


class BridgeTimeout(BridgeError, TimeoutError):
    """A wait ran out of time; the message names what was waited for."""


# --------------------------------------------------------------------------------------------
# rclpy, once per process, and never across a fork
# --------------------------------------------------------------------------------------------
_rclpy_lock = threading.Lock()
_rclpy_users = 0
_rclpy_ours = False
#: In a forked child: the pid of the parent, when rclpy (so DDS: Fast DDS's threads, sockets and
#: locks) was live there at the fork. Set by the fork hooks below, inherited by the child.
_forked_from_live: int | None = None


def _default_context_live() -> bool:
    """Whether rclpy's default context is initialised. Reads the attribute without rclpy's lock
    (this runs in a fork hook)."""
    import rclpy.utilities

    context = getattr(rclpy.utilities, "g_default_context", None)
    return context is not None and context.handle is not None


def _before_fork() -> None:
    global _forked_from_live
    if _forked_from_live is None and (_rclpy_users > 0 or _default_context_live()):
        _forked_from_live = os.getpid()


def _after_fork_in_parent() -> None:
    global _forked_from_live
    if _forked_from_live == os.getpid():
        _forked_from_live = None


os.register_at_fork(before=_before_fork, after_in_parent=_after_fork_in_parent)


def fork_error() -> BridgeError | None:
    """The error to raise when this process was forked from one where rclpy was live, else None.

    rclpy over Fast DDS is not fork-safe: the child inherits the context's memory but not the
    threads that serve it, so its first wait blocks forever on a lock a vanished thread held."""
    if _forked_from_live is None or _forked_from_live == os.getpid():
        return None
    return BridgeError(
        f"rclpy/DDS is not fork-safe: a context initialised in pid {_forked_from_live} cannot be used in pid "
        f"{os.getpid()}, a process forked from it. Make the environments in the child (sorting_line_gym "
        "envs connect at their first reset(), so constructing them before the fork is fine as long as "
        "nothing used rclpy yet), or start the children with the multiprocessing context 'spawn' or "
        "'forkserver' (e.g. AsyncVectorEnv(..., context='spawn'), SubprocVecEnv(..., start_method='spawn'))"
    )


def check_not_forked() -> None:
    error = fork_error()
    if error is not None:
        raise error


def acquire_rclpy() -> None:
    """Initialises rclpy if nobody has; paired with :func:`release_rclpy`. Raises instead of
    blocking when this process was forked from one where rclpy was live (:func:`fork_error`)."""
    global _rclpy_users, _rclpy_ours
    check_not_forked()
    with _rclpy_lock:
        if _rclpy_users == 0 and not rclpy.ok():
            rclpy.init()
            _rclpy_ours = True
        _rclpy_users += 1


def release_rclpy() -> None:
    """Shuts rclpy down when the last user that needed it to be initialised is gone."""
    global _rclpy_users, _rclpy_ours
    if fork_error() is not None:
        return  # the inherited context is not ours to shut down here
    with _rclpy_lock:
        _rclpy_users = max(0, _rclpy_users - 1)
        if _rclpy_users == 0 and _rclpy_ours and rclpy.ok():
            rclpy.shutdown()
            _rclpy_ours = False


# --------------------------------------------------------------------------------------------
# Joining the graph, one at a time
# --------------------------------------------------------------------------------------------
def host_state_directory() -> Path:
    """Where this host's bridges coordinate (line servers, joining the graph), per user."""
    path = Path(tempfile.gettempdir()) / f"sorting_line_gym-{os.getuid()}"
    path.mkdir(parents=True, exist_ok=True)
    return path


def network_namespace() -> str:
    """This process's network namespace: DDS traffic does not cross it, files do."""
    try:
        return os.readlink("/proc/self/ns/net")
    except OSError:
        return "host"


@contextlib.contextmanager
def joining_graph(timeout: float):
    """Holds this host's lock for joining the DDS graph of ``ROS_DOMAIN_ID`` (per network
    namespace) while a bank starts its participant and node and discovers the node's endpoints.

    Measured (benches/discovery.py, README "Many envs per host"): when several client and node
    participants start at the same moment (16 SubprocVecEnv workers, each starting a node), Fast
    DDS and RustDDS lose some endpoint announcements between them for good (a node's reset
    service never becomes ready for its client, even after 60 s); one participant pair joining at
    a time discovers completely, whatever the number of participants. Waiting for the lock counts
    against ``timeout``; a holder that dies frees it at once (flock)."""
    digest = hashlib.sha1(f"{network_namespace()}|{os.environ.get('ROS_DOMAIN_ID', '0')}".encode()).hexdigest()[:12]
    path = host_state_directory() / f"join-{digest}.lock"
    deadline = time.monotonic() + timeout
    with open(path, "a+") as f:
        while True:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise BridgeTimeout(
                        f"timed out after {timeout:g} s waiting for other environments of this host to join "
                        f"the DDS graph (lock {path})"
                    ) from None
                time.sleep(0.01)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


# --------------------------------------------------------------------------------------------
# The node process
# --------------------------------------------------------------------------------------------
def find_node_binary() -> str:
    """The `sorting_line` binary, the one lookup of bridge, tests and benchmarks: $SORTING_LINE_BIN
    (which must then exist), else this checkout's release build, else PATH."""
    chosen = os.environ.get("SORTING_LINE_BIN")
    if chosen:
        if not (os.path.isfile(chosen) and os.access(chosen, os.X_OK)):
            raise BridgeError(f"SORTING_LINE_BIN = {chosen} is not an executable file")
        return chosen
    repo = Path(__file__).resolve().parents[2]
    for c in (str(repo / "target" / "release" / "sorting_line"), shutil.which("sorting_line")):
        if c and os.path.isfile(c) and os.access(c, os.X_OK):
            return c
    raise BridgeError(
        "cannot find the sorting_line binary: set SORTING_LINE_BIN, or build it with "
        "`cargo build --release` (launch_scripts/setup.sh does)"
    )


_spawn_counter = itertools.count()


def private_namespace() -> str:
    """A namespace no other bridge in any process uses: /sorting_line_gym/p<pid>_<n>."""
    return f"/sorting_line_gym/p{os.getpid()}_{next(_spawn_counter)}"


class NodeProcess:
    """A `sorting_line node` process owned by a bridge: started with the given options in its own
    namespace (plus ``ros_args``, e.g. remaps, after ``--ros-args``), its log kept in a temporary
    file, stopped with SIGINT (SIGKILL if it hangs).

    The log is deleted when the node stopped cleanly (exit code 0) and kept when it failed: then
    its path is in the error (``death_notice``) or in the warning ``stop`` gives. The node gets
    SIGTERM if the bridge dies (``setpriv --pdeathsig``, where available), so a killed bridge
    leaves no node behind. (The parent-death signal follows the thread that started the node: a
    bridge made in a short-lived thread should be made elsewhere.)"""

    def __init__(self, namespace: str, options: dict[str, object], ros_args: tuple[str, ...] = ()):
        self.namespace = namespace
        args = [find_node_binary(), "node"]
        for key, value in options.items():
            if value is not None:
                args += [f"--{key.replace('_', '-')}", str(value)]
        args += ["--ros-args", "-r", f"__ns:={namespace}", *ros_args]
        self.command = args
        self._log = tempfile.NamedTemporaryFile(prefix="sorting_line_node_", suffix=".log", delete=False)
        self.log_path = self._log.name
        launcher = ["setpriv", "--pdeathsig", "TERM", "--"] if shutil.which("setpriv") else []
        self.process = subprocess.Popen(
            launcher + args, stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT
        )

    def alive(self) -> bool:
        return self.process.poll() is None

    def log_tail(self, lines: int = 8) -> str:
        try:
            text = Path(self.log_path).read_text(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return "\n".join(text[-lines:])

    def death_notice(self) -> str:
        return (
            f"the sorting_line node for {self.namespace} exited with code {self.process.returncode}"
            f" (log {self.log_path}):\n{self.log_tail()}"
        )

    def stop(self, timeout: float = 5.0) -> int | None:
        """Stops the node; returns its exit code. Deletes the log if the node stopped cleanly."""
        if self.alive():
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout)
        if not self._log.closed:
            self._log.close()
            code = self.process.returncode
            if code == 0:
                Path(self.log_path).unlink(missing_ok=True)
            else:
                warnings.warn(f"{self.death_notice()}\n(the log is kept)", RuntimeWarning, stacklevel=2)
        return self.process.returncode


# --------------------------------------------------------------------------------------------
# Waiting
# --------------------------------------------------------------------------------------------
#: Longest single wait: how soon a dead node or the deadline is noticed.
WAIT_SLICE = 0.05


class Waiter:
    """Waits until a condition holds, with a deadline and a liveness check: ``until`` spins the
    executor (services, any subscription); ``until_received`` waits on the given subscriptions
    alone, for conditions that take their messages themselves (the step loop)."""

    def __init__(self, executor: SingleThreadedExecutor, process: NodeProcess | None):
        self.executor = executor
        self.process = process
        self._wait_set = None
        self._wait_handles: tuple = ()

    def _check(self, deadline: float, timeout: float, what: Callable[[], str]) -> float:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise BridgeTimeout(f"timed out after {timeout:g} s waiting for {what()}")
        if self.process is not None and not self.process.alive():
            raise BridgeError(f"while waiting for {what()}: {self.process.death_notice()}")
        return remaining

    def until(self, done: Callable[[], bool], timeout: float, what: Callable[[], str]) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            remaining = self._check(deadline, timeout, what)
            self.executor.spin_once(timeout_sec=min(remaining, WAIT_SLICE))

    def until_received(self, subscriptions, done: Callable[[], bool], timeout: float, what: Callable[[], str]) -> None:
        """Like ``until``, but sleeps on an rcl wait set holding only ``subscriptions``, kept
        across calls, instead of the executor, which rebuilds a wait set over every entity of
        the node and dispatches through Python on every wake-up: the step loop's round trip is
        shorter this way (benches/bridge_throughput.py). ``done`` must take the messages itself
        (``take_message``); nothing here runs callbacks. This is the wait that
        ``rclpy.wait_for_message`` performs, through rclpy's implementation module (rclpy is
        pinned exactly in requirements-ros.txt)."""
        if done():
            return
        deadline = time.monotonic() + timeout
        handles = tuple(sub.handle for sub in subscriptions)
        if self._wait_set is None or handles != self._wait_handles:
            from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

            self._wait_set = _rclpy.WaitSet(len(handles), 0, 0, 0, 0, 0, self.executor.context.handle)
            self._wait_handles = handles
        wait_set = self._wait_set
        while not done():
            remaining = self._check(deadline, timeout, what)
            wait_set.clear_entities()
            for handle in handles:
                wait_set.add_subscription(handle)
            wait_set.wait(int(min(remaining, WAIT_SLICE) * 1e9))


# --------------------------------------------------------------------------------------------
# One line
# --------------------------------------------------------------------------------------------
def stamp_key(t: Time) -> tuple[int, int]:
    return (t.sec, t.nanosec)


def publish_commands(speed_pub, mode_pub, stamp: Time, speed_index: int, mode: int) -> None:
    """Answers the tick stamped ``stamp`` on a line's command topics: the sort mode first (when
    the line has one, ``mode_pub`` not None), then the speed, which completes the tick."""
    if mode_pub is not None:
        m = SortModeCommand()
        m.header.stamp = stamp
        m.mode = int(mode)
        mode_pub.publish(m)
    s = SpeedCommand()
    s.header.stamp = stamp
    s.speed = SPEEDS[speed_index]
    speed_pub.publish(s)


@dataclass
class ResetResult:
    """What a reset tells about one line: its first observation and where it now stands."""

    quantity: float
    category: int
    episode: int
    seed: int
    stamp: Time


@dataclass
class Tick:
    """Where a line is: the stamp to answer, the episode and the step."""

    stamp: Time
    episode: int
    step: int


def check_not_taken_over(namespace: str, ours: int, seen: int) -> None:
    """A state of a later episode than ours means another client reset the line: our commands are
    refused from now on (the node lets one client drive an episode), so say so rather than wait."""
    if seen > ours:
        raise BridgeError(
            f"{namespace}: another client reset this line (episode {seen}; this bridge drives episode "
            f"{ours}); the node refuses this bridge's commands from now on ('not_owner' on /diagnostics). "
            "Call reset() to take the line back, or give each bridge a line of its own"
        )


def _drain(sub, inbox: deque) -> None:
    """Takes every message a subscription has already received, without the executor.

    The executor hands over one message per wake-up, each wake-up rebuilding a wait set over every
    entity; when several messages are due together (the states of a round trip), taking the rest
    directly, as the executor itself does (``Subscription.handle.take_message``), saves those
    wake-ups.
    """
    with sub.handle:
        while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
            inbox.append(taken[0])


class LineLink:
    """The endpoints of one line on the bridge's rclpy node, and its lock-step position.

    With ``per_line_topics=False`` (lines driven and reset through :class:`BatchLink`) it creates
    no endpoints at all: every entity is one more thing each executor wait scans."""

    def __init__(self, node: Node, namespace: str, advanced: bool, per_line_topics: bool = True):
        self.namespace = namespace.rstrip("/") or ""
        self.advanced = advanced
        self.node = node
        name = lambda rel: f"{self.namespace}/{rel}"
        self.state_topic = name("state")
        self.speed_pub = self.mode_pub = self.state_sub = self.reset_client = None
        # States arrive in order; keep a short backlog so nothing is lost while we publish.
        self.inbox: deque[LineState] = deque(maxlen=64)
        if per_line_topics:
            self.reset_client = node.create_client(ResetLine, name("reset"), qos_profile=QOS)
            self.speed_pub = node.create_publisher(SpeedCommand, name("cmd/speed"), QOS)
            self.mode_pub = node.create_publisher(SortModeCommand, name("cmd/sort_mode"), QOS) if advanced else None
            self.state_sub = node.create_subscription(LineState, self.state_topic, lambda m: self.inbox.append(m), QOS)
        self.tick: Tick | None = None
        self.last_state: LineState | None = None
        self._reset_future = None

    # -- matching ----------------------------------------------------------------------------
    def endpoints_matched(self, node: Node) -> bool:
        """Commands have a reader and the state topic a writer (necessary, not sufficient)."""
        ok = self.reset_client is None or self.reset_client.service_is_ready()
        if self.speed_pub is not None:
            ok = ok and self.speed_pub.get_subscription_count() > 0 and node.count_publishers(self.state_topic) > 0
        if self.mode_pub is not None:
            ok = ok and self.mode_pub.get_subscription_count() > 0
        return ok

    # -- reset -------------------------------------------------------------------------------
    def send_reset(self, seed: int | None) -> None:
        request = ResetLine.Request()
        request.has_seed = seed is not None
        request.seed = int(seed) if seed is not None else 0
        self._reset_future = self.reset_client.call_async(request)

    def reset_done(self) -> bool:
        return self._reset_future is not None and self._reset_future.done()

    def finish_reset(self) -> ResetResult:
        response = self._reset_future.result()
        self._reset_future = None
        if response is None or not response.success:
            raise BridgeError(f"{self.namespace}/reset refused: {getattr(response, 'message', 'no response')}")
        self.tick = Tick(response.stamp, response.episode, 0)
        # States of earlier ticks can no longer be what anyone waits for. The new episode's
        # step-0 state may already be here (the node publishes it before replying): keep it.
        start = stamp_key(response.stamp)
        kept = [s for s in self.inbox if stamp_key(s.header.stamp) >= start]
        self.inbox.clear()
        self.inbox.extend(kept)
        return ResetResult(response.quantity, response.category, response.episode, response.seed, response.stamp)

    def saw_state_of_current_tick(self) -> bool:
        """Whether the step-0 state of the current episode arrived (the handshake's proof)."""
        t = self.tick
        return any(s.episode == t.episode and stamp_key(s.header.stamp) == stamp_key(t.stamp) for s in self.inbox)

    # -- step --------------------------------------------------------------------------------
    def send_action(self, speed_index: int, mode: int) -> None:
        publish_commands(self.speed_pub, self.mode_pub, self.tick.stamp, speed_index, mode)

    def drain(self) -> None:
        _drain(self.state_sub, self.inbox)

    def take_next_state(self) -> bool:
        """Consumes the inbox up to the state of the tick after ours; True once it is there."""
        t = self.tick
        while self.inbox:
            s = self.inbox.popleft()
            if s.episode == t.episode and s.step == t.step + 1:
                self.last_state = s
                self.tick = Tick(s.header.stamp, s.episode, s.step)
                return True
            check_not_taken_over(self.namespace, t.episode, s.episode)
            # Anything else is older (the step-0 state, a previous episode): never returned.
        return False

    def describe_wait(self) -> str:
        t = self.tick
        return (
            f"{self.state_topic} of episode {t.episode} step {t.step + 1} "
            f"(answering the tick stamped {t.stamp.sec}.{t.stamp.nanosec:09d})"
        )


class BatchLink:
    """``batch/cmd`` and ``batch/state`` of a node: every line's command in one message and every
    line's state in one message of arrays, so a round trip over N lines costs two messages, not 2N.

    Both messages cross as bytes, read and written by :mod:`.batch_codec` as numpy records:
    a state batch is a namespace of arrays (entry k = line k). Where the lines stand is the newest
    batch that showed them (``position``): its stamps are what the next command answers, and its
    episodes and steps are compared whole with the next batch's. Nothing is unpacked per line in
    the step loop; that keeps a 16-line round trip close to a one-line one
    (benches/bridge_throughput.py).
    """

    def __init__(self, node: Node, namespace: str, links: list[LineLink]):
        self.links = links
        n = len(links)
        base = namespace.rstrip("/")
        self.state_topic = f"{base}/batch/state"
        self.cmd_pub = node.create_publisher(LineCommands, f"{base}/batch/cmd", QOS)
        self.reset_client = node.create_client(ResetLines, f"{base}/batch/reset", qos_profile=QOS)
        self.reset_name = f"{base}/batch/reset"
        self._reset_future = None
        self.advanced = links[0].advanced
        self._states = BatchCodec(LineStates, n)
        self._commands = BatchCodec(LineCommands, n, None if self.advanced else {"modes": 0})
        #: Received ``batch/state`` messages, serialised (the executor's callback and ``_drain`` both append).
        self.inbox: deque[bytes] = deque(maxlen=64)
        self.state_sub = node.create_subscription(LineStates, self.state_topic, lambda raw: self.inbox.append(raw), QOS, raw=True)
        #: Lines no reset has started yet: they cannot be stepped.
        self.unstarted = set(range(n))
        #: The newest batch showing every line's current tick (after a reset: the reply's states).
        self.position: SimpleNamespace | None = None
        self._next_step = None
        self._speeds = np.array(SPEEDS)

    def matched(self, node: Node) -> bool:
        return (
            self.cmd_pub.get_subscription_count() > 0
            and node.count_publishers(self.state_topic) > 0
            and self.reset_client.service_is_ready()
        )

    def send_reset(self, seeds: dict[int, int | None]) -> None:
        request = ResetLines.Request()
        request.lines = array("I", seeds.keys())
        request.has_seed = [s is not None for s in seeds.values()]
        request.seeds = array("Q", (int(s) if s is not None else 0 for s in seeds.values()))
        self._reset_future = self.reset_client.call_async(request)

    def reset_done(self) -> bool:
        return self._reset_future is not None and self._reset_future.done()

    def finish_reset(self, seeds: dict[int, int | None]) -> dict[int, ResetResult]:
        response = self._reset_future.result()
        self._reset_future = None
        if response is None or not response.success:
            raise BridgeError(f"{self.reset_name} refused: {getattr(response, 'message', 'no response')}")
        # The reply carries every line's state after the reset; lines not reset are where they were.
        b = self.position = from_message(response.states)
        self.unstarted.difference_update(seeds)
        results = {}
        for k in seeds:
            stamp = Time(sec=int(b.stamp_sec[k]), nanosec=int(b.stamp_nanosec[k]))
            results[k] = ResetResult(
                float(b.observation_quantity[k]), int(b.observation_category[k]), int(b.episode[k]), int(b.seed[k]), stamp
            )
        return results

    def check_started(self) -> None:
        if self.unstarted:
            k = min(self.unstarted)
            raise BridgeError(f"{self.links[k].namespace}: step() before reset()")

    def send(self, speed_indices: np.ndarray, modes: np.ndarray) -> None:
        """Answers every line's current tick (the stamps of ``position``)."""
        p = self.position
        fields = {"stamp_sec": p.stamp_sec, "stamp_nanosec": p.stamp_nanosec, "speeds": self._speeds[speed_indices]}
        if self.advanced:
            fields["modes"] = modes
        self._next_step = p.step + 1
        self.cmd_pub.publish(self._commands.encode(**fields))

    def _find(self, step: np.ndarray) -> SimpleNamespace | None:
        """The first batch in the inbox showing every line in its current episode at ``step``;
        older batches are dropped."""
        _drain(self.state_sub, self.inbox)
        episode = self.position.episode
        while self.inbox:
            batch = self._states.decode(self.inbox.popleft())
            if len(batch.step) == len(self.links) and (batch.episode == episode).all() and (batch.step == step).all():
                return batch
            for link, ours, seen in zip(self.links, episode.tolist(), batch.episode.tolist()):
                check_not_taken_over(link.namespace, ours, seen)
        return None

    def saw_current_ticks(self) -> bool:
        """Whether a batch showed every line at its current tick (the handshake after a reset)."""
        return self._find(self.position.step) is not None

    def take_next_states(self) -> bool:
        batch = self._find(self._next_step)
        if batch is None:
            return False
        self.position = batch
        return True

    def describe_wait(self) -> str:
        p, n = self.position, len(self.links)
        ticks = ", ".join(f"{self.links[k].namespace} episode {p.episode[k]} step {p.step[k] + 1}" for k in range(min(n, 4)))
        more = f" and {n - 4} more lines" if n > 4 else ""
        return f"{self.state_topic} with the next state of every line ({ticks}{more})"
