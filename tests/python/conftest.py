"""pytest set-up of the Python tests: the unit tier (tests/python/unit/) and the ROS tier (the rest).

A session is in the ROS tier unless every path it was given lies inside tests/python/unit/ (decided from
the command line in pytest_configure, before any test module is imported: support/tiers.py). Only the ROS tier fixes the
ROS environment (ROS_DOMAIN_ID from the environment, default 87; Fast DDS with the project's profile)
before rclpy loads, refuses to run outside an isolated (loopback-only) network namespace and checks the
node binary, at session start, as before the tiers existed: so `pytest tests/python`, `pytest
tests/python/test_node.py` or `pytest tests/python/unit tests/python/test_node.py` refuse outside a
namespace exactly as they did, while `pytest tests/python/unit` needs no root, no ROS environment and no
node. Why from the paths and not from the collected items: the guard then still comes before any ROS test
module is imported; and a unit-tier session that collected a test outside unit/ anyway (a path spelled
some way this did not foresee) stops after collection (pytest_collection_modifyitems).

The fixtures below initialise rclpy once per session with one executor and start/stop real node
processes; the unit tests use none of them (unit/conftest.py has the one they need, one_torch_thread,
and keeps rclpy out of a unit-only session).

Run like CI:
    .venv/bin/python -m pytest tests/python/unit -q
    unshare -n bash -c 'ip link set lo up; source launch_scripts/env.sh; export ROS_DOMAIN_ID=87;
                        python -m pytest tests/python --ignore=tests/python/unit -q'
"""

from __future__ import annotations

import itertools
import signal
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from support import ros2_cli, shards, tiers, torch_threads  # noqa: E402
from support import ros_harness as h  # noqa: E402
from support.line_client import LineClient  # noqa: E402


def pytest_configure(config):
    if tiers.decide(config):
        h.ros_environment()  # before anything imports rclpy


def pytest_sessionstart(session):
    if not tiers.is_ros_tier(session.config):
        return
    problem = h.isolation_problem()
    if problem:
        pytest.exit(f"refusing to run the ROS tests: {problem}", returncode=3)
    h.node_binary()  # fails early and clearly when the binary is missing


def pytest_collection_modifyitems(config, items):
    outside = [item.nodeid for item in items if not tiers.in_unit(item.path)]
    if outside and not tiers.is_ros_tier(config):
        pytest.exit(f"a unit-tier session collected tests outside {tiers.UNIT}: {outside[:3]}", returncode=3)


@pytest.hookimpl(tryfirst=True)
def pytest_runtestloop(session):
    """The ROS tier's files shared with other sessions when test.sh runs several (support/shards.py)."""
    return shards.run_claimed(session) if tiers.is_ros_tier(session.config) else None


def pytest_report_header(config):
    if not tiers.is_ros_tier(config):
        return ["sorting_line unit tests (tests/python/unit): no ROS environment, no network namespace, no node"]
    env = h.ros_environment()
    return [
        f"sorting_line ROS tests: node {h.node_binary()}, " + ", ".join(f"{k}={v}" for k, v in env.items()),
        f"ros2 CLI: {ros2_cli.describe()}",
    ]


@pytest.fixture(scope="session")
def ros():
    """rclpy, initialised once, with the session's single SingleThreadedExecutor."""
    session = h.RosSession()
    yield session
    session.shutdown()


@pytest.fixture(scope="session")
def ros2(tmp_path_factory):
    """The real `ros2` command line (tests/python/support/ros2_cli.py); skips with the reason when there is none.

    A graph command (`ros2 topic echo`, `list`, ...) starts a ros2 daemon of its domain when none
    runs, and that daemon outlives pytest; the session stops the one of its domain at the end (a
    test that uses another domain stops that domain's itself)."""
    base = tmp_path_factory.mktemp("ros2cli")
    cli, origin = ros2_cli.locate(base / "overlay", base / "log")
    if cli is None:
        print(f"\n{origin}", file=sys.stderr)
        pytest.skip(origin)
    yield cli
    cli.run("daemon", "stop", timeout=30, check=False)


@pytest.fixture(scope="module")
def ros2_daemon(ros2):
    """The ros2 daemon, running in this test network namespace for one test module (stopped before
    the namespace goes away, and before later modules run)."""
    ros2.run("daemon", "stop", timeout=30, check=False)  # one of an earlier module has another environment
    ros2.run("daemon", "start", timeout=30)
    yield ros2
    ros2.run("daemon", "stop", timeout=30)


@pytest.fixture
def same_binary(monkeypatch):
    """SORTING_LINE_BIN set to the binary this session's nodes run (``h.node_binary()``), so that the
    bag tools, agents, controllers and envs a test starts run that one too. A module asks for it with
    ``pytestmark = pytest.mark.usefixtures("same_binary")``."""
    monkeypatch.setenv("SORTING_LINE_BIN", str(h.node_binary()))


_NAMESPACES = itertools.count()


@pytest.fixture
def namespace(request):
    """namespace(tag) -> a namespace used by no other node of this session (an exited node's
    endpoints stay visible to rclpy for ~50 s, so names are never reused)."""

    def make(tag: str = "") -> str:
        base = h.sanitize(request.node.name)[:40]
        return "/" + h.sanitize(f"t{next(_NAMESPACES)}_{base}_{tag}")

    return make


@pytest.fixture
def start_node(tmp_path, request):
    """start_node(*args, env=None) -> NodeProcess. At teardown every node still running gets SIGINT
    and must exit with 0 within 5 s; a node that died on its own fails the test."""
    nodes: list[h.NodeProcess] = []

    def start(*args, env=None, log_name=None) -> h.NodeProcess:
        log = tmp_path / (log_name or f"node_{len(nodes)}.log")
        node = h.NodeProcess(args, log, env=env)
        nodes.append(node)
        return node

    yield start
    problems = h.stop_problems(nodes, _stop_node_at_teardown)
    if problems:
        pytest.fail("\n\n".join(problems), pytrace=False)


def _stop_node_at_teardown(node: h.NodeProcess) -> str | None:
    """SIGINT to a node the test left running: what is wrong if it does not exit with 0 (or had died)."""
    if node.stopped_by_test:
        return None
    if not node.running():
        problem = f"node exited on its own with {node.proc.returncode}\n{node.describe()}"
        node.kill()
        return problem
    code = node.stop(signal.SIGINT, timeout=5.0)
    return None if code == 0 else f"node exited with {code} after SIGINT (want 0)\n{node.describe()}"


@pytest.fixture
def client_factory(ros):
    """client_factory(namespace, variant, node_proc=..., ...) -> LineClient, destroyed at teardown."""
    clients: list[LineClient] = []

    def make(namespace: str, variant: str = "basic", **kwargs) -> LineClient:
        c = LineClient(ros, namespace, variant, **kwargs)
        clients.append(c)
        return c

    yield make
    for c in clients:
        c.destroy()


@pytest.fixture
def probe(ros):
    """An rclpy node of this test's own (for /clock, /diagnostics, graph queries, parameter clients)."""
    node = ros.make_node("test_probe")
    yield node
    ros.destroy_node(node)


@pytest.fixture
def make_env(request):
    """make_env(id_or_None, **kwargs): gymnasium.make(id, ...) or, with id None, SortingLineEnv(...);
    every env is closed at teardown (a second close is harmless). For the bridge's tests."""
    envs = []

    def close_all():
        errors = []
        for env in reversed(envs):
            try:
                env.close()
            except Exception as e:  # noqa: BLE001 - report every env that fails to close
                errors.append(repr(e))
        assert not errors, f"closing the envs failed: {errors}"

    request.addfinalizer(close_all)

    import gymnasium

    from sorting_line_gym import SortingLineEnv

    def make(env_id=None, **kwargs):
        env = gymnasium.make(env_id, **kwargs) if env_id is not None else SortingLineEnv(**kwargs)
        envs.append(env)
        return env

    return make


@pytest.fixture
def make_vec(request):
    """make_vec(cls, **kwargs): a SortingLineVectorEnv or SortingLineSB3VecEnv closed at teardown."""
    envs = []
    request.addfinalizer(lambda: [env.close() for env in reversed(envs)])

    def make(cls, **kwargs):
        env = cls(**kwargs)
        envs.append(env)
        return env

    return make


@pytest.fixture(scope="module")
def one_torch_thread():
    """One torch thread for a module (support/torch_threads.py)."""
    with torch_threads.one_torch_thread():
        yield
