"""The user's controller as a child process of `sorting-line-bag check --controller CMD`: started
with the standard remap ``--ros-args -r __ns:=<the check's namespace>`` appended (so any node that
uses relative topic names, in any language, answers the check's line unchanged), its output kept
in a temporary log, stopped at the end (SIGINT to its process group, SIGKILL if it hangs).

It has the two methods :class:`~sorting_line_gym.ros.waits.Waiter` asks of a process it watches
(``alive``, ``death_notice``): every wait of a check fails at once, naming the controller's exit
code and its last output lines, when the controller dies mid-run.
"""

from __future__ import annotations

import os
import shlex
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

from ...line.process import file_tail, with_parent_death_signal

#: Output lines a death notice shows.
TAIL_LINES = 12


def controller_command(controller: str | list[str] | tuple[str, ...], namespace: str) -> list[str]:
    """The command line to start: CMD (a shell-like string is split as a shell would) plus the
    remap into ``namespace`` (after CMD's own ``--ros-args``, if it has some)."""
    args = shlex.split(controller) if isinstance(controller, str) else [str(a) for a in controller]
    if not args:
        raise ValueError("--controller: empty command")
    remap = ["-r", f"__ns:={namespace}"]
    return args + (
        remap if "--ros-args" in args and "--" not in args[args.index("--ros-args") :] else ["--ros-args", *remap]
    )


class ControllerProcess:
    """A running controller (see the module's docstring)."""

    def __init__(self, controller, namespace: str, env: dict[str, str] | None = None):
        self.command = controller_command(controller, namespace)
        if shutil.which(self.command[0]) is None and not os.path.isfile(self.command[0]):
            raise FileNotFoundError(f"--controller: {self.command[0]!r} is not a program on PATH nor a file")
        # Kept open for the child to write to; stop() closes it.
        self._log = tempfile.NamedTemporaryFile(  # noqa: SIM115
            prefix="sorting_line_check_controller_", suffix=".log", delete=False
        )
        self.log_path = self._log.name
        # Its own process group: stopping it stops what it started (a launch file, a shell script).
        self.process = subprocess.Popen(
            with_parent_death_signal(self.command),
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            env=env if env is not None else os.environ.copy(),
        )
        self.stopped_by_us = False

    def alive(self) -> bool:
        return self.process.poll() is None

    def output_tail(self, lines: int = TAIL_LINES) -> str:
        return file_tail(self.log_path, lines)

    def death_notice(self) -> str:
        return (
            f"the controller ({shlex.join(self.command)}) exited with code {self.process.returncode}; "
            f"its last output lines:\n{self.output_tail()}"
        )

    def stop(self, timeout: float = 5.0) -> int | None:
        """Stops it (if still running) and returns its exit code; deletes the log unless it died
        on its own with a non-zero code."""
        if self.alive():
            self.stopped_by_us = True
            for sig, wait in ((signal.SIGINT, timeout), (signal.SIGKILL, timeout)):
                try:
                    os.killpg(self.process.pid, sig)
                except ProcessLookupError:
                    break
                try:
                    self.process.wait(wait)
                    break
                except subprocess.TimeoutExpired:
                    continue
        if not self._log.closed:
            self._log.close()
            if self.stopped_by_us or self.process.returncode == 0:
                Path(self.log_path).unlink(missing_ok=True)
        return self.process.returncode
