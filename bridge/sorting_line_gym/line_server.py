"""Line servers: one `sorting_line node` process hosting many lines for every environment of this
host that asks (``node="shared"``), instead of one node process per environment.

Why: every node process is one more DDS participant, and each one a client has to discover
(SPDP, then SEDP for its 30-odd endpoints). Past about a dozen on one host and domain, some
clients never complete endpoint discovery of some nodes (README, "Many envs per host", has the
measurements), and 64 node processes cost start-up time and memory. With line servers, N envs in
P processes on one host are P client participants and ceil(N / LINES) node participants.

Leases are file locks (``fcntl.flock``), held by the process that uses the line: the kernel frees a
lease when its holder exits, however it exits, so a crashed training script leaves no line taken.
All files live in a directory keyed by everything that must match for two envs to share a node:
the node options (variant, setup, episode length, ...), ``ROS_DOMAIN_ID``, the DDS settings, the
node binary, and the network namespace (DDS does not cross it; the file system does).

- ``s<i>.server.lock``: held by server i's supervisor (:func:`main`, a process of its own)
  for as long as its node runs; a free lock means no server.
- ``s<i>.line<k>.lock``: line k of server i; held by the env that leases it.
- ``start.lock``: held for a moment to start a server, to lease a line, or by a supervisor to
  decide that it is idle, so a line is never leased from a server that is stopping.

A supervisor starts its node (which dies with it), then stops both when no line has been leased
for ``IDLE_EXIT`` seconds, or when the node dies. Servers are started detached from the env that
started them: they serve every process on the host, and outlive the first one.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import hashlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from .transport import BridgeError, BridgeTimeout, NodeProcess, find_node_binary

#: Lines per server node: a node of 16 lines steps as fast per line as one of 1
#: (benches/bridge_throughput.py), and 64 envs take 4 servers.
LINES = 16
#: How long a server with no leased line waits for a new lessee before it stops.
IDLE_EXIT = 10.0
#: Environment variables that decide which DDS graph a node joins.
_GRAPH_ENV = ("ROS_DOMAIN_ID", "RMW_IMPLEMENTATION", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS",
              "FASTRTPS_DEFAULT_PROFILES_FILE")


def _netns() -> str:
    try:
        return os.readlink("/proc/self/ns/net")
    except OSError:
        return "host"


def server_directory(options: dict[str, object]) -> Path:
    """The directory of the servers for nodes of ``options`` in this process's DDS graph."""
    graph = {k: os.environ.get(k, "") for k in _GRAPH_ENV}
    key = json.dumps([sorted(options.items()), sorted(graph.items()), _netns(), find_node_binary()], default=str)
    digest = hashlib.sha1(key.encode()).hexdigest()[:16]
    return Path(tempfile.gettempdir()) / f"sorting_line_gym-{os.getuid()}" / digest


def _try_lock(path: Path, shared: bool = False):
    """An open file holding a flock on ``path``, or None if another process holds it."""
    f = open(path, "a+")
    try:
        fcntl.flock(f, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
        return f
    except BlockingIOError:
        f.close()
        return None


@contextlib.contextmanager
def _held(path: Path, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while (f := _try_lock(path)) is None:
        if time.monotonic() > deadline:
            raise BridgeTimeout(f"timed out after {timeout:g} s waiting for {what} ({path})")
        time.sleep(0.02)
    try:
        yield
    finally:
        f.close()


def _server_running(directory: Path, index: int) -> bool:
    probe = _try_lock(directory / f"s{index}.server.lock", shared=True)
    if probe is None:
        return True
    probe.close()
    return False


def _server_info(directory: Path, index: int) -> dict | None:
    try:
        return json.loads((directory / f"s{index}.json").read_text())
    except (OSError, ValueError):
        return None


@dataclass
class Lease:
    """Line ``line`` of server ``index``, held until :meth:`release` (or this process's exit).
    It stands in for the node process in a bank's liveness checks (``alive``, ``death_notice``)."""

    namespace: str
    directory: Path
    index: int
    line: int
    _file: object
    _checked_at: float = 0.0
    _alive: bool = True

    def alive(self) -> bool:
        """Whether the server still runs (its supervisor holds its lock); checked at most every
        0.2 s, as it is asked on every wait of the step loop."""
        now = time.monotonic()
        if now - self._checked_at > 0.2:
            self._checked_at = now
            self._alive = _server_running(self.directory, self.index)
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
        with _held(directory / "start.lock", max(remaining, 0.1), "the line servers' start lock"):
            if not _server_running(directory, index):
                _start_server(directory, index, options, deadline)
            info = _server_info(directory, index)
            if info is None:  # its node died and the supervisor is on its way out: try the next one
                index += 1
                continue
            for k in range(info["lines"]):
                held = _try_lock(directory / f"s{index}.line{k}.lock")
                if held is not None:
                    namespace = f"{info['namespace'].rstrip('/')}/line_{k}"
                    return Lease(namespace, directory, index, k, held)
        index += 1


def _start_server(directory: Path, index: int, options: dict[str, object], deadline: float) -> None:
    (directory / f"s{index}.json").unlink(missing_ok=True)
    log = open(directory / f"s{index}.log", "ab")
    command = [sys.executable, "-c", "from sorting_line_gym.line_server import main; main()",
               str(directory), str(index), json.dumps(options)]
    # A session of its own: the server serves every process of the host, and a Ctrl-C meant for
    # the script that happened to start it must not stop the others' lines.
    process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    log.close()
    while _server_info(directory, index) is None:
        if process.poll() is not None:
            raise BridgeError(f"the line server {directory}/s{index} exited with {process.returncode} at start "
                              f"(log {directory}/s{index}.log)")
        if time.monotonic() > deadline:
            process.kill()
            raise BridgeTimeout(f"timed out waiting for the line server {directory}/s{index} to start")
        time.sleep(0.02)


# ------------------------------------------------------------------------------------------------
# The supervisor: main() with DIRECTORY INDEX OPTIONS_JSON


def _idle(directory: Path, index: int, lines: int) -> bool:
    """Whether no line is leased (call with the start lock held)."""
    held = [_try_lock(directory / f"s{index}.line{k}.lock") for k in range(lines)]
    try:
        return all(f is not None for f in held)
    finally:
        for f in held:
            if f is not None:
                f.close()


def serve(directory: Path, index: int, options: dict[str, object]) -> int:
    server_lock = _try_lock(directory / f"s{index}.server.lock")
    if server_lock is None:
        print(f"line server s{index}: another supervisor holds {directory}/s{index}.server.lock", flush=True)
        return 1
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append("SIGTERM"))
    signal.signal(signal.SIGINT, lambda *_: stop.append("SIGINT"))
    namespace = f"/sorting_line_gym/server_{directory.name}_{index}_p{os.getpid()}"  # never reused
    node = NodeProcess(namespace, dict(options, lines=LINES))
    (directory / f"s{index}.json").write_text(json.dumps({"namespace": namespace, "lines": LINES, "pid": os.getpid(),
                                                          "node_pid": node.process.pid}))
    print(f"line server s{index}: {LINES} lines in {namespace} (node pid {node.process.pid})", flush=True)
    idle_since = time.monotonic()
    try:
        while not stop and node.alive():
            time.sleep(0.5)
            with _held(directory / "start.lock", 30.0, "the line servers' start lock"):
                if not _idle(directory, index, LINES):
                    idle_since = time.monotonic()
                elif time.monotonic() - idle_since > IDLE_EXIT:
                    # Stopped with the start lock held: nobody leases a line of a stopping server.
                    print(f"line server s{index}: no lease for {IDLE_EXIT:g} s, stopping", flush=True)
                    (directory / f"s{index}.json").unlink(missing_ok=True)
                    code = node.stop()
                    server_lock.close()
                    return 0 if code == 0 else 1
        if not node.alive():
            print(node.death_notice(), flush=True)
    finally:
        (directory / f"s{index}.json").unlink(missing_ok=True)
        code = node.stop()
        server_lock.close()
    return 0 if code == 0 else 1


def main() -> None:
    ap = argparse.ArgumentParser(description="a line server's supervisor (started by sorting_line_gym itself)")
    ap.add_argument("directory", type=Path)
    ap.add_argument("index", type=int)
    ap.add_argument("options")
    args = ap.parse_args()
    sys.exit(serve(args.directory, args.index, json.loads(args.options)))


if __name__ == "__main__":
    main()
