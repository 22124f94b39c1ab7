"""Line servers (``node="shared"``) meet the conditions under which "shared" may be the envs' default:

1. every env's trajectory equals the library's (and so "spawn"'s) for the same seed: test_vectorizers's
   SyncVectorEnv of 64 shared envs checks every env against `sorting_line trace`;
2. a dead line server fails only the envs that leased from it, with an error that says so (here);
3. no line server outlives its last env by more than 10 s (here).

Each test uses a threshold no other test uses, so its envs get line servers of their own. About 25 s.
"""

from __future__ import annotations

import os
import signal
import time

import gymnasium
import pytest

import sorting_line_gym  # noqa: F401 - registers the Gymnasium ids
from sorting_line_gym import BridgeError
from sorting_line_gym.line import line_supervisor
from support.env_trace import BASIC, assert_episode_follows_trace, fixed_actions
from support.waits import wait_until

OUTLIVE_LIMIT = 10.0  # s: the longest a line server may outlive its last env (the project's rule for the default)


def server_of(env) -> tuple[dict, object]:
    lease = env.unwrapped.bank.process
    info = line_supervisor.server_info(lease.directory, lease.index)
    assert info is not None, f"no server info for {lease}"
    return info, lease


def pid_alive(pid: int) -> bool:
    """Running, not a zombie: the supervisor is this process's child when one of its envs started it."""
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def test_a_dead_line_server_fails_only_its_own_envs(make_env):
    doomed = make_env(BASIC, setup="A", node="shared", threshold=0.61)
    other = make_env(BASIC, setup="A", node="shared")  # the default threshold, as the library's trace
    for env in (doomed, other):
        env.reset(seed=3)
        env.step(4)
    info, _ = server_of(doomed)
    assert info["pid"] != server_of(other)[0]["pid"], "the two configurations must be served by two servers"
    os.kill(info["node_pid"], signal.SIGKILL)
    with pytest.raises(BridgeError, match="line server") as failure:
        for _ in range(20):  # the lease notices within a step or two (its liveness check is every 0.2 s)
            doomed.step(4)
    print(f"\nthe doomed env's error: {failure.value}")
    # The other server's env goes on, and stays exact.
    assert_episode_follows_trace(other.unwrapped, "A", "basic", 9, fixed_actions(10, 10, 9), "the other server's env")


def test_a_line_server_stops_within_10_s_of_its_last_env():
    env = gymnasium.make(BASIC, setup="A", node="shared", threshold=0.63)
    env.reset(seed=1)
    env.step(2)
    info, _ = server_of(env)
    env.close()
    closed = time.monotonic()
    # 60 s, not OUTLIVE_LIMIT: the wait measures how long they outlive it, and the limit is asserted below.
    wait_until(
        lambda: not (pid_alive(info["pid"]) or pid_alive(info["node_pid"])),
        60,
        "the line server and its node to exit after their last env closed",
        poll=0.1,
        context=lambda: (
            f"line server {info['pid']} alive: {pid_alive(info['pid'])}, "
            f"node {info['node_pid']} alive: {pid_alive(info['node_pid'])}"
        ),
    )
    outlived = time.monotonic() - closed
    print(f"\nthe line server and its node exited {outlived:.1f} s after the last env closed")
    assert outlived <= OUTLIVE_LIMIT, f"the line server outlived its last env by {outlived:.1f} s"
