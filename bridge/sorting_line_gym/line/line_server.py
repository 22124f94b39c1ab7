"""Line servers: one `sorting_line node` process hosting many lines for every environment of this
host that asks (``node="shared"``), instead of one node process per environment.

Why: every node process is one more DDS participant, and each one a client has to discover
(SPDP, then SEDP for its 30-odd endpoints). Past about a dozen on one host and domain, some
clients never complete endpoint discovery of some nodes (docs/results/many-envs.md has the
measurements), and 64 node processes cost start-up time and memory. With line servers, N envs in
P processes on one host are P client participants and ceil(N / line_supervisor.LINES) node participants.

Leases are file locks (``fcntl.flock``), held by the process that uses the line: the kernel frees a
lease when its holder exits, however it exits, so a crashed training script leaves no line taken.
All files live in a directory keyed by everything that must match for two envs to share a node:
the node options (variant, setup, episode length, ...), ``ROS_DOMAIN_ID``, the DDS settings, the
node binary, and the network namespace (DDS does not cross it; the file system does).

- ``s<i>.server.lock``: held by server i's supervisor (``line_supervisor``, a process of its
  own) for as long as its node runs; a free lock means no server.
- ``s<i>.line<k>.lock``: line k of server i; held by the env that leases it.
- ``start.lock``: held for a moment to start a server, to lease a line, or by a supervisor to
  decide that it is idle, so a line is never leased from a server that is stopping.

A supervisor starts its node (which dies with it), then stops both when no line has been leased
for ``line_supervisor.IDLE_EXIT`` seconds, or when the node dies. Servers are started detached from the env that
started them: they serve every process on the host, and outlive the first one. Leasing happens
while the env holds the host's lock for joining the graph (``host.joining_graph``).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from . import line_supervisor
from .errors import BridgeError, BridgeTimeout
from .host import host_state_directory, network_namespace
from .line_supervisor import held, server_info, server_running, try_lock
from .process import find_node_binary, with_parent_death_signal

#: Environment variables that decide which DDS graph a node joins.
_GRAPH_ENV = (
    "ROS_DOMAIN_ID",
    "RMW_IMPLEMENTATION",
    "ROS_AUTOMATIC_DISCOVERY_RANGE",
    "ROS_STATIC_PEERS",
    "FASTRTPS_DEFAULT_PROFILES_FILE",
)


def server_directory(options: dict[str, object]) -> Path:
    """The directory of the servers for nodes of ``options`` in this process's DDS graph."""
    graph = {k: os.environ.get(k, "") for k in _GRAPH_ENV}
    key = json.dumps(
        [sorted(options.items()), sorted(graph.items()), network_namespace(), find_node_binary()], default=str
    )
    digest = hashlib.sha1(key.encode()).hexdigest()[:16]
    return host_state_directory() / digest


@dataclass
class Lease:
    """Line ``line`` of server ``index``, held until :meth:`release` (or this process's exit).
    A ``process.HeldNode``: it stands in for the node process in a bank's waits."""

    namespace: str
    directory: Path
    index: int
    line: int
    #: The open file whose lock holds the line (None once released).
    _file: IO[str] | None
    _checked_at: float = 0.0
    _alive: bool = True

    def alive(self) -> bool:
        """Whether the server still runs (its supervisor holds its lock); checked at most every
        0.2 s, as it is asked on every wait of the step loop."""
        now = time.monotonic()
        if now - self._checked_at > 0.2:
            self._checked_at = now
            self._alive = server_running(self.directory, self.index)
        return self._alive

    def death_notice(self) -> str:
        log = self.directory / f"s{self.index}.log"
        tail = "\n".join(log.read_text(errors="replace").splitlines()[-8:]) if log.exists() else ""
        return f"the line server hosting {self.namespace} stopped (log {log}):\n{tail}"

    def release(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def stop(self, timeout: float = 5.0) -> None:
        """What a bank calls on its node at close: a shared node is not ours to stop."""
        self.release()


def lease(options: dict[str, object], timeout: float = 20.0) -> Lease:
    """Leases a free line of a server for nodes of ``options``, starting a server when every
    running one is full."""
    directory = server_directory(options)
    directory.mkdir(parents=True, exist_ok=True)
    deadline = time.monotonic() + timeout
    index = 0
    while True:
        remaining = deadline - time.monotonic()
        with held(directory / "start.lock", max(remaining, 0.1), "the line servers' start lock", BridgeTimeout):
            if not server_running(directory, index):
                _start_server(directory, index, options, deadline)
            info = server_info(directory, index)
            if info is None:  # its node died and the supervisor is on its way out: try the next one
                index += 1
                continue
            for k in range(info["lines"]):
                line_file = try_lock(directory / f"s{index}.line{k}.lock")
                if line_file is not None:
                    namespace = f"{info['namespace'].rstrip('/')}/line_{k}"
                    return Lease(namespace, directory, index, k, line_file)
        index += 1


def _start_server(directory: Path, index: int, options: dict[str, object], deadline: float) -> None:
    (directory / f"s{index}.json").unlink(missing_ok=True)
    command = [
        sys.executable,
        line_supervisor.__file__,
        str(directory),
        str(index),
        json.dumps(options),
        json.dumps(with_parent_death_signal([find_node_binary()])),
    ]
    # A session of its own: the server serves every process of the host, and a Ctrl-C meant for
    # the script that happened to start it must not stop the others' lines.
    with open(directory / f"s{index}.log", "ab") as log:
        process = subprocess.Popen(
            command, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
    while server_info(directory, index) is None:
        if process.poll() is not None:
            raise BridgeError(
                f"the line server {directory}/s{index} exited with {process.returncode} at start "
                f"(log {directory}/s{index}.log)"
            )
        if time.monotonic() > deadline:
            process.kill()
            raise BridgeTimeout(f"timed out waiting for the line server {directory}/s{index} to start")
        time.sleep(0.005)
