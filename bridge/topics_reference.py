"""The node's topic table in README.md and docs/ros-node.md, written from the package's topic
vocabulary (sorting_line_gym/line/topics.py, itself checked against the node's table by
tests/python/unit/test_topics.py) between two markers in each page, so the pages cannot drift apart
or from the node. launch_scripts/docs.py calls ``rewrite`` for each of ``PAGES``.

Standard library only: the vocabulary is loaded from its file, without importing the package.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

BRIDGE = Path(__file__).resolve().parent
VOCABULARY = BRIDGE / "sorting_line_gym" / "line" / "topics.py"
PAGES = (BRIDGE.parent / "README.md", BRIDGE.parent / "docs" / "ros-node.md")
BEGIN = "<!-- topics: written by launch_scripts/docs.py from sorting_line_gym/line/topics.py -->"
END = "<!-- end of topics -->"

DIRECTIONS = {
    "publishes": "publishes",
    "subscribes": "subscribes",
    "service": "service server",
    "action": "action server",
}
WHERE = {"advanced": "advanced", "evolving": "evolving line"}


def vocabulary():
    """sorting_line_gym.line.topics, loaded from its file."""
    spec = importlib.util.spec_from_file_location("docs_line_topics", VOCABULARY)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (its dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


def _groups(endpoints) -> list[list]:
    """The endpoints as the table's rows: a run of private services of one package with the same
    QoS and note is one row (the parameter services, the simulation services)."""
    rows: list[list] = []
    for e in endpoints:
        last = rows[-1][-1] if rows else None
        if (
            last is not None
            and e.scope == last.scope == "private"
            and e.kind == last.kind == "service"
            and (e.type.split("/")[0], e.qos, e.note) == (last.type.split("/")[0], last.qos, last.note)
        ):
            rows[-1].append(e)
        else:
            rows.append([e])
    return rows


def _row(group: list) -> str:
    first = group[0]
    names = ", ".join(f"`~/{e.name}`" if e.scope == "private" else f"`{e.name}`" for e in group)
    where = [WHERE[first.when]] if first.when in WHERE else []
    where += ["node namespace"] if first.scope == "node" else []
    name = names + "".join(f" ({w})" for w in where)
    direction = DIRECTIONS[first.kind] + ("s" if len(group) > 1 else "")
    direction += f" ({first.note})" if first.note else ""
    if len(group) > 1:
        package, interface, _ = first.type.split("/")
        type_ = f"{package}/{interface}/..."
    else:
        type_ = first.type
    qos = "default" if first.qos == "default" else vocabulary().QOS_PROFILES[first.qos]
    return f"| {name} | {direction} | `{type_}` | {qos} |"


def render() -> str:
    """The generated block, markers included."""
    v = vocabulary()
    lines = [
        BEGIN,
        "Names relative to the line's namespace unless absolute; `~/` is the node's private namespace",
        f'(`<namespace>/sorting_line/`). QoS "default" is {v.QOS_PROFILES["default"]} (rclpy\'s default).',
        "",
        "| name | direction (node's view) | type | QoS |",
        "|---|---|---|---|",
        *(_row(group) for group in _groups(v.ENDPOINTS)),
        END,
    ]
    return "\n".join(lines)


def rewrite(text: str, page: Path) -> str:
    """``text`` (the page) with the block between the markers written anew."""
    start, end = text.find(BEGIN), text.find(END)
    if start < 0 or end < start:
        raise ValueError(f"{page}: no topic table markers ({BEGIN} ... {END})")
    return text[:start] + render() + text[end + len(END) :]
