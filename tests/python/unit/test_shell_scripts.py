"""No shell entry point lets a step's failure pass unnoticed.

Each script the repository runs (every tracked ``*.sh``, ``.ci/run`` and the git hooks in ``.githooks/``) starts
with ``set -euo pipefail``, and so does every script it hands to a shell of its own (``bash -c '...'``, inside a
network namespace or not): run.sh once ran its job in such a child shell without errexit and reported success over
two failed steps. A script that is only sourced (env.sh, jobs.sh) says so to shellcheck instead. No script calls one
of its own functions as ``[[ ... ]] && function``: bash runs a function called from an ``&&`` list without errexit,
so a failing command inside it would not end the script. shellcheck (test.sh's lint step) checks the rest.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
#: Scripts that are sourced, never run: they inherit the options of the shell that sources them.
SOURCED = {"launch_scripts/env.sh", "launch_scripts/jobs.sh"}
STRICT = "set -euo pipefail"


def scripts() -> list[str]:
    listed = subprocess.run(
        ["git", "ls-files", "*.sh", ".ci/run", ".githooks"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
    ).stdout.split()
    assert "launch_scripts/run.sh" in listed, listed
    return sorted(listed)


def first_command(lines: list[str]) -> str:
    """The first line that is neither blank nor a comment."""
    return next((line.strip() for line in lines if line.strip() and not line.lstrip().startswith("#")), "")


def strict_problems(script: str, text: str) -> list[str]:
    """Why the script would not run strict (or, when sourced, does not say so)."""
    lines = text.splitlines() or [""]
    if script in SOURCED:
        problems = ["a sourced script needs no shebang"] if lines[0].startswith("#!") else []
        if "# shellcheck shell=bash" not in lines[:3]:
            problems.append("a sourced script tells shellcheck its shell (`# shellcheck shell=bash`)")
        return problems
    if lines[0] != "#!/usr/bin/env bash":
        return [f"the first line is {lines[0]!r}, not #!/usr/bin/env bash"]
    return [] if first_command(lines[1:]) == STRICT else [f"its first command is not `{STRICT}`"]


def child_shell_problems(text: str) -> list[str]:
    """Every `bash -c` script that does not start with `set -euo pipefail`, by line."""
    problems = []
    for match in re.finditer(r"""\bbash -c (['"])\n?""", text):
        if first_command(text[match.end() :].splitlines()) != STRICT:
            line = text.count("\n", 0, match.start()) + 1
            problems.append(f"line {line}: the `bash -c` script does not start with `{STRICT}`")
    return problems


def and_list_problems(text: str) -> list[str]:
    """Every `[[ ... ]] && own_function` statement, by line."""
    functions = set(re.findall(r"^\s*([A-Za-z_]\w*)\(\) \{", text, re.M))
    problems = []
    for number, line in enumerate(text.splitlines(), 1):
        called = re.match(r"^\s*\[\[.*\]\] && ([A-Za-z_]\w*)\b", line)
        if called and called.group(1) in functions:
            problems.append(f"line {number}: `{line.strip()}` runs {called.group(1)} without errexit: use an if")
    return problems


@pytest.mark.parametrize("script", scripts())
def test_the_script_runs_strict_or_says_it_is_sourced(script):
    assert strict_problems(script, (ROOT / script).read_text()) == [], script


@pytest.mark.parametrize("script", scripts())
def test_every_child_shell_runs_strict(script):
    assert child_shell_problems((ROOT / script).read_text()) == [], script


@pytest.mark.parametrize("script", scripts())
def test_no_own_function_runs_behind_an_and_list(script):
    assert and_list_problems((ROOT / script).read_text()) == [], script


def test_the_checks_find_the_bugs_they_guard_against():
    """Each rule on a script that breaks it, the way run.sh once did."""
    assert strict_problems("x.sh", "#!/usr/bin/env bash\nset -eu\n")
    assert strict_problems("x.sh", "#!/bin/sh\nset -euo pipefail\n")
    assert strict_problems("launch_scripts/env.sh", "#!/usr/bin/env bash\n")
    assert not strict_problems("x.sh", "#!/usr/bin/env bash\n# why\n\nset -euo pipefail\n")
    child = "unshare -n bash -c '\n  ip link set lo up\n  job\n'\n"
    assert child_shell_problems(child) == ["line 1: the `bash -c` script does not start with `set -euo pipefail`"]
    assert not child_shell_problems("unshare -n bash -c '\n  set -euo pipefail\n  job\n'\n")
    behind = "install() {\n  false\n}\n[[ $X == 1 ]] && install\n[[ $X == 1 ]] && echo fine\n"
    assert [p.split(":")[0] for p in and_list_problems(behind)] == ["line 4"]
