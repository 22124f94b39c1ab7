"""A line server's supervisor, and the file locks line servers are made of (see ``line_server``).

This module imports nothing but the standard library, and runs as a script by its path
(``python line_supervisor.py DIRECTORY INDEX OPTIONS_JSON NODE_COMMAND_JSON``), not through the
package: a supervisor then starts in tens of milliseconds instead of the seconds that importing
Gymnasium, numpy and rclpy take, and envs wait for it while they join the graph.

The supervisor holds ``s<i>.server.lock`` as long as it runs, starts ``sorting_line node --lines
LINES`` through the command it is given (``line_server`` gives the binary behind the parent-death
launcher of ``workarounds.orphaned_processes``, so the node gets SIGTERM if the supervisor dies),
publishes where it serves in ``s<i>.json``, and stops the node and itself when no line has been
leased for ``IDLE_EXIT`` seconds (deciding that with ``start.lock`` held, so nobody leases a line
of a stopping server), when the node dies, or on SIGINT/SIGTERM.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import IO

#: Lines per server node: a node of 16 lines steps as fast per line as one of 1
#: (benches/bridge_throughput.py), and 64 envs take 4 servers.
LINES = 16
#: How long a server with no leased line waits for a new lessee before it stops: with the 0.5 s between
#: checks and the node's stop, no server outlives its last env by more than 10 s (test_line_servers; at
#: IDLE_EXIT 10 it took 10.2 s).
IDLE_EXIT = 8.0


def try_lock(path: Path, shared: bool = False) -> IO[str] | None:
    """An open file holding a flock on ``path``, or None if another process holds it."""
    f = open(path, "a+")
    try:
        fcntl.flock(f, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
        return f
    except BlockingIOError:
        f.close()
        return None


@contextlib.contextmanager
def held(path: Path, timeout: float, what: str, error: type[Exception] = TimeoutError):
    """Holds an exclusive flock on ``path``; raises ``error`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while (f := try_lock(path)) is None:
        if time.monotonic() > deadline:
            raise error(f"timed out after {timeout:g} s waiting for {what} ({path})")
        time.sleep(0.01)
    try:
        yield
    finally:
        f.close()


def server_running(directory: Path, index: int) -> bool:
    probe = try_lock(directory / f"s{index}.server.lock", shared=True)
    if probe is None:
        return True
    probe.close()
    return False


def server_info(directory: Path, index: int) -> dict | None:
    try:
        return json.loads((directory / f"s{index}.json").read_text())
    except (OSError, ValueError):
        return None


def idle(directory: Path, index: int, lines: int) -> bool:
    """Whether no line of server ``index`` is leased (call with the start lock held)."""
    probes = [try_lock(directory / f"s{index}.line{k}.lock") for k in range(lines)]
    try:
        return all(f is not None for f in probes)
    finally:
        for f in probes:
            if f is not None:
                f.close()


def start_node(command: list[str], namespace: str, options: dict[str, object], log: Path) -> subprocess.Popen:
    """``sorting_line node`` (``command`` runs the binary) with ``options`` as flags, in ``namespace``."""
    args = [*command, "node"]
    for key, value in options.items():
        args += [f"--{key.replace('_', '-')}", str(value)]
    args += ["--lines", str(LINES), "--ros-args", "-r", f"__ns:={namespace}"]
    with open(log, "ab") as out:
        return subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT)


def stop_node(node: subprocess.Popen) -> int | None:
    if node.poll() is None:
        node.send_signal(signal.SIGINT)
        try:
            node.wait(5)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait(5)
    return node.returncode


def serve(directory: Path, index: int, options: dict[str, object], command: list[str]) -> int:
    server_lock = try_lock(directory / f"s{index}.server.lock")
    if server_lock is None:
        print(f"line server s{index}: another supervisor holds {directory}/s{index}.server.lock", flush=True)
        return 1
    stop: list[str] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append("SIGTERM"))
    signal.signal(signal.SIGINT, lambda *_: stop.append("SIGINT"))
    namespace = f"/sorting_line_gym/server_{directory.name}_{index}_p{os.getpid()}"  # never reused
    node = start_node(command, namespace, options, directory / f"s{index}.log")
    info = directory / f"s{index}.json"
    info.write_text(json.dumps({"namespace": namespace, "lines": LINES, "pid": os.getpid(), "node_pid": node.pid}))
    print(f"line server s{index}: {LINES} lines in {namespace} (node pid {node.pid})", flush=True)
    idle_since = time.monotonic()
    try:
        while not stop and node.poll() is None:
            time.sleep(0.5)
            with held(directory / "start.lock", 30.0, "the line servers' start lock"):
                if not idle(directory, index, LINES):
                    idle_since = time.monotonic()
                elif time.monotonic() - idle_since > IDLE_EXIT:
                    print(f"line server s{index}: no lease for {IDLE_EXIT:g} s, stopping", flush=True)
                    info.unlink(missing_ok=True)
                    return 0 if stop_node(node) == 0 else 1
        if node.poll() is not None:
            print(f"line server s{index}: the node exited with {node.returncode}", flush=True)
    finally:
        info.unlink(missing_ok=True)
        code = stop_node(node)
        server_lock.close()
    return 0 if code == 0 else 1


def main() -> None:
    if len(sys.argv) != 5:
        sys.exit(
            "usage: line_supervisor.py DIRECTORY INDEX OPTIONS_JSON NODE_COMMAND_JSON (started by sorting_line_gym)"
        )
    directory, index, options, command = Path(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3]), sys.argv[4]
    sys.exit(serve(directory, index, options, json.loads(command)))


if __name__ == "__main__":
    main()
