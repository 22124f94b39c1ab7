"""The topics of a sorting line as a bag holds them: what the node publishes for a line and in
which order, the commands it takes, the node-wide topics, the type of each, and the node's options
a bag's line description holds; topic names relative to a line's namespace and back.

Names only: :mod:`sorting_line_gym.bag.storage.schema` holds the type definitions themselves.
"""

from __future__ import annotations

INTERFACES = "sorting_line_interfaces"

#: What the node publishes for one line, in the order it publishes a tick (``events/reset`` comes
#: first on a reset, ``state`` last). Names are relative to the line's namespace.
PUBLISHED = ("events/reset", "events/evolution", "input", "belt/occupancy", "sensors/ratio", "state")
#: Topics of a line's hardware: on an evolving line they come and go with its upgrades, so a
#: recorder or replay cannot wait for them at the start.
HARDWARE = ("sensors/ratio", "cmd/sort_mode")
#: What a controller sends a line, in the order a tick's answer is sent (mode first).
COMMANDS = ("cmd/sort_mode", "cmd/speed")
#: Node-wide topics a bag of a line records by default.
CLOCK = "/clock"

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

#: The type of every topic a line has (relative names), and the node-wide ones.
LINE_TYPES = {
    "input": f"{INTERFACES}/msg/MaterialInput",
    "belt/occupancy": f"{INTERFACES}/msg/BeltOccupancy",
    "sensors/ratio": f"{INTERFACES}/msg/MaterialRatio",
    "state": f"{INTERFACES}/msg/LineState",
    "events/reset": f"{INTERFACES}/msg/ResetEvent",
    "events/evolution": f"{INTERFACES}/msg/EvolutionEvent",
    "cmd/speed": f"{INTERFACES}/msg/SpeedCommand",
    "cmd/sort_mode": f"{INTERFACES}/msg/SortModeCommand",
}
GLOBAL_TYPES = {
    CLOCK: "rosgraph_msgs/msg/Clock",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


def line_topics(variant: str | None, evolving: bool = False) -> list[str]:
    """The relative topics of a line a bag records by default: what the node publishes and the
    commands (the basic line has no ``sensors/ratio`` and no ``cmd/sort_mode``; only an evolving
    line has ``events/evolution``, and every hardware topic, whatever its variant)."""
    names = list(PUBLISHED) + list(COMMANDS)
    if not evolving:
        names.remove("events/evolution")
    if variant == "basic" and not evolving:
        names = [t for t in names if t not in ("sensors/ratio", "cmd/sort_mode")]
    return names


def join(namespace: str, relative: str) -> str:
    """``namespace`` + ``relative`` as an absolute topic name (absolute names stay as they are)."""
    if relative.startswith("/"):
        return relative
    base = namespace.rstrip("/")
    return f"{base}/{relative}"


def relative_to(namespace: str, topic: str) -> str | None:
    """``topic`` relative to ``namespace``, or None when it is not inside it."""
    base = namespace.rstrip("/") + "/"
    return topic[len(base) :] if topic.startswith(base) else None
