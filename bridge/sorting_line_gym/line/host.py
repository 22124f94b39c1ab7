"""What the environments of one host share: a per-user state directory and the network namespace
(DDS traffic does not cross it, files do). The lock for joining the DDS graph one at a time, which
lives in that directory, is a workaround: ``workarounds/simultaneous_discovery.py``."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def host_state_directory() -> Path:
    """Where this host's bridges coordinate (line servers, joining the graph), per user."""
    path = Path(tempfile.gettempdir()) / f"sorting_line_gym-{os.getuid()}"
    path.mkdir(parents=True, exist_ok=True)
    return path


def network_namespace() -> str:
    """This process's network namespace: DDS traffic does not cross it, files do."""
    try:
        return os.readlink("/proc/self/ns/net")
    except OSError:
        return "host"
