"""The message types of a sorting_line bag: one `rosbags` typestore (ROS 2 Jazzy's standard types
plus `sorting_line_interfaces`, registered from the .msg text the package was built from), the
node's QoS as a bag stores it, and decoded messages as plain values. (The topics and their type
names are :mod:`..format.topics`; the rclpy classes of the same names,
:func:`..transport.rosnode.rclpy_class`.)

Everything that reads, writes or compares bags goes through here, so the schema embedded in a
bag, the CDR a recorder stores and the values a replay compares are the same definitions.
"""

from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from ...line import topics
from ..format.topics import INTERFACES

#: The node's QoS (``line.topics.NODE_QOS``), as a rosbag2 offered QoS profile.
NODE_QOS = Qos(
    history=QosHistory.KEEP_LAST,
    depth=topics.NODE_QOS.depth,
    reliability=QosReliability[topics.NODE_QOS.reliability.upper()],
    durability=QosDurability[topics.NODE_QOS.durability.upper()],
    deadline=QosTime(0, 0),
    lifespan=QosTime(0, 0),
    liveliness=QosLiveliness.AUTOMATIC,
    liveliness_lease_duration=QosTime(0, 0),
    avoid_ros_namespace_conventions=False,
)


def _msg_dirs() -> list[Path]:
    """Where the .msg files of sorting_line_interfaces are: the installed package's share
    directory (what rclpy was built from), else this checkout's msg/."""
    dirs = []
    try:
        # Optional (a ROS install or the venv's ament index): imported only where it is looked up.
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory(INTERFACES)) / "msg")
    except Exception:  # noqa: BLE001 - not installed or no ament index: fall back to the checkout
        pass
    dirs.append(Path(__file__).resolve().parents[4] / "msg" / "msg")
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
