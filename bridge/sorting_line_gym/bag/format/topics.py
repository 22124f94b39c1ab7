"""The topics of a sorting line as a bag holds them: which of the line's topics a bag records, and
the node's options a bag's line description holds; topic names relative to a line's namespace and
back. The names, their types and the order the node publishes them are the package's one topic
vocabulary, :mod:`sorting_line_gym.line.topics`, re-exported here for the bag's layers.

Names only: :mod:`sorting_line_gym.bag.storage.schema` holds the type definitions themselves.
"""

from __future__ import annotations

from ...line.topics import (
    CLOCK,
    COMMANDS,
    EVOLUTION_EVENT,
    GLOBAL_TYPES,
    HARDWARE,
    INTERFACES,
    LINE_TYPES,
    PUBLISHED,
    SENSORS_RATIO,
    SORT_MODE_CMD,
    join,
)

__all__ = ["CLOCK", "COMMANDS", "GLOBAL_TYPES", "HARDWARE", "INTERFACES", "LINE_TYPES", "PUBLISHED", "join"]
__all__ += ["LINE_OPTIONS", "line_topics", "relative_to"]

#: The node's options that describe a line, as `sorting_line node` flags name them (underscores): what
#: a bag's line description holds, whoever recorded it.
LINE_OPTIONS = (
    "variant",
    "input",
    "obs_noise",
    "action_penalty",
    "threshold",
    "max_steps",
    "seed",
    "mode",
    "tick_period",
    "lines",
    "evolution_file",
)


def line_topics(variant: str | None, evolving: bool = False) -> list[str]:
    """The relative topics of a line a bag records by default: what the node publishes and the
    commands (the basic line has no ``sensors/ratio`` and no ``cmd/sort_mode``; only an evolving
    line has ``events/evolution``, and every hardware topic, whatever its variant)."""
    names = list(PUBLISHED) + list(COMMANDS)
    if not evolving:
        names.remove(EVOLUTION_EVENT)
    if variant == "basic" and not evolving:
        names = [t for t in names if t not in (SENSORS_RATIO, SORT_MODE_CMD)]
    return names


def relative_to(namespace: str, topic: str) -> str | None:
    """``topic`` relative to ``namespace``, or None when it is not inside it."""
    base = namespace.rstrip("/") + "/"
    return topic[len(base) :] if topic.startswith(base) else None
