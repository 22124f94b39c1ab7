"""pytest plugin for testing a controller of the sorting line at topic level (entry point ``pytest11``,
so every pytest run in an environment with ``sorting_line_gym`` installed has it; ``-p
sorting_line_gym.testing`` loads it explicitly, ``-p no:sorting_line_gym.testing`` leaves it out).

Nothing happens until a test asks for a fixture; importing this module imports no rclpy. Each test
that uses one gets a graph of its own: a ``ROS_DOMAIN_ID`` of its own (from ``--sorting-line-domain``,
by default 100 + the pid mod 80, then the next of 20 for each test; ``--sorting-line-same-domain``
keeps the first for every test), a namespace of its own, and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (set for the test, restored after it), so nothing
is discovered beyond this host. Outside a loopback-only network namespace (``unshare -n``) the
first such test warns once that DDS traffic stays on this host only by that setting;
``--sorting-line-require-netns`` skips the tests instead.

Fixtures (everything they start is stopped after the test; a node that died fails the test):

- ``sorting_line_graph``: the test's ``domain_id`` and ``namespace``;
- ``sorting_line_node(**options)`` -> :class:`LineNode`: a `sorting_line node` (options as its
  flags: ``setup="D"``, ``variant``, ``seed``, ``max_steps``, ``mode="realtime"``, ``rate``, ...)
  serving the test's namespace, ready (its reset service and state topic discovered);
  ``line.run_episode(seed)`` resets it and waits until a controller has driven the episode to
  its end;
- ``sorting_line_recorder(out=..., topics=None)`` -> :class:`Recording`: `sorting-line-bag record`
  of the test's line (started once it records); ``recording.stop()`` closes the bag;
- ``sorting_line_bag_player(bag, lockstep=True, ...)``: `sorting-line-bag play` of a bag into the
  test's namespace (the keyword arguments of :func:`sorting_line_gym.bag.transport.play.play`);
- ``sorting_line_check(bag, controller=..., closed_loop=..., ...)`` -> the verdict
  `sorting-line-bag check` prints (:func:`check_controller`, with the test's namespace).

:func:`check_controller` itself is importable from here too.
"""

from __future__ import annotations

import itertools
import os
import re
import threading
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from .line.topics import DIAGNOSTICS, INPUT, RESET, SPEED_CMD, STATE
from .workarounds.late_matching import retried_handshake

#: Domains a session's tests take in turn, from the first (``--sorting-line-domain``).
DOMAINS_PER_SESSION = 20
#: Node start-up (a busy CI machine) and the longest wait for the line's first answer.
READY_TIMEOUT, FIRST_ANSWER_TIMEOUT = 30.0, 3.0


def __getattr__(name: str):
    # check_controller imports rclpy: only when asked for.
    if name == "check_controller":
        from .bag.check.checker import check_controller

        return check_controller
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def pytest_addoption(parser):
    group = parser.getgroup("sorting_line", "sorting_line_gym.testing (ROS 2 graphs of the sorting line per test)")
    group.addoption(
        "--sorting-line-domain",
        type=int,
        default=None,
        metavar="N",
        help="first ROS_DOMAIN_ID of the tests' graphs (each test takes the next of "
        f"{DOMAINS_PER_SESSION}; default 100 + pid mod 80)",
    )
    group.addoption(
        "--sorting-line-same-domain",
        action="store_true",
        help="every test on the first domain (for ROS objects that outlive a test: a session-wide "
        "rclpy context, a module-scoped env); tests still get namespaces of their own",
    )
    group.addoption(
        "--sorting-line-require-netns",
        action="store_true",
        help="skip the tests that start ROS graphs unless in a loopback-only network namespace",
    )


def isolation_problem() -> str | None:
    """None inside a loopback-only network namespace; otherwise what is there besides ``lo``."""
    try:  # (/proc/net follows this process's network namespace; /sys/class/net may show the host's)
        rows = Path("/proc/net/dev").read_text().splitlines()[2:]
    except OSError:
        return "cannot tell whether this is a loopback-only network namespace (no /proc/net/dev)"
    others = sorted(name for row in rows if (name := row.split(":", 1)[0].strip()) != "lo")
    if others:
        return f"not in a loopback-only network namespace (interfaces {', '.join(others)} besides lo)"
    return None


@dataclass
class Graph:
    """The ROS 2 graph of one test: its domain and namespace (set in the environment for the test)."""

    domain_id: int
    namespace: str
    _names: itertools.count = field(default_factory=itertools.count, repr=False)

    def sub_namespace(self, tag: str = "") -> str:
        """A namespace inside the test's for a second line, player, ... (``<ns>/<tag>_<n>``)."""
        return f"{self.namespace}/{_token(tag or 'ns')}_{next(self._names)}"


_TESTS = itertools.count()


def _token(text: str) -> str:
    token = re.sub(r"[^A-Za-z0-9_]", "_", text)[:48]
    return token if token[:1].isalpha() else f"t{token}"


@pytest.fixture
def sorting_line_graph(request, monkeypatch) -> Graph:
    """The test's own ROS_DOMAIN_ID and namespace, discovery on this host only."""
    config = request.config
    problem = isolation_problem()
    if problem and config.getoption("--sorting-line-require-netns"):
        pytest.skip(f"--sorting-line-require-netns: {problem}")
    if problem and not getattr(config, "_sorting_line_warned", False):
        config._sorting_line_warned = True
        warnings.warn(
            pytest.PytestWarning(
                f"sorting_line_gym.testing: {problem}: the tests' DDS traffic stays on this host only through "
                "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (run under `unshare -n` with lo up to isolate it fully, "
                "or pass --sorting-line-require-netns to skip instead)"
            ),
            stacklevel=1,
        )
    k = next(_TESTS)
    same = config.getoption("--sorting-line-same-domain")
    domain = domain_of_test(config.getoption("--sorting-line-domain"), k, same)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    return Graph(domain, f"/sorting_line_test/{_token(request.node.name)}_{os.getpid()}_{k}")


def domain_of_test(first: int | None, k: int, same: bool = False) -> int:
    """The ROS_DOMAIN_ID of the session's k-th test (``first``: --sorting-line-domain, or None)."""
    if first is None:
        first = 100 + os.getpid() % 80
    if not 0 <= first <= 232 - DOMAINS_PER_SESSION:
        raise pytest.UsageError(
            f"--sorting-line-domain {first}: the tests' domains {first}.."
            f"{first + DOMAINS_PER_SESSION - 1} must lie within 0..232"
        )
    return first if same else first + k % DOMAINS_PER_SESSION


class LineNode:
    """A `sorting_line node` serving ``namespace``, and an rclpy node of the test's own that
    resets it and watches its states (``states``: every LineState received, in order)."""

    def __init__(self, namespace: str, options: dict):
        from .line.process import NodeProcess

        self.namespace = namespace
        self.options = dict(options)
        self.process = NodeProcess(namespace, self.options)
        self.states: list = []
        self._tool = None
        self._reset_client = None
        self._input_matches = None

    def wait_ready(self, timeout: float = READY_TIMEOUT) -> None:
        """Until the node's reset service and state topic are discovered (TimeoutError, with the
        node's log if it died, otherwise)."""
        from sorting_line_interfaces.msg import LineState
        from sorting_line_interfaces.srv import ResetLine

        from .bag.transport.rosnode import DEEP_QOS, ToolNode

        self._tool = tool = ToolNode("sorting_line_test", self.process)
        self._reset_client = tool.node.create_client(ResetLine, f"{self.namespace}/{RESET}")
        tool.node.create_subscription(LineState, f"{self.namespace}/{STATE}", self.states.append, DEEP_QOS)
        tool.until(
            lambda: (
                self._reset_client.service_is_ready() and tool.node.count_publishers(f"{self.namespace}/{STATE}") > 0
            ),
            timeout,
            f"the sorting_line node serving {self.namespace}",
        )

    def reset(self, seed: int | None = None, timeout: float = 10.0):
        """Resets the line (``seed`` None: the streams carry on); returns the service's response."""
        from sorting_line_interfaces.srv import ResetLine

        request = ResetLine.Request(has_seed=seed is not None, seed=int(seed or 0))
        future = self._reset_client.call_async(request)
        self._tool.until(future.done, timeout, f"the reply of {self.namespace}/{RESET}")
        response = future.result()
        if not response.success:
            raise AssertionError(f"{self.namespace}/{RESET} refused: {response.message}")
        return response

    def run_episode(self, seed: int | None = None, timeout: float = 60.0, attempts: int = 3) -> list:
        """Resets the line and waits until the controller driving it has ended the episode
        (a state with ``truncated`` or ``terminated``); returns the episode's states.

        A reset whose first tick nobody answers within a few seconds (a controller still
        discovering the node misses the tick's readings) is repeated, up to ``attempts`` times: a
        seeded reset repeated is the same episode. Not on an evolving line (``evolution=``
        option), where each reset is the schedule's next episode: there the reset waits (up to
        ``timeout``) until a controller's publisher and subscription on the line are seen, and is
        sent once."""

        def first_answer(limit: float) -> int:
            episode = self.reset(seed).episode
            self._until_state(
                lambda s: s.episode == episode and s.step >= 1,
                limit,
                f"the first answer to episode {episode} of {self.namespace}",
            )
            return episode

        if self.options.get("evolution") is None:
            episode = retried_handshake(first_answer, [FIRST_ANSWER_TIMEOUT] * attempts, TimeoutError)
        else:
            self._until_controller(timeout)
            episode = first_answer(FIRST_ANSWER_TIMEOUT * attempts)
        self._until_state(
            lambda s: s.episode == episode and (s.truncated or s.terminated),
            timeout,
            f"the end of episode {episode} of {self.namespace}",
        )
        return [s for s in self.states if s.episode == episode]

    def _until_controller(self, timeout: float) -> None:
        """Until a controller reads the line's input and writes its speed commands, and the node
        has matched its input reader."""
        from .bag.transport.rosnode import InputMatches, controller_seen

        self._tool.until(
            lambda: controller_seen(self._tool.node, self.namespace),
            timeout,
            f"a controller of {self.namespace} (a reader of {INPUT}, a writer of {SPEED_CMD})",
        )
        # Seen here is not yet matched by the node, which sends a tick's input only to the readers
        # it has matched: a reset whose input the controller missed is never answered, and here it
        # is not repeated. So wait for the node's word: a fixed settle time is not enough under load
        # (1 s was not, at load 7).
        matches = self._input_matches or InputMatches(self._tool.node)
        self._input_matches = matches
        self._tool.until(
            lambda: matches.all_matched(self.namespace),
            timeout,
            f"the node serving {self.namespace} to match every reader of its {INPUT} (input_readers on {DIAGNOSTICS})",
        )

    def _until_state(self, wanted, timeout: float, what: str) -> None:
        self._tool.until(lambda: any(wanted(s) for s in self.states), timeout, what)

    def stop(self) -> str | None:
        """Stops the node; a problem to report (it died, or exited with an error), or None."""
        died = None if self.process.alive() else self.process.death_notice()
        if self._tool is not None:
            self._tool.close()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the exit code is reported here instead
            code = self.process.stop()
        if died:
            return f"the node died during the test: {died}"
        return None if code == 0 else f"the node exited with {code} when stopped (log {self.process.log_path})"


@pytest.fixture
def sorting_line_node(sorting_line_graph):
    """``sorting_line_node(namespace=None, **options)`` -> a ready :class:`LineNode` (the first in
    the test's namespace, later ones in namespaces inside it); stopped after the test."""
    nodes: list[LineNode] = []

    def start(namespace: str | None = None, ready_timeout: float = READY_TIMEOUT, **options) -> LineNode:
        ns = namespace or (sorting_line_graph.sub_namespace("line") if nodes else sorting_line_graph.namespace)
        node = LineNode(ns, options)
        nodes.append(node)
        node.wait_ready(ready_timeout)
        return node

    yield start
    problems = [p for p in (n.stop() for n in nodes) if p]
    if problems:
        pytest.fail("\n".join(problems), pytrace=False)


class Recording:
    """`sorting-line-bag record` of a line, in a thread of this process, started once it records."""

    def __init__(self, namespace: str, out: Path, topics: list[str] | None, wait: float):
        self.namespace, self.path = namespace, Path(out)
        self.lines: list[str] = []  # what the recorder reported (recording ..., matched ...)
        self.result = None
        self._stop, self._ready = threading.Event(), threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(
            target=self._run, args=(topics, wait), daemon=True, name=f"sorting_line_recorder {namespace}"
        )
        self._thread.start()
        if not self._ready.wait(wait + 30.0) or self._error is not None:
            self.stop()
            raise AssertionError(f"the recorder of {namespace} did not start: {self._error or 'no answer'}")

    def _run(self, topics, wait) -> None:
        from .bag.transport.record import record

        def said(line: str) -> None:
            self.lines.append(line)
            self._ready.set()

        try:
            self.result = record(self.namespace, self.path, topics, wait=wait, stop=self._stop.is_set, on_ready=said)
        except BaseException as e:  # noqa: BLE001 - handed to the test's thread
            self._error = e
        finally:
            self._ready.set()

    def wait_matched(self, relative: str, publishers: int = 1, timeout: float = 20.0) -> None:
        """Until the recorder has matched ``publishers`` writers of the line's ``relative`` topic
        (a controller's commands sent before that are not in the bag)."""
        want = f"matched {self.namespace.rstrip('/')}/{relative}: "
        deadline = time.monotonic() + timeout
        while not any(line.startswith(want) and int(line[len(want) :].split()[0]) >= publishers for line in self.lines):
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"the recorder of {self.namespace} matched no {publishers} writer(s) of {relative} "
                    f"in {timeout} s (it said: {self.lines})"
                )
            time.sleep(0.05)

    def stop(self, timeout: float = 30.0):
        """Stops recording and closes the bag; returns the RecordResult (``.path``, ``.counts``)."""
        self._stop.set()
        self._thread.join(timeout)
        if self._thread.is_alive():
            raise TimeoutError(f"the recorder of {self.namespace} did not stop within {timeout} s")
        if self._error is not None:
            raise self._error
        return self.result


@pytest.fixture
def sorting_line_recorder(sorting_line_graph, tmp_path):
    """``sorting_line_recorder(out=None, namespace=None, topics=None, wait=10.0)`` -> a started
    :class:`Recording` of the test's line (``out`` default: ``<tmp_path>/recorded``)."""
    recordings: list[Recording] = []

    def start(
        out: str | Path | None = None, namespace: str | None = None, topics: list[str] | None = None, wait: float = 10.0
    ) -> Recording:
        path = Path(out) if out is not None else tmp_path / f"recorded{len(recordings) or ''}"
        recording = Recording(namespace or sorting_line_graph.namespace, path, topics, wait)
        recordings.append(recording)
        return recording

    yield start
    for r in recordings:
        if r._thread.is_alive():
            r.stop()


@pytest.fixture
def sorting_line_bag_player(sorting_line_graph):
    """``sorting_line_bag_player(bag, namespace=None, **play_options)`` -> PlayResult: plays the
    bag's node side into the test's namespace (``lockstep=True`` for tick by tick), and returns
    when it is played."""

    def play_bag(bag: str | Path, namespace: str | None = None, **options):
        from .bag.transport.play import play

        options.setdefault("on_ready", lambda _line: None)
        return play(bag, namespace=namespace or sorting_line_graph.namespace, **options)

    return play_bag


@pytest.fixture
def sorting_line_check(sorting_line_graph):
    """``sorting_line_check(bag, controller=None, closed_loop=False, **options)`` -> the Verdict
    `sorting-line-bag check` prints (``verdict.passed``, ``.exit_code``, ``.summary()``), run in the
    test's graph and namespace."""

    def check(bag: str | Path, **options):
        from .bag.check.checker import check_controller

        options.setdefault("namespace", sorting_line_graph.namespace)
        return check_controller(bag, **options)

    return check


def pytest_report_header(config):
    first = config.getoption("--sorting-line-domain")
    first = first if first is not None else 100 + os.getpid() % 80
    where = "a loopback-only network namespace" if isolation_problem() is None else "this host (LOCALHOST discovery)"
    last = first + DOMAINS_PER_SESSION - 1
    return [f"sorting_line_gym.testing: each test's ROS graph on a domain from {first}..{last}, in {where}"]
