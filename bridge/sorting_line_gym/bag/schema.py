"""The message types of a sorting_line bag: one `rosbags` typestore (ROS 2 Jazzy's standard types
plus `sorting_line_interfaces`, registered from the .msg text the package was built from), the
rclpy classes for the same names, the topics of a line, and decoded messages as plain values.

Everything that reads, writes or compares bags goes through here, so the schema embedded in a
bag, the CDR a recorder stores and the values a replay compares are the same definitions.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

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

#: The node's QoS (docs/ros-node.md), as a rosbag2 offered QoS profile.
NODE_QOS = Qos(
    history=QosHistory.KEEP_LAST,
    depth=10,
    reliability=QosReliability.RELIABLE,
    durability=QosDurability.VOLATILE,
    deadline=QosTime(0, 0),
    lifespan=QosTime(0, 0),
    liveliness=QosLiveliness.AUTOMATIC,
    liveliness_lease_duration=QosTime(0, 0),
    avoid_ros_namespace_conventions=False,
)


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


def _msg_dirs() -> list[Path]:
    """Where the .msg files of sorting_line_interfaces are: the installed package's share
    directory (what rclpy was built from), else this checkout's msg/."""
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory(INTERFACES)) / "msg")
    except Exception:  # noqa: BLE001 - not installed or no ament index: fall back to the checkout
        pass
    dirs.append(Path(__file__).resolve().parents[3] / "msg" / "msg")
    return [d for d in dirs if d.is_dir()]


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    """Jazzy's standard types plus every message of sorting_line_interfaces."""
    store = get_typestore(Stores.ROS2_JAZZY)
    dirs = _msg_dirs()
    if not dirs:
        raise RuntimeError(f"cannot find the .msg files of {INTERFACES} (installed share directory or msg/msg)")
    types: dict = {}
    for path in sorted(dirs[0].glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"{INTERFACES}/msg/{path.stem}"))
    store.register(types)
    return store


def rclpy_class(msgtype: str):
    """The rclpy message class of ``pkg/msg/Name`` (raises ImportError naming it if missing)."""
    package, kind, name = msgtype.split("/")
    module = importlib.import_module(f"{package}.{kind}")
    try:
        return getattr(module, name)
    except AttributeError:
        raise ImportError(f"{package}.{kind} has no {name}") from None


def to_plain(value: Any) -> Any:
    """A decoded (rosbags) message as plain Python values: dicts of fields, lists, numbers,
    strings; NaN as the string "nan" so that NaN equals NaN in comparisons."""
    if dataclasses.is_dataclass(value):
        # (rosbags adds a __msgtype__ field: the type, not a value of the message)
        return {
            f.name: to_plain(getattr(value, f.name)) for f in dataclasses.fields(value) if not f.name.startswith("__")
        }
    if isinstance(value, np.ndarray):
        return [to_plain(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    return value


def decode(data: bytes | memoryview, msgtype: str) -> dict:
    """CDR bytes of ``msgtype`` as plain values (see :func:`to_plain`)."""
    return to_plain(typestore().deserialize_cdr(data, msgtype))


def stamp_ns(message: dict) -> int | None:
    """The time a decoded message describes: ``header.stamp`` (or ``clock`` for /clock), in ns."""
    t = message.get("header", {}).get("stamp") if isinstance(message.get("header"), dict) else None
    if t is None:
        t = message.get("clock")
    if not isinstance(t, dict):
        return None
    return int(t["sec"]) * 1_000_000_000 + int(t["nanosec"])
