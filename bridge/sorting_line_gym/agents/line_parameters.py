"""Which line a controller is about to drive, read from the line node's own parameters (its
``get_parameters`` service), and whether a learned policy was trained for it.

The node serving a line lives in the line's namespace (one line) or in its parent (``<ns>/line_k``
with ``--lines N``); its name is the user's choice, so every node there with a ``get_parameters``
service is asked, and the first that has a ``variant`` parameter is the line's. Its ``setup``, or
else the setup its ``input``, ``obs_noise`` and ``action_penalty`` are, and its ``evolution_file``
describe the line. A line whose node is not found in time (a bag played open loop serves no
parameters) is described by the controller's flags instead.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from rcl_interfaces.srv import GetParameters
from rclpy.node import Node

from ..line.policy_card import PolicyCard
from ..line.vocabulary import SETUPS, VARIANTS

#: The node parameters that describe a line.
NAMES = ("variant", "setup", "input", "obs_noise", "action_penalty", "evolution_file")


@dataclass
class LineDescription:
    """What a policy must have been trained for; ``source`` says where it was read."""

    setup: str | None
    variant: str
    evolution: str = ""
    source: str = ""

    def describe(self) -> str:
        evolving = f" (evolving: {self.evolution})" if self.evolution else ""
        return f"setup {self.setup or 'custom'} {self.variant}{evolving}"


def _setup_of(values: dict) -> str | None:
    if values.get("setup"):
        return values["setup"]
    for name, setup in SETUPS.items():
        if all(values.get(k) == v for k, v in setup.items()):
            return name
    return None


def _value(parameter_value):
    """A ParameterValue's content by its type (string, double, integer, bool)."""
    return {1: parameter_value.bool_value, 2: parameter_value.integer_value, 3: parameter_value.double_value}.get(
        parameter_value.type, parameter_value.string_value
    )


def candidates(node: Node, namespace: str) -> list[str]:
    """Services ``<node>/get_parameters`` of the other nodes in ``namespace`` or its parent."""
    parent = namespace.rsplit("/", 1)[0] or "/" if namespace.rsplit("/", 1)[-1].startswith("line_") else None
    spaces = {namespace, parent} - {None}
    me = node.get_fully_qualified_name()
    found = []
    for name, ns in node.get_node_names_and_namespaces():
        full = f"{ns.rstrip('/')}/{name}"
        if ns in spaces and full != me:
            found.append(f"{full}/get_parameters")
    return found


def read_line(node: Node, executor, namespace: str, timeout: float) -> LineDescription | None:
    """The line serving ``namespace`` from its node's parameters, or None after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    asked: set[str] = set()
    while time.monotonic() < deadline:
        for service in candidates(node, namespace):
            if service in asked:
                continue
            client = node.create_client(GetParameters, service)
            try:
                if not client.wait_for_service(timeout_sec=max(0.1, min(2.0, deadline - time.monotonic()))):
                    continue
                asked.add(service)
                future = client.call_async(GetParameters.Request(names=list(NAMES)))
                executor.spin_until_future_complete(future, timeout_sec=max(0.1, deadline - time.monotonic()))
                response = future.result()
            finally:
                node.destroy_client(client)
            if response is None or len(response.values) != len(NAMES):
                continue
            values = {n: _value(v) for n, v in zip(NAMES, response.values, strict=True)}
            if values["variant"] in VARIANTS:
                evolution = Path(values["evolution_file"]).stem if values["evolution_file"] else ""
                source = service.rsplit("/", 1)[0]
                # An evolving line's policy has the advanced spaces throughout (SortingLineEvolving-v0),
                # whatever variant the line starts as.
                variant = "advanced" if evolution else values["variant"]
                return LineDescription(_setup_of(values), variant, evolution, f"parameters of {source}")
        executor.spin_once(timeout_sec=0.1)
    return None


def mismatches(card: PolicyCard, line: LineDescription) -> list[str]:
    """How the policy's training line differs from ``line`` (empty: it fits)."""
    found = []
    if card.variant != line.variant:
        found.append(f"variant {card.variant} vs {line.variant}")
    if card.setup != line.setup:
        found.append(f"setup {card.setup} vs {line.setup or 'custom'}")
    if card.evolution != line.evolution:
        found.append(f"evolution {card.evolution or 'none'} vs {line.evolution or 'none'}")
    return found
