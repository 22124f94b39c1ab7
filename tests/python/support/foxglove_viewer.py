"""Foxglove's own readers as test peers: :class:`Viewer` runs tests/foxglove/live.mjs (the
WebSocket protocol client @foxglove/ws-protocol and the decoder @foxglove/rosmsg2-serialization,
headless under Node.js) against the node's live view and collects what it reports, one JSON event
a line; :func:`read_bags` runs tests/foxglove/bags.mjs (@mcap/core) over bags. The npm packages
are pinned in tests/foxglove/package-lock.json and installed by test.sh's set-up (`npm ci`)."""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sorting_line_gym.line.process import with_parent_death_signal
from support.waits import wait_until

FOXGLOVE = Path(__file__).resolve().parents[2] / "foxglove"

#: The node's log line naming where its live view listens.
LISTENING = re.compile(r"foxglove live view on (ws://\S+)")


def node_js() -> str:
    """The `node` command with the pinned packages installed, or an AssertionError saying what to do."""
    node = shutil.which("node")
    assert node, "Node.js (`node`) is not on PATH: install the distribution's nodejs package"
    assert (FOXGLOVE / "node_modules" / "@foxglove" / "ws-protocol").is_dir(), (
        f"the pinned npm packages are not installed: run `npm ci` in {FOXGLOVE} (test.sh's set-up does)"
    )
    return node


def live_view_url(node_proc, timeout: float = 10.0) -> str:
    """The ws:// address the node logged for its live view (port 0: the one the system chose)."""
    found = wait_until(
        lambda: LISTENING.search(node_proc.log()),
        timeout,
        "the node to log its live view's address",
        context=node_proc.describe,
        abort=lambda: None if node_proc.running() else "the node exited before its live view listened",
    )
    return found.group(1)


class Viewer:
    """`node live.mjs MODE URL` with its events collected by a reader thread; closing its stdin
    ends it (see live.mjs)."""

    def __init__(self, mode: str, url: str, log_path: Path, *extra: object):
        self.mode, self.url = mode, url
        self.events: list[dict[str, Any]] = []
        self.lock = threading.Condition()
        self.stderr = open(log_path, "wb")
        self.proc = subprocess.Popen(
            with_parent_death_signal([node_js(), str(FOXGLOVE / "live.mjs"), mode, url, *map(str, extra)]),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.stderr,
            cwd=FOXGLOVE,
        )
        self.log_path = log_path
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                event = json.loads(line)
            except ValueError:  # a line cut short as the viewer was ended: kept, to show
                event = {"event": "unreadable", "line": line[:200].decode(errors="replace")}
            with self.lock:
                self.events.append(event)
                self.lock.notify_all()

    def of(self, event: str, topic: str | None = None) -> list[dict[str, Any]]:
        with self.lock:
            return [e for e in self.events if e["event"] == event and (topic is None or e.get("topic") == topic)]

    def describe(self) -> str:
        with self.lock:
            counts: dict[str, int] = {}
            for e in self.events:
                key = e["event"] + (f" {e['topic']}" if "topic" in e else "")
                counts[key] = counts.get(key, 0) + 1
        state = "running" if self.proc.poll() is None else f"exited with {self.proc.returncode}"
        return f"viewer `{self.mode}` ({state}); events: {counts}\n--- stderr ---\n{self.log_path.read_text()}"

    def wait_for(self, condition: Callable[[], Any], timeout: float, what: str) -> Any:
        """`condition()`'s first truthy value, or an AssertionError naming `what` after `timeout` s."""
        deadline = time.monotonic() + timeout
        with self.lock:
            while True:
                result = condition()
                if result:
                    return result
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                if self.proc.poll() is not None and not self.reader.is_alive():
                    break
                self.lock.wait(min(remaining, 0.1))
        raise AssertionError(f"timed out after {timeout:.1f} s waiting for the viewer: {what}\n{self.describe()}")

    def close(self, timeout: float = 10.0) -> int:
        """Closes its stdin (it leaves) and waits for it; returns its exit code."""
        if self.proc.stdin and not self.proc.stdin.closed:
            try:
                self.proc.stdin.close()
            except BrokenPipeError:
                pass
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=5)
            raise AssertionError(f"the viewer did not exit within {timeout} s\n{self.describe()}") from None
        self.reader.join(timeout=5)
        self.stderr.close()
        return code


def message_bytes(event: dict[str, Any]) -> bytes:
    return base64.b64decode(event["data"])


def read_bags(bags: list[Path], timeout: float = 60.0) -> dict[str, Any]:
    """What tests/foxglove/bags.mjs reports for each bag directory: its files, each message decoded
    by the schema stored in the bag; {bag: {"counts": {topic: n}, "errors": [...], "files": n}}."""
    r = subprocess.run(
        [node_js(), str(FOXGLOVE / "bags.mjs"), *map(str, bags)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=FOXGLOVE,
    )
    assert r.returncode == 0, f"bags.mjs failed with {r.returncode}\n{r.stdout}\n{r.stderr}"
    return json.loads(r.stdout)
