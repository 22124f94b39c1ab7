"""Ray for the RLlib tests: the environment its workers get (the node binary, RLlib's settings as docs/rllib.md
tells a user of `ray start`), and a head and a worker started as `ray start --block` daemons in the hosts
of a netns_hosts.Hosts."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sorting_line_gym.training.rllib import RAY_ENVIRONMENT
from support import ros_harness as h


def ray_env(**values: str) -> dict[str, str]:
    env = dict(os.environ, PYTHONUNBUFFERED="1", SORTING_LINE_BIN=str(h.node_binary()))
    env.update(RAY_ENVIRONMENT)  # as docs/rllib.md tells a user of `ray start`
    env.update(values)
    return env


class RayCluster:
    """`ray start --block` daemons on the hosts of a netns_hosts.Hosts, all with the same env."""

    def __init__(self, hosts, env: dict[str, str], gcs: str, tmp_path):
        self.hosts, self.env, self.gcs, self.tmp_path = hosts, env, gcs, tmp_path
        self.ray = str(Path(sys.executable).with_name("ray"))
        self.daemons: dict[str, subprocess.Popen] = {}

    def status(self) -> subprocess.CompletedProcess:
        argv = self.hosts.argv("head", [self.ray, "status", f"--address={self.gcs}"])
        return subprocess.run(argv, capture_output=True, text=True, timeout=60, env=self.env)

    def start(self, host: str, flags: str, ready, what: str) -> None:
        """`ray start FLAGS --block` on `host`, until `ready(ray status)`. Ray gives its raylet a fixed
        30 s to register and exits when it is late, which happens on the 2 shared cores under load:
        then it is started again (3 attempts)."""
        log = open(self.tmp_path / f"ray_{host}.log", "a")
        for _ in range(3):
            argv = [self.ray, "start", *flags.split(), "--block"]
            self.daemons[host] = p = self.hosts.popen(host, argv, env=self.env, stdout=log, stderr=subprocess.STDOUT)
            deadline = time.monotonic() + 240
            while not ready(last := self.status()):
                if p.poll() is not None:
                    break
                assert time.monotonic() < deadline, f"{what} within 240 s:\n{last.stdout}\n{last.stderr[-2000:]}"
                time.sleep(2)
            else:
                return
        pytest.fail(f"{what}: `ray start` exited in 3 attempts (log {self.tmp_path}/ray_{host}.log)")

    def stop(self) -> None:
        for host in ("worker", "head"):
            p = self.daemons.get(host)
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGTERM)  # `ray start --block` stops the Ray processes it started
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    p.kill()
