"""The plan of a replay, worked out from a bag alone before any node runs: the recorded line's
namespace and the options of a fresh node for it (the bag's, overridden by flags), what to send
(the bag's resets and effective commands, in the order they reached the recorded node) and what to
compare; and the fresh lock-step node itself. `replay` (:mod:`.replay`) and the closed-loop check
(:mod:`..check.closed_loop`) both start from it; the rules are in :mod:`.replay`'s docstring.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ...line.process import NodeProcess
from ...line.topics import EVOLUTION_EVENT, RESET_EVENT, SENSORS_RATIO, STATE
from ..format.errors import BagError
from ..format.options import NodeOverrides
from ..format.topics import CLOCK, COMMANDS, LINE_TYPES, PUBLISHED, join
from ..storage.foreign import REQUIRED, flags_for, with_setup
from ..storage.reader import Bag, BagMessage
from ..storage.schema import stamp_ns


def line_namespace(bag: Bag) -> str:
    """The recorded line's namespace: from the bag's description, else the one ``.../state``."""
    if bag.info:
        return bag.info.namespace
    states = [t for t, ty in bag.types.items() if ty == LINE_TYPES[STATE]]
    if len(states) != 1:
        raise BagError(f"{bag.path}: cannot tell which line the bag recorded (state topics: {states or 'none'})")
    return states[0][: -len(f"/{STATE}")] or "/"


def evolution_text(bag: Bag) -> str | None:
    """The evolution schedule the recorded node ran by, if it evolved."""
    return (bag.info.node.get("evolution") if bag.info else None) or None


def sort_modes_by_stamp(events: list[dict]) -> list[tuple[int, bool]]:
    """(stamp, whether the line has sort modes from that tick's step on), from the recorded
    ``events/evolution``: a reset's message gives the whole setup, a tick's the fields it changed."""
    out = []
    for e in sorted(events, key=lambda e: (stamp_ns(e), not e["at_reset"])):
        if e["at_reset"]:
            out.append((stamp_ns(e), bool(e["sort_modes"])))
        elif "sort_modes" in e["changed"]:
            out.append((stamp_ns(e), e["values"][e["changed"].index("sort_modes")] == "true"))
    return out


def node_options(bag: Bag, overrides: NodeOverrides | None) -> dict:
    """The options of a fresh node for ``bag``: the bag's, overridden by the flags given
    (``setup`` stands for its options); BagError naming the flags for what neither has."""
    overrides = with_setup(overrides)
    options = dict(bag.info.node if bag.info else {})
    options.update(overrides)
    if options.get("mode", "lockstep") != "lockstep" and not overrides.get("mode"):
        raise BagError(
            f"{bag.path} was recorded from a {options['mode']} node: replay reproduces lock-step "
            "recordings only (a realtime node applies commands when they arrive, which a bag does not show)"
        )
    missing = [k for k in REQUIRED if k not in options]
    if missing:
        raise BagError(f"{bag.path} does not say the node's {', '.join(missing)}: pass {flags_for(missing)}")
    return {k: options[k] for k in REQUIRED}


def order_drivers(resets: list[BagMessage], commands: list[tuple[str, BagMessage]]) -> list[tuple[str, BagMessage]]:
    """Resets and commands in the order they reached the recorded node: each command after the
    reset that started the episode of the tick it answers, commands in the order they were
    received. (Stamps, not receive times, place a command relative to the resets: receive times
    of different writers' messages are only roughly ordered.)"""
    starts = [stamp_ns(r.plain) for r in resets]
    keyed = [((k, 0, r.log_time), (RESET_EVENT, r)) for k, r in enumerate(resets)]
    for rel, m in commands:
        group = sum(1 for s in starts if s <= stamp_ns(m.plain)) - 1
        keyed.append(((group, 1, m.log_time), (rel, m)))
    keyed.sort(key=lambda x: x[0])
    return [item for _, item in keyed]


def lockstep_node(plan: ReplayPlan, namespace: str, scratch: Path, ros_args: tuple[str, ...] = ()) -> NodeProcess:
    """A fresh one-line lock-step node with the plan's options in ``namespace`` (an evolving line's
    schedule, stored in the bag, written to ``scratch`` for it)."""
    options = dict(plan.options, mode="lockstep", lines=1)
    if plan.evolution is not None:
        schedule = scratch / "evolution.yaml"
        schedule.write_text(plan.evolution)
        options["evolution"] = str(schedule)
    return NodeProcess(namespace, options, ros_args=ros_args)


@dataclass
class ReplayPlan:
    """What a replay sends and compares, worked out from the bag alone."""

    bag: Bag
    options: dict
    period: int  # ns per tick
    rel_msgs: dict[str, list[BagMessage]]
    start: int  # stamp of the bag's first reset: nothing before it is sent or compared
    bag_states: dict[int, dict]  # recorded states by stamp
    drivers: list[tuple[str, BagMessage]]  # resets and commands, in the order to send them
    compared_topics: list[str]
    ineffective: int  # commands left out: the recorded node never stepped from their tick
    evolution: str | None = None  # the schedule of an evolving line
    sort_modes: list[tuple[int, bool]] = field(default_factory=list)  # (stamp, modes from then on)
    at_start: dict[str, int] = field(default_factory=dict)  # per compared topic: messages of the first reset's tick

    def had_sort_modes(self, stamp: int) -> bool:
        """Whether the recorded line took sort modes for the step answering ``stamp``."""
        modes = False
        for at, on in self.sort_modes:
            if at > stamp:
                break
            modes = on
        return modes


def plan_replay(bag: Bag, overrides: NodeOverrides | None) -> ReplayPlan:
    namespace = line_namespace(bag)
    options = node_options(bag, overrides)
    period = round(float(options["tick_period"]) * 1e9)
    rel_msgs = bag.by_relative_topic()
    evolution = evolution_text(bag)
    if evolution is not None:
        announced = [m.plain for m in rel_msgs.get(EVOLUTION_EVENT, [])]
        first = next((e for e in announced if e["at_reset"]), None)
        if first is None or (first["episode"], first["tick"]) != (1, 0):
            where = f"episode {first['episode']}, tick {first['tick']}" if first else f"no {EVOLUTION_EVENT} at a reset"
            raise BagError(
                f"{bag.path} records an evolving line from {where}: its schedule counts episodes and ticks "
                "from the node's start, so a replay needs the recording to start at the node's first reset "
                "(episode 1, tick 0)"
            )
    resets = rel_msgs.get(RESET_EVENT, [])
    if not resets:
        raise BagError(f"{bag.path}: no {join(namespace, RESET_EVENT)} in the bag: a replay starts at a reset")
    first = resets[0].plain
    start = stamp_ns(first)
    if not first.get("seeded", True) and (start != period or first["episode"] != 1):
        raise BagError(
            f"{bag.path} starts with a reset without a seed at tick {start // period} (episode {first['episode']}): "
            "the node's random streams had already moved on, so that episode cannot be reproduced. Record from a "
            "fresh node, or start the recording with a seeded reset"
        )
    bag_states = {stamp_ns(m.plain): m.plain for m in rel_msgs.get(STATE, [])}
    # A command for a tick the recorded node never stepped from (the episode was over, a reset
    # came first, or the recording ended) changed nothing there; sent here it might step the node.
    stepped = {s - period for s, m in bag_states.items() if m["step"] > 0}
    commands = [(rel, m) for rel in COMMANDS for m in rel_msgs.get(rel, []) if stamp_ns(m.plain) >= start]
    effective = [c for c in commands if stamp_ns(c[1].plain) in stepped]
    compared = [t for t in (*PUBLISHED, CLOCK) if rel_msgs.get(t) and not (evolution and t == SENSORS_RATIO)]
    modes = sort_modes_by_stamp([m.plain for m in rel_msgs.get(EVOLUTION_EVENT, [])]) if evolution else []
    at_start = {t: sum(1 for m in rel_msgs[t] if stamp_ns(m.plain) == start) for t in compared}
    return ReplayPlan(
        bag,
        options,
        period,
        rel_msgs,
        start,
        bag_states,
        order_drivers(resets, effective),
        compared,
        len(commands) - len(effective),
        evolution,
        modes,
        at_start,
    )
