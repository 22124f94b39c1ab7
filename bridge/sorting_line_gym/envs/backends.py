"""The Gymnasium ids' entry points: each takes ``backend`` ("ros", the default, or "native") and
makes the env of that backend from the same keyword arguments, checked by the ROS env's
``keywords.Keywords`` (so an unknown or misspelt argument fails the same way on both backends).

- ``backend="ros"``: the env of ``env`` / ``evolving``, one line of a `sorting_line` node over ROS 2.
- ``backend="native"``: ``native.NativeLineEnv``, the library's line in this process (no rclpy).

The vector faces take ``backend`` themselves (``vector.SortingLineVectorEnv``,
``sb3_vec_env.SortingLineSB3VecEnv``): they share one class over either kind of lines.
"""

from __future__ import annotations

from typing import Any

from ..line.vocabulary import check
from .native import BACKENDS, ros_backend


def line_env(backend: str = "ros", **kwargs: Any):
    """``SortingLine-v0`` and ``SortingLineAdvanced-v0``."""
    from .env import KEYWORDS, SortingLineEnv

    if check("backend", backend, BACKENDS) == "ros":
        return ros_backend(lambda: SortingLineEnv(**kwargs))
    from .native import NativeLineEnv

    own, line = KEYWORDS.split(kwargs)
    return NativeLineEnv(KEYWORDS.line_options(line), render_mode=own["render_mode"])


def evolving_env(backend: str = "ros", **kwargs: Any):
    """``SortingLineEvolving-v0``."""
    from .evolving import KEYWORDS, SortingLineEvolvingEnv, schedule_file

    if check("backend", backend, BACKENDS) == "ros":
        return ros_backend(lambda: SortingLineEvolvingEnv(**kwargs))
    from .native import NativeLineEnv

    own, line = KEYWORDS.split(kwargs)
    evolution = str(schedule_file(own["evolution"]))
    return NativeLineEnv(KEYWORDS.line_options(line, variant="advanced", evolution=evolution))
