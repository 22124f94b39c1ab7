"""Bags as `ros2 bag record` writes them in a ROS 2 graph, made with `rosbags`' writer from a golden
bag's messages (the real node's CDR, as recorded): rosbag2 version 9 (Jazzy) metadata, storage
``mcap`` or ``sqlite3``, the file named ``<bag>_0.<ext>`` and ``ros_distro: jazzy``, type hashes
and schemas from the type store, the publishers' offered QoS, and no ``custom_data`` of ours.

Like `ros2 bag record -a` in a real graph, a bag can hold what else was on the graph: ``/rosout``,
the ``/parameter_events`` of a controller declaring its parameters, a topic of a type this project
does not know (``factory_msgs/msg/CellStatus``, schema embedded), and ``/diagnostics`` with the
line's status as the node publishes it (variant, input, seed, mode). The line is moved into
another namespace; the golden bags' own namespace is nowhere in the messages, so only names change.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from sorting_line_gym.bag import open_bag
from sorting_line_gym.bag.storage.schema import NODE_QOS, typestore
from sorting_line_gym.line.topics import DIAGNOSTICS, PARAMETER_EVENTS, ROSOUT

CELL_STATUS = "factory_msgs/msg/CellStatus"
CELL_STATUS_MSG = "string cell\nfloat64 temperature\n"
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}


def _qos(depth: int, durability: QosDurability) -> Qos:
    zero = QosTime(0, 0)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=depth,
        reliability=QosReliability.RELIABLE,
        durability=durability,
        deadline=zero,
        lifespan=zero,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=zero,
        avoid_ros_namespace_conventions=False,
    )


def user_typestore():
    """Jazzy's types, ours, and a type of the user's own (factory_msgs)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register({k: v for k, v in typestore().fielddefs.items() if k.startswith("sorting_line_interfaces/")})
    store.register(get_types_from_msg(CELL_STATUS_MSG, CELL_STATUS))
    return store


def _time(store, ns: int):
    return store.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def diagnostics(store, namespace: str, stamp_ns: int, options: dict):
    """A /diagnostics array with the line's status, as the node publishes it (src/ros/node/diagnostics.rs)."""
    kv = store.types["diagnostic_msgs/msg/KeyValue"]
    values = [kv(key=k, value=str(options[k])) for k in ("seed", "variant", "input", "mode")]
    status = store.types["diagnostic_msgs/msg/DiagnosticStatus"](
        level=0, name=f"sorting_line: {namespace}", message="running", hardware_id="", values=values
    )
    header = store.types["std_msgs/msg/Header"](stamp=_time(store, stamp_ns), frame_id="")
    return store.types["diagnostic_msgs/msg/DiagnosticArray"](header=header, status=[status])


def parameter_event(store, node: str, stamp_ns: int, parameters: dict):
    """``new_parameters`` of ``node`` as a node announces them when it declares them."""
    value_type = store.types["rcl_interfaces/msg/ParameterValue"]

    def value(v):
        kind = {bool: 1, int: 2, float: 3, str: 4}[type(v)]
        fields = {"bool_value": False, "integer_value": 0, "double_value": 0.0, "string_value": ""}
        fields[{1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value"}[kind]] = v
        empty = {
            f"{name}_array_value": np.array([], dtype=dtype)
            for name, dtype in (("byte", np.uint8), ("bool", np.bool_), ("integer", np.int64), ("double", np.float64))
        }
        return value_type(type=kind, string_array_value=[], **empty, **fields)

    parameter = store.types["rcl_interfaces/msg/Parameter"]
    return store.types["rcl_interfaces/msg/ParameterEvent"](
        stamp=_time(store, stamp_ns),
        node=node,
        new_parameters=[parameter(name=k, value=value(v)) for k, v in parameters.items()],
        changed_parameters=[],
        deleted_parameters=[],
    )


def _extras(store, namespace: str, t0: int, options: dict, node_parameters: dict | None) -> list:
    """(topic, msgtype, log_time, message, qos) of what else a `ros2 bag record -a` catches."""
    log = store.types["rcl_interfaces/msg/Log"](
        stamp=_time(store, t0),
        level=20,
        name="sorting_line_controller",
        msg="controlling the line",
        file="controller.py",
        function="main",
        line=1,
    )
    cell = store.types[CELL_STATUS](cell="cell_3", temperature=41.5)
    volatile, local = _qos(1000, QosDurability.VOLATILE), _qos(1000, QosDurability.TRANSIENT_LOCAL)
    extras = [
        (ROSOUT, "rcl_interfaces/msg/Log", t0 - 3_000_000, log, local),
        (
            PARAMETER_EVENTS,
            "rcl_interfaces/msg/ParameterEvent",
            t0 - 2_000_000,
            parameter_event(
                store, f"{namespace}/sorting_line_controller", t0, {"use_sim_time": False, "variant": "basic"}
            ),
            volatile,
        ),
        ("/factory/cell_status", CELL_STATUS, t0 - 1_000_000, cell, NODE_QOS),
        (
            DIAGNOSTICS,
            "diagnostic_msgs/msg/DiagnosticArray",
            t0 - 500_000,
            diagnostics(store, namespace, 0, options),
            NODE_QOS,
        ),
    ]
    if node_parameters is not None:
        node = f"{namespace.rsplit('/', 1)[0] or ''}/sorting_line"
        extras.append(
            (
                PARAMETER_EVENTS,
                "rcl_interfaces/msg/ParameterEvent",
                t0 - 4_000_000,
                parameter_event(store, node, t0, node_parameters),
                volatile,
            )
        )
    return extras


def write_ros2_bag(
    golden: Path, out: Path, storage: str, namespace: str, options: dict, node_parameters: dict | None = None
) -> Path:
    """The golden bag ``golden`` as `ros2 bag record -a` would have written it with its line in
    ``namespace``. ``options``: the line's variant, input, seed and mode for its /diagnostics;
    ``node_parameters``: the node's parameters on /parameter_events too (None: not caught)."""
    bag = open_bag(golden)
    old = bag.info.namespace
    store = user_typestore()
    rename = {t: (namespace + t[len(old) :] if t.startswith(old + "/") else t) for t in bag.types}
    messages = [(rename[m.topic], m.msgtype, m.log_time, m.data, NODE_QOS) for m in bag.messages]
    t0 = messages[0][2]
    for topic, msgtype, log_time, message, qos in _extras(store, namespace, t0, options, node_parameters):
        messages.append((topic, msgtype, log_time, bytes(store.serialize_cdr(message, msgtype)), qos))
    writer = Writer(out, version=9, storage_plugin=STORAGES[storage])
    writer.open()
    connections = {}
    for topic, msgtype, log_time, data, qos in sorted(messages, key=lambda m: m[2]):
        if topic not in connections:
            connections[topic] = writer.add_connection(topic, msgtype, typestore=store, offered_qos_profiles=[qos])
        writer.write(connections[topic], log_time, data)
    writer.close()
    _as_rosbag2_names_it(out)
    return out


def _as_rosbag2_names_it(out: Path) -> None:
    """rosbag2 names the first file ``<bag>_0.<ext>`` and writes its distro into metadata.yaml."""
    meta_path = out / "metadata.yaml"
    meta = yaml.safe_load(meta_path.read_text())
    info = meta["rosbag2_bagfile_information"]
    for k, name in enumerate(info["relative_file_paths"]):
        new = f"{out.name}_{k}{Path(name).suffix}"
        (out / name).rename(out / new)
        info["relative_file_paths"][k] = new
        info["files"][k]["path"] = new
    info["ros_distro"] = "jazzy"
    meta_path.write_text(yaml.safe_dump(meta, sort_keys=False))
