"""The ROS tier in several pytest sessions at once, sharing its test files (launch_scripts/test.sh).

Why: most ROS tests wait (for discovery, a node's start, a training's subprocess), so one session
keeps a 2-core machine about half busy; two sessions, each in a network namespace of its own with a
domain id of its own, finish the tier sooner. Each session collects the whole tier, then takes test
files one at a time from a shared folder of claims (``SORTING_LINE_TEST_CLAIMS``): a file is run by
the session that claims it first (an ``O_EXCL`` create, atomic between processes), so the sessions
balance themselves whatever the files cost, and no test runs twice or not at all. A session reports
the files it did not claim as deselected.

What stays as in one session: a file's tests run in their order in one process, with its module
fixtures; the session's fixtures (rclpy, the ros2 CLI) are set up once per session. Files that must
not run at the same time on one machine are claimed together (:data:`TOGETHER`). The slowest files
are claimed first (:data:`SLOWEST_FIRST`), so that no session starts a long file when the other is
about to end; a file missing from that list only costs balance.

Without ``SORTING_LINE_TEST_CLAIMS`` pytest's own loop runs, as always.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

CLAIMS = "SORTING_LINE_TEST_CLAIMS"

#: Claimed as one: Ray's daemons keep machine-wide state under /tmp/ray (its session folders and the
#: current cluster's address), so two Ray clusters are never started at once.
TOGETHER = (("test_rllib.py", "test_ray_cells.py"),)

#: The files taking the longest, longest first (a fresh clone's --durations, 2026-12-03: the engine
#: check 224 s, run.sh's jobs 250 s, Ray's tests 200 s, ...).
SLOWEST_FIRST = (
    "test_run_sh.py",
    "test_rllib.py",
    "test_engine_check.py",
    "test_training.py",
    "test_deploying_a_policy.py",
    "test_transfer_resume.py",
    "test_bridge.py",
    "test_pytest_plugin.py",
    "test_studies_batched.py",
    "test_wheel.py",
    "test_vectorizers.py",
    "test_multihost.py",
)


def claims_folder() -> Path | None:
    value = os.environ.get(CLAIMS)
    if not value:
        return None
    folder = Path(value)
    if not folder.is_dir():
        raise pytest.UsageError(f"{CLAIMS}={value!r}: no such folder (test.sh makes it for its ROS-tier sessions)")
    return folder


def units(items: list[pytest.Item]) -> list[tuple[str, list[pytest.Item]]]:
    """The session's items as claimable units (a file, or the files of a TOGETHER group), in the order
    they are claimed: SLOWEST_FIRST, then the collection's order; within a unit, the collection's order."""
    group_of = {name: "+".join(group) for group in TOGETHER for name in group}
    by_unit: dict[str, list[pytest.Item]] = {}
    for item in items:
        name = item.path.name
        by_unit.setdefault(group_of.get(name, name), []).append(item)
    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}

    def order(unit: tuple[str, list[pytest.Item]]) -> int:
        return min(rank.get(name, len(rank)) for name in unit[0].split("+"))

    return sorted(by_unit.items(), key=order)  # stable: ties keep the collection's order


def claim(folder: Path, unit: str) -> bool:
    """True when this session is the first to claim ``unit``."""
    try:
        fd = os.open(folder / f"{unit}.claim", os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        return False
    with os.fdopen(fd, "w") as f:
        f.write(f"{os.getpid()}\n")
    return True


def run_claimed(session: pytest.Session) -> bool | None:
    """pytest_runtestloop for a session sharing its files; None (pytest's own loop) without a claims folder.
    Mirrors _pytest.main.pytest_runtestloop, but runs only the units this session claims."""
    folder = claims_folder()
    if folder is None:
        return None
    if session.testsfailed and not session.config.option.continue_on_collection_errors:
        raise session.Interrupted(f"{session.testsfailed} errors during collection")
    if session.config.option.collectonly:
        return True
    all_units = units(session.items)
    firsts = [items[0] for _, items in all_units]
    skipped: list[pytest.Item] = []
    for index, (unit, items) in enumerate(all_units):
        if not claim(folder, unit):
            skipped.extend(items)
            continue
        # The item after a unit's last is one of another file, run or not: pytest then tears down this
        # file's module fixtures and keeps the session's (None would end rclpy's session too).
        other = next((first for j, first in enumerate(firsts) if j != index), None)
        for i, item in enumerate(items):
            nextitem = items[i + 1] if i + 1 < len(items) else other
            item.config.hook.pytest_runtest_protocol(item=item, nextitem=nextitem)
            if session.shouldfail:
                raise session.Failed(session.shouldfail)
            if session.shouldstop:
                raise session.Interrupted(session.shouldstop)
    if skipped:
        session.config.hook.pytest_deselected(items=skipped)
        files = len({item.path for item in skipped})
        reporter = session.config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.ensure_newline()
            reporter.write_line(
                f"shards: {len(skipped)} tests of {files} files ran in another session (claims in {folder})"
            )
    return True
