"""The RIHS01 type hashes the node announces, generated from what rosidl computed.

Jazzy's rosidl installs a type description (`<prefix>/share/<pkg>/<msg|srv>/<Type>.json`) with
the RIHS01 hash of each interface, our own `sorting_line_interfaces` (built from msg/ by
setup.sh) included. The node cannot compute hashes at run time (no ROS install), so it carries
them in src/ros/type_hash_table.rs, written by this module:

    .venv/bin/python tests/python/support/type_hashes.py --write

test_type_hash.py fails when the table differs from rosidl's (a .msg/.srv changed and the
table was not regenerated) and checks that the running node announces them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
TABLE = ROOT / "src" / "ros" / "type_hash_table.rs"

# Interfaces of other packages that the node's endpoints use: its own topics (/clock,
# /diagnostics) and those ros2-client creates for every node (/rosout, /parameter_events, the
# parameter services, ros_discovery_info).
EXTERNAL = [
    "rosgraph_msgs/msg/Clock",
    "diagnostic_msgs/msg/DiagnosticArray",
    "rcl_interfaces/msg/Log",
    "rcl_interfaces/msg/ParameterEvent",
    "rcl_interfaces/srv/DescribeParameters",
    "rcl_interfaces/srv/GetParameterTypes",
    "rcl_interfaces/srv/GetParameters",
    "rcl_interfaces/srv/ListParameters",
    "rcl_interfaces/srv/SetParameters",
    "rcl_interfaces/srv/SetParametersAtomically",
    "rmw_dds_common/msg/ParticipantEntitiesInfo",
    # every action server's status topic and cancel service (simulation_interfaces' SimulateSteps)
    "action_msgs/msg/GoalStatusArray",
    "action_msgs/srv/CancelGoal",
]


# Interface packages built from this repository (by setup.sh): package -> its directory.
PACKAGES = {"sorting_line_interfaces": ROOT / "msg", "simulation_interfaces": ROOT / "msg" / "simulation_interfaces"}


def our_interfaces() -> list[str]:
    """pkg/msg/X, pkg/srv/X and pkg/action/X for every interface file of the packages built from
    msg/ (the node serves every service and action of simulation_interfaces we build)."""
    names = []
    for package, directory in PACKAGES.items():
        for kind in ("msg", "srv", "action"):
            for f in sorted((directory / kind).glob(f"*.{kind}")):
                names.append(f"{package}/{kind}/{f.stem}")
    return names


def share_dir() -> Path:
    """The prefix rosidl installed into: the venv this interpreter runs in."""
    return Path(sys.prefix) / "share"


def rosidl_hash(type_name: str, file_type: str | None = None) -> str:
    """The RIHS01 hash rosidl wrote for `type_name`, found in the description file of
    `file_type` (`pkg/kind/Type`, by default the type itself)."""
    pkg, kind, name = (file_type or type_name).split("/")
    path = share_dir() / pkg / kind / f"{name}.json"
    hashes = json.loads(path.read_text())["type_hashes"]
    return next(h["hash_string"] for h in hashes if h["type_name"] == type_name)


def endpoint_types(type_name: str) -> list[str]:
    """The types whose hashes endpoints announce: a message's own; for a service, its request
    and response (what rmw_fastrtps puts on the request and reply endpoints); for an action, those
    of its goal and result services and its feedback message."""
    pkg, kind, name = type_name.split("/")
    if kind == "action":
        return [
            f"{type_name}_{part}"
            for part in (
                "SendGoal_Request",
                "SendGoal_Response",
                "GetResult_Request",
                "GetResult_Response",
                "FeedbackMessage",
            )
        ]
    return [type_name] if kind == "msg" else [f"{type_name}_Request", f"{type_name}_Response"]


def expected() -> dict[str, str]:
    """(endpoint type, hash) for every interface the node uses; a service's hashes are in its
    own description file."""
    return {
        t: rosidl_hash(t, file_type=interface)
        for interface in sorted(our_interfaces() + EXTERNAL)
        for t in endpoint_types(interface)
    }


def render(table: dict[str, str]) -> str:
    rows = "".join(f'    ("{t}", "{h}"),\n' for t, h in table.items())
    return (
        "//! The RIHS01 hash of every interface the node's endpoints use, as rosidl computed them.\n"
        "//! Generated: `.venv/bin/python tests/python/support/type_hashes.py --write`. Do not edit;\n"
        "//! tests/python/test_graph_citizen.py::test_type_hash_table_is_rosidls "
        "fails when this differs from rosidl's.\n\n"
        "/// (ROS type name, RIHS01 hash), sorted by name; one row a line, as generated (and as\n"
        "/// type_hashes.checked_in reads it back), so rustfmt leaves it alone.\n"
        "#[rustfmt::skip]\n"
        "pub const TYPE_HASHES: &[(&str, &str)] = &[\n"
        f"{rows}"
        "];\n"
    )


def checked_in() -> dict[str, str]:
    """The table in src/ros/type_hash_table.rs."""
    table = {}
    for line in TABLE.read_text().splitlines():
        line = line.strip()
        if line.startswith('("'):
            name, value = (part.strip(' "') for part in line.strip("(),").split(","))
            table[name] = value
    return table


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: type_hashes.py --write   (regenerates src/ros/type_hash_table.rs)")
    TABLE.write_text(render(expected()))
    print(f"wrote {TABLE} ({len(expected())} types)")
