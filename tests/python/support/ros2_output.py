"""Reading the real ros2 CLI's answers in the tests: a `ros2 ...` command repeated until its output shows
what is wanted, and its YAML output (`ros2 topic echo`, `param dump`, ...) as documents."""

from __future__ import annotations

import time

import yaml


def poll(ros2, args: list[str], until, what: str, timeout: float = 15.0, each: float = 15.0, context=None) -> str:
    """Repeats `ros2 ARGS` until `until(stdout)` holds; returns that stdout (fails with the last one,
    and with what `context()` says then)."""
    deadline = time.monotonic() + timeout
    last = None
    while True:
        r = ros2.run(*args, timeout=each, check=False)
        if r.returncode == 0 and until(r.stdout):
            return r.stdout
        last = r
        if time.monotonic() > deadline:
            raise AssertionError(
                f"`ros2 {' '.join(args)}` did not show {what} within {timeout} s; last answer "
                f"(exit {last.returncode}):\n{last.stdout}\n{last.stderr}" + (f"\n{context()}" if context else "")
            )
        time.sleep(0.5)


def yaml_docs(text: str) -> list:
    return [d for d in yaml.safe_load_all(text) if d is not None]
