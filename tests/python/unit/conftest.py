"""pytest set-up of the unit tier (tests/python/unit/): the tests that need no root, no network namespace,
no DDS, no rclpy and no node process (they may run the native extension, numpy, SB3, torch, JAX, git, and
the `sorting_line` binary's offline commands such as `vocabulary`, `trace` and `eval`).

tests/python/conftest.py decides the tier. In a session of the unit tier alone (`pytest tests/python/unit`)
rclpy cannot be imported in the test process: a test that reaches for it (an env on the ROS backend, a
node's client) fails at once naming the tier, before any DDS participant exists outside a namespace, and
the session stops if rclpy was loaded before the tests ran. So a test that starts needing ROS is noticed
and moved out of unit/ rather than quietly needing a ROS environment. (Subprocesses a test starts are not
covered; none here starts a node.)
"""

from __future__ import annotations

import importlib.abc
import sys
from pathlib import Path

import pytest

# tests/python, for `support`: a session started inside unit/ (rootdir unit/) does not load its conftest.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from support import torch_threads  # noqa: E402
from support.tiers import is_ros_tier, unit_workers  # noqa: E402


class _NoRclpy(importlib.abc.MetaPathFinder):
    """Refuses rclpy (and its submodules) to the unit tier's test process."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname == "rclpy" or fullname.startswith("rclpy."):
            raise ModuleNotFoundError(
                f"{fullname}: the unit tier (tests/python/unit) runs without rclpy; a test that needs ROS "
                "belongs in the ROS tier (tests/python/, run in a network namespace)",
                name=fullname,
            )
        return None


def pytest_xdist_auto_num_workers(config):
    """The workers of pytest.ini's ``-n auto`` (support/tiers.py)."""
    return unit_workers(config)


def _rclpy_modules() -> list[str]:
    return sorted(m for m in sys.modules if m == "rclpy" or m.startswith("rclpy."))[:3]


def pytest_sessionstart(session):
    if is_ros_tier(session.config):
        return
    if _rclpy_modules():
        pytest.exit(f"rclpy was loaded before the unit tests ran ({_rclpy_modules()}): a plugin imports it", 1)
    sys.meta_path.insert(0, _NoRclpy())


@pytest.fixture(scope="module")
def one_torch_thread():
    """One torch thread for a module (support/torch_threads.py)."""
    with torch_threads.one_torch_thread():
        yield
