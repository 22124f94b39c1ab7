"""Which tier a pytest session of tests/python runs: the unit tier (tests/python/unit/, no root, no
ROS environment, no namespace, no node) or the ROS tier (everything else, inside a loopback-only
network namespace). Decided from the paths the session was given, before any test module is imported,
by tests/python/conftest.py; unit/conftest.py reads it back."""

from __future__ import annotations

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
