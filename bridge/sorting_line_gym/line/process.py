"""The `sorting_line` node as a child process: finding the binary, a private namespace per node,
starting it with its options (and the parent-death signal: what the bridge starts dies with it),
its log, and stopping it."""

from __future__ import annotations

import itertools
import os
import shutil
import signal
import subprocess
import tempfile
import warnings
from pathlib import Path
from typing import Protocol

from .errors import BridgeError


def with_parent_death_signal(argv: list[str], sig: str = "TERM") -> list[str]:
    """``argv`` behind ``setpriv --pdeathsig SIG --`` where setpriv (util-linux) is installed:
    setpriv execs ``argv`` (same pid) after asking the kernel for ``sig`` when the process that
    started it dies, so a killed bridge, supervisor or test run leaves no node behind. (The signal
    follows the thread that started the process: start it from a thread that lives as long.)"""
    if shutil.which("setpriv"):
        return ["setpriv", "--pdeathsig", sig, "--", *argv]
    return list(argv)


def find_node_binary() -> str:
    """The `sorting_line` binary, the one lookup of bridge, tests and benchmarks: $SORTING_LINE_BIN
    (which must then exist), else this checkout's release build, else PATH."""
    chosen = os.environ.get("SORTING_LINE_BIN")
    if chosen:
        if not (os.path.isfile(chosen) and os.access(chosen, os.X_OK)):
            raise BridgeError(f"SORTING_LINE_BIN = {chosen} is not an executable file")
        return chosen
    repo = Path(__file__).resolve().parents[3]
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


class HeldNode(Protocol):
    """A node process the bridge holds, as a wait watches it: :class:`NodeProcess` (a node it
    started), ``line_server.Lease`` (a line of a shared node) and ``ros.fleet``'s nodes of a fleet
    (several as one). A wait fails at once, with the notice, when ``alive()`` turns False."""

    def alive(self) -> bool: ...

    def death_notice(self) -> str:
        """What happened to the node, with the tail of its log."""
        ...


def file_tail(path: str | Path, lines: int) -> str:
    """The last ``lines`` lines of a child process's log ("" if it cannot be read)."""
    try:
        text = Path(path).read_text(errors="replace").strip().splitlines()
    except OSError:
        return ""
    return "\n".join(text[-lines:])


#: Seconds a node is given to leave on SIGINT, and then on SIGKILL.
STOP_TIMEOUT = 5.0


class NodeProcess:
    """A `sorting_line node` process owned by a bridge: started with the given options in its own
    namespace (plus ``ros_args``, e.g. remaps, after ``--ros-args``), its log kept in a temporary
    file, stopped with SIGINT (SIGKILL if it hangs).

    The log is deleted when the node stopped cleanly (exit code 0) and kept when it failed: then
    its path is in the error (``death_notice``) or in the warning ``stop`` gives. The node gets
    SIGTERM if the bridge dies (``workarounds.orphaned_processes``), so a killed bridge leaves no
    node behind. (The parent-death signal follows the thread that started the node: a
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
        self.process = subprocess.Popen(
            with_parent_death_signal(args), stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT
        )

    def alive(self) -> bool:
        return self.process.poll() is None

    def log_tail(self, lines: int = 8) -> str:
        return file_tail(self.log_path, lines)

    def death_notice(self) -> str:
        return (
            f"the sorting_line node for {self.namespace} exited with code {self.process.returncode}"
            f" (log {self.log_path}):\n{self.log_tail()}"
        )

    def stop(self, timeout: float = STOP_TIMEOUT) -> int | None:
        """Stops the node; returns its exit code. Deletes the log if the node stopped cleanly.

        SIGINT, then SIGKILL if it has not left after ``timeout``, each waited ``timeout`` at most."""
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
