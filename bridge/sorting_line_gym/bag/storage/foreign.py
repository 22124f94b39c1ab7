"""Bags recorded by other tools (`ros2 bag record` in a ROS 2 graph, MCAP or sqlite3 storage): which
line such a bag recorded and what it tells about the node that served it, since it has none of
the ``custom_data`` that `sorting-line-bag record` stores.

The line is the one topic of type ``LineState`` named ``<namespace>/state`` (any namespace; other
topics may be there too). The node's options come from what the bag holds, each option from the
first source that has it (``info`` shows which; what none has must come from flags):

1. ``/parameter_events``: the ``new_parameters`` of the node serving the line (the nearest node
   whose namespace holds the line's and which announced the line's parameters), as a node
   announces its parameters when it declares them, caught by a recorder started before it;
2. the first ``events/reset`` of the line, when it was seeded: the seed its streams started from;
3. ``/diagnostics``: the line's status (``sorting_line: <namespace>``) names variant, input, seed
   and mode (an evolving line also obs_noise, action_penalty, threshold and evolution_file);
4. the line's states: ``tick_period`` from two consecutive steps' stamps, ``max_steps`` from a
   state that ended its episode by ``truncated``; and ``sensors/ratio`` only exists on an advanced line.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

from ...line.topics import DIAGNOSTICS, PARAMETER_EVENTS, RESET_EVENT, SENSORS_RATIO, STATE
from ...line.vocabulary import SETUPS, THRESHOLD
from ..format.options import NodeOverrides
from ..format.topics import LINE_OPTIONS, LINE_TYPES, join
from .schema import stamp_ns

#: The options a fresh node for a bag needs (replay, closed-loop check): from the bag or from flags.
REQUIRED = ("variant", "input", "obs_noise", "action_penalty", "threshold", "max_steps", "seed", "tick_period")
#: The options a setup (``--setup A..D``) stands for.
SETUP_OPTIONS = ("input", "obs_noise", "action_penalty", "threshold")

Messages = Mapping[str, list]  # topic -> the bag's messages on it (BagMessage: .plain decodes)


def line_namespace_of(types: Mapping[str, str]) -> str | None:
    """The namespace of the one line a bag recorded (``<ns>/state`` of type LineState), or None
    when it has none or several."""
    states = [t for t, ty in types.items() if ty == LINE_TYPES[STATE] and t.endswith(f"/{STATE}")]
    if len(states) != 1:
        return None
    return states[0][: -len(f"/{STATE}")] or "/"


def options_from_topics(namespace: str, messages: Messages) -> tuple[dict, dict]:
    """The node's options the bag's messages tell, and where each came from (see the module's
    docstring): ``(options, sources)``."""
    options: dict = {}
    sources: dict = {}
    finders: list[tuple[str, Callable[[str, Messages], dict]]] = [
        (PARAMETER_EVENTS, _from_parameter_events),
        (RESET_EVENT, _from_first_reset),
        (DIAGNOSTICS, _from_diagnostics),
        ("states", _from_states),
    ]
    for name, find in finders:
        for key, value in find(namespace, messages).items():
            if key not in options and value is not None:
                options[key], sources[key] = value, name
    schedule = options.get("evolution_file")
    if schedule:
        # What the node ran by is on the recording machine; read it if it is here too.
        try:
            options["evolution"] = Path(schedule).read_text()
        except OSError:
            pass
    return options, sources


def with_setup(overrides: NodeOverrides | None) -> dict:
    """Flags as given, with ``setup`` (A..D) expanded into the options it stands for: input,
    obs_noise, action_penalty and the paper's threshold; flags given explicitly win."""
    out = {k: v for k, v in (overrides or {}).items() if v is not None and k != "setup"}
    setup = (overrides or {}).get("setup")
    if setup:
        for key, value in {**SETUPS[setup], "threshold": THRESHOLD}.items():
            out.setdefault(key, value)
    return out


def flags_for(missing: list[str]) -> str:
    """What to pass for the ``missing`` options: each flag, and ``--setup`` where it would do."""
    text = " ".join(f"--{k.replace('_', '-')} ..." for k in missing)
    if set(missing) & set(SETUP_OPTIONS):
        text += f" (--setup A|B|C|D gives {', '.join(SETUP_OPTIONS)})"
    return text


def describe_sources(info) -> list[str]:
    """``info``'s lines for a bag of another recorder: each option with its source, and what is
    not in the bag (the flags a replay needs)."""
    known = ", ".join(f"{k}={info.node[k]} ({info.sources[k]})" for k in LINE_OPTIONS if k in info.sources)
    lines = [
        f"  line {info.namespace} (recorded by another tool, no sorting_line custom_data); from its topics: "
        f"{known or 'no options'}"
    ]
    missing = [k for k in REQUIRED if k not in info.node]
    if missing:
        lines.append(
            f"  not in the bag: {', '.join(missing)}; replay and check --closed-loop need {flags_for(missing)}"
        )
    return lines


def _parameter_value(value: dict):
    """A decoded rcl_interfaces/ParameterValue as a Python value (None: not set or an array)."""
    return {1: value["bool_value"], 2: value["integer_value"], 3: value["double_value"], 4: value["string_value"]}.get(
        value["type"]
    )


def _from_parameter_events(namespace: str, messages: Messages) -> dict:
    """The announced parameters of the nearest node above the line that announced ``max_steps``
    and ``variant`` (the line's node: a controller announces its own, other, parameters)."""
    announced: dict[str, dict] = {}
    for m in messages.get(PARAMETER_EVENTS, []):
        event = m.plain
        values = {p["name"]: _parameter_value(p["value"]) for p in event["new_parameters"]}
        if {"variant", "max_steps"} <= values.keys():
            announced.setdefault(event["node"], {}).update(values)
    nodes = [n for n in announced if _holds(n.rsplit("/", 1)[0] or "/", namespace)]
    if not nodes:
        return {}
    node = max(nodes, key=len)
    values = {k: v for k, v in announced[node].items() if k in LINE_OPTIONS}
    if "seed" in values:
        values["seed"] = int(values["seed"]) + _line_index(namespace, values.get("lines"))
    return values


def _holds(outer: str, inner: str) -> bool:
    return outer == "/" or inner == outer or inner.startswith(outer.rstrip("/") + "/")


def _line_index(namespace: str, lines) -> int:
    """k for ``<ns>/line_k`` of a node hosting several lines (its line k has seed + k)."""
    tail = namespace.rstrip("/").rsplit("/", 1)[-1]
    if lines and int(lines) > 1 and tail.startswith("line_") and tail[5:].isdigit():
        return int(tail[5:])
    return 0


def _from_first_reset(namespace: str, messages: Messages) -> dict:
    resets = messages.get(join(namespace, RESET_EVENT), [])
    first = resets[0].plain if resets else None
    return {"seed": int(first["seed"])} if first and first.get("seeded") else {}


def _from_diagnostics(namespace: str, messages: Messages) -> dict:
    """The first status of the line (``sorting_line: <namespace>``) in ``/diagnostics``."""
    name = f"sorting_line: {namespace}"
    kinds = {"seed": int, "obs_noise": float, "action_penalty": float, "threshold": float}
    for m in messages.get(DIAGNOSTICS, []):
        for status in m.plain.get("status", []):
            if status["name"] != name:
                continue
            values = {kv["key"]: kv["value"] for kv in status["values"]}
            return {
                k: kinds.get(k, str)(values[k])
                for k in (
                    "variant",
                    "input",
                    "seed",
                    "mode",
                    "obs_noise",
                    "action_penalty",
                    "threshold",
                    "evolution_file",
                )
                if values.get(k) not in (None, "")
            }
    return {}


def _from_states(namespace: str, messages: Messages) -> dict:
    out: dict = {}
    previous = None
    for m in messages.get(join(namespace, STATE), []):
        s = m.plain
        if s.get("truncated") and "max_steps" not in out:
            out["max_steps"] = int(s["step"])
        if (
            previous
            and "tick_period" not in out
            and (previous["episode"], previous["step"] + 1) == (s["episode"], s["step"])
        ):
            out["tick_period"] = (stamp_ns(s) - stamp_ns(previous)) / 1e9
        previous = s
        if len(out) == 2:
            break
    if join(namespace, SENSORS_RATIO) in messages:
        out["variant"] = "advanced"
    return out
