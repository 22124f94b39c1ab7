"""Which tier a pytest session of tests/python runs: the unit tier (tests/python/unit/, no root, no
ROS environment, no namespace, no node) or the ROS tier (everything else, inside a loopback-only
network namespace). Decided from the paths the session was given, before any test module is imported,
by tests/python/conftest.py; unit/conftest.py reads it back."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

UNIT = Path(__file__).resolve().parents[1] / "unit"

_ROS_TIER = pytest.StashKey[bool]()


def decide(config: pytest.Config) -> bool:
    """Records and returns whether this session is in the ROS tier: unless every path it collects
    from lies in unit/ (an argument that is no path, such as a --pyargs module, counts as outside)."""
    paths = [(config.invocation_params.dir / arg.split("::")[0]).resolve() for arg in config.args]
    config.stash[_ROS_TIER] = not paths or not all(p.is_relative_to(UNIT) for p in paths)
    return config.stash[_ROS_TIER]


def is_ros_tier(config: pytest.Config) -> bool:
    """As decided; undecided means tests/python/conftest.py was not loaded: a session started inside
    unit/ (its rootdir there), which collects only unit tests."""
    return config.stash.get(_ROS_TIER, False)


def in_unit(path: Path) -> bool:
    return path.resolve().is_relative_to(UNIT)


#: The most workers a session of the whole unit tier starts (each imports torch and JAX).
MAX_UNIT_WORKERS = 4


def unit_workers(config: pytest.Config) -> int:
    """pytest-xdist workers of a unit-tier session (unit/pytest.ini's ``-n auto``): one per CPU, at most
    :data:`MAX_UNIT_WORKERS`, when the session is given folders (the whole tier), none when it names a file
    or a test (one process, started at once, where ``--pdb`` and ``-s`` work as usual)."""
    named = [arg for arg in config.args if "::" in arg or not (config.invocation_params.dir / arg).is_dir()]
    return 0 if named else min(MAX_UNIT_WORKERS, len(os.sched_getaffinity(0)))
