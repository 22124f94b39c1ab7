"""Reading the real ros2 CLI's answers in the tests: a `ros2 ...` command repeated until its output shows
what is wanted, and its YAML output (`ros2 topic echo`, `param dump`, ...) as documents."""

from __future__ import annotations

import subprocess

import yaml

from support.waits import wait_until


def poll(ros2, args: list[str], until, what: str, timeout: float = 15.0, each: float = 15.0, context=None) -> str:
    """Repeats `ros2 ARGS` until `until(stdout)` holds; returns that stdout (fails with the last one,
    and with what `context()` says then)."""
    last: list[subprocess.CompletedProcess] = []

    def answered() -> tuple[str] | None:  # a tuple: an empty answer may be the one wanted
        r = ros2.run(*args, timeout=each, check=False)
        last[:] = [r]
        return (r.stdout,) if r.returncode == 0 and until(r.stdout) else None

    def last_answer() -> str:
        r = last[0]
        return f"last answer (exit {r.returncode}):\n{r.stdout}\n{r.stderr}" + (f"\n{context()}" if context else "")

    (stdout,) = wait_until(answered, timeout, f"`ros2 {' '.join(args)}` to show {what}", poll=0.5, context=last_answer)
    return stdout


def yaml_docs(text: str) -> list:
    return [d for d in yaml.safe_load_all(text) if d is not None]
