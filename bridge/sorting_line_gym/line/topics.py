"""The node's topics, services and action as the Python package names them: one constant per name,
and the table of every endpoint (its type, what the node does with it, where its name lives, its
QoS and on which lines it exists). ``ros/``, ``agents/``, ``bag/`` and the tests take their topic
names from here; no other module of the package writes one (tests/python/unit/test_topics.py checks
both that and this table against the node's own, which ``sorting_line vocabulary`` prints from
src/ros/topics.rs). The README's and docs/ros-node.md's topic table is written from this table
(launch_scripts/docs.py), so the docs cannot drift from it either.

Standard library only: docs.py loads this file before any set-up, and nothing here imports ROS.
"""

from __future__ import annotations

from dataclasses import dataclass

#: The interface package built from msg/.
INTERFACES = "sorting_line_interfaces"

# -- The names (relative to a line's namespace unless absolute) --------------------------------

INPUT = "input"
BELT_OCCUPANCY = "belt/occupancy"
SENSORS_RATIO = "sensors/ratio"
STATE = "state"
RESET_EVENT = "events/reset"
EVOLUTION_EVENT = "events/evolution"
SPEED_CMD = "cmd/speed"
SORT_MODE_CMD = "cmd/sort_mode"
#: The line's reset service.
RESET = "reset"
# In the node's namespace, one for all its lines.
BATCH_CMD = "batch/cmd"
BATCH_STATE = "batch/state"
BATCH_RESET = "batch/reset"
# Absolute.
CLOCK = "/clock"
DIAGNOSTICS = "/diagnostics"
ROSOUT = "/rosout"
PARAMETER_EVENTS = "/parameter_events"


@dataclass(frozen=True)
class Endpoint:
    """One endpoint of the node, with the fields ``sorting_line vocabulary`` prints for it."""

    name: str  # relative to its scope; absolute for scope "global"
    kind: str  # "publishes", "subscribes", "service" (a server) or "action" (a server)
    type: str  # package/msg|srv|action/Name
    scope: str  # "line", "node" (the node's namespace), "global" or "private" (~/name)
    qos: str  # a key of QOS_PROFILES
    when: str  # "always", "advanced" (the line's hardware), "evolving" (an evolving line only)
    note: str = ""  # a remark for the docs' table


@dataclass(frozen=True)
class Qos:
    """A QoS profile as plain values, for each ROS library to build its own object from
    (``ros.links.QOS`` for rclpy, ``bag.storage.schema.NODE_QOS`` for a bag's metadata)."""

    reliability: str  # "reliable" or "best_effort"
    durability: str  # "volatile" or "transient_local"
    depth: int  # of a keep-last history

    def words(self) -> str:
        """The profile as ``sorting_line vocabulary`` prints it: ``reliable, volatile, keep-last 10``."""
        return f"{self.reliability.replace('_', '-')}, {self.durability.replace('_', '-')}, keep-last {self.depth}"


#: The node's QoS for its commands, sensors and state (src/ros/qos.rs, ``default_profile``).
NODE_QOS = Qos(reliability="reliable", durability="volatile", depth=10)

#: The QoS profiles, in words (src/ros/qos.rs has them; ros2-client creates /rosout's and
#: /parameter_events' as rcl does).
QOS_PROFILES = {
    "default": NODE_QOS.words(),
    "action": "rcl_action's: status reliable, transient-local, keep-last 1; the rest default",
    "rosout": "reliable, transient-local, keep-last 1, lifespan 10 s",
    "parameter_events": "reliable, transient-local, keep-last 1",
}


def _ours(interface: str, name: str) -> str:
    return f"{INTERFACES}/{interface}/{name}"


def _line(name: str, kind: str, type_: str, when: str = "always", note: str = "") -> Endpoint:
    return Endpoint(name, kind, type_, "line", "default", when, note)


def _node(name: str, kind: str, type_: str, note: str = "") -> Endpoint:
    return Endpoint(name, kind, type_, "node", "default", "always", note)


def _global(name: str, type_: str, qos: str = "default", note: str = "") -> Endpoint:
    return Endpoint(name, "publishes", type_, "global", qos, "always", note)


def _private(name: str, type_: str, note: str = "", kind: str = "service", qos: str = "default") -> Endpoint:
    return Endpoint(name, kind, type_, "private", qos, "always", note)


_REFUSED = "sets are refused with a reason"

#: Every endpoint of the node, in the order of src/ros/topics.rs (the docs' order).
ENDPOINTS = (
    _line(INPUT, "publishes", _ours("msg", "MaterialInput")),
    _line(BELT_OCCUPANCY, "publishes", _ours("msg", "BeltOccupancy")),
    _line(SENSORS_RATIO, "publishes", _ours("msg", "MaterialRatio"), "advanced"),
    _line(STATE, "publishes", _ours("msg", "LineState"), note="last in each tick"),
    _line(RESET_EVENT, "publishes", _ours("msg", "ResetEvent")),
    _line(EVOLUTION_EVENT, "publishes", _ours("msg", "EvolutionEvent"), "evolving"),
    _line(SPEED_CMD, "subscribes", _ours("msg", "SpeedCommand")),
    _line(SORT_MODE_CMD, "subscribes", _ours("msg", "SortModeCommand"), "advanced"),
    _line(RESET, "service", _ours("srv", "ResetLine")),
    _node(BATCH_CMD, "subscribes", _ours("msg", "LineCommands"), "every line's command, as arrays"),
    _node(BATCH_STATE, "publishes", _ours("msg", "LineStates"), "every line's state, as arrays"),
    _node(BATCH_RESET, "service", _ours("srv", "ResetLines")),
    _global(CLOCK, "rosgraph_msgs/msg/Clock", note="matches best-effort readers"),
    _global(DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray", note="1 Hz"),
    _global(ROSOUT, "rcl_interfaces/msg/Log", "rosout"),
    _global(PARAMETER_EVENTS, "rcl_interfaces/msg/ParameterEvent", "parameter_events"),
    *(
        _private(name, f"rcl_interfaces/srv/{type_}", _REFUSED)
        for name, type_ in (
            ("describe_parameters", "DescribeParameters"),
            ("get_parameters", "GetParameters"),
            ("get_parameter_types", "GetParameterTypes"),
            ("list_parameters", "ListParameters"),
            ("set_parameters", "SetParameters"),
            ("set_parameters_atomically", "SetParametersAtomically"),
        )
    ),
    *(
        _private(name, f"simulation_interfaces/srv/{type_}")
        for name, type_ in (
            ("get_simulator_features", "GetSimulatorFeatures"),
            ("get_simulation_state", "GetSimulationState"),
            ("set_simulation_state", "SetSimulationState"),
            ("step_simulation", "StepSimulation"),
            ("reset_simulation", "ResetSimulation"),
        )
    ),
    _private("simulate_steps", "simulation_interfaces/action/SimulateSteps", kind="action", qos="action"),
)

# -- What the package derives from them --------------------------------------------------------

#: What the node publishes for one line, in the order it publishes a tick (``events/reset`` comes
#: first on a reset, ``state`` last).
PUBLISHED = (RESET_EVENT, EVOLUTION_EVENT, INPUT, BELT_OCCUPANCY, SENSORS_RATIO, STATE)
#: What a controller sends a line, in the order a tick's answer is sent (mode first).
COMMANDS = (SORT_MODE_CMD, SPEED_CMD)
#: Topics of a line's hardware: on an evolving line they come and go with its upgrades, so a
#: recorder or replay cannot wait for them at the start.
HARDWARE = tuple(e.name for e in ENDPOINTS if e.when == "advanced")
#: The type of every topic of a line (relative names; not its service).
LINE_TYPES = {e.name: e.type for e in ENDPOINTS if e.scope == "line" and e.kind in ("publishes", "subscribes")}
#: The types of the node's own absolute topics (not ros2-client's /rosout and /parameter_events).
GLOBAL_TYPES = {e.name: e.type for e in ENDPOINTS if e.name in (CLOCK, DIAGNOSTICS)}


def line_types(evolving: bool = False) -> dict[str, str]:
    """The topics of one line and their types: all of them on an evolving line, else all but
    ``events/evolution`` (whatever the variant: the basic line has the advanced one's names)."""
    return {name: t for name, t in LINE_TYPES.items() if evolving or name != EVOLUTION_EVENT}


def join(namespace: str, relative: str) -> str:
    """``namespace`` + ``relative`` as an absolute topic name (absolute names stay as they are)."""
    if relative.startswith("/"):
        return relative
    base = namespace.rstrip("/")
    return f"{base}/{relative}"
