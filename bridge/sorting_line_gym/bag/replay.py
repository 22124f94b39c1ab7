"""`sorting-line-bag replay`: feeds a bag's resets and commands into a fresh lock-step node and
compares what the node publishes with what the bag recorded, field by field.

- The node: started with the options the bag stores (see :mod:`.bagfile`; flags may override
  them), lock-step, one line, in a private namespace, its ``/clock`` and ``/diagnostics``
  remapped into that namespace so that other nodes on the domain cannot mix in.
- Handshake: a reset seeded with the line's seed (which puts the random streams exactly where a
  fresh node has them) is repeated until its reply and its step-0 state arrive, proving that
  every endpoint is matched.
- Seeds: each ``events/reset`` of the bag becomes a reset of the replay node, with the event's
  ``seed`` when ``seeded`` is true (the streams restarted) and without one otherwise (they
  carried on). A bag that starts with an unseeded reset is replayable only if that reset was
  the node's first act (tick 1, episode 1): otherwise the streams had moved on unseen.
- Commands: ``cmd/speed`` and ``cmd/sort_mode`` in the order the recorder received them (each
  after the reset whose episode it belongs to), restamped onto the replay node's ticks. No
  wall-clock playback: before a command for tick T the replay waits for the node's state of
  T, before a reset for the states the bag shows before it. Commands for a tick the recorded
  node never stepped from (no state of step > 0 at T+1 in the bag: the episode was over, a reset came
  first, or the recording ended) are not sent: they changed nothing there.
- Lining up: the replay node counts its ticks and episodes from its own start, so its stamps
  and episode numbers are shifted by the difference at the first reset; everything else must
  be equal. The comparison (:mod:`.compare`) covers every message from the bag's first reset on,
  of ``events/reset``, ``input``, ``belt/occupancy``, ``sensors/ratio``, ``state`` and ``/clock``
  as far as the bag has them, and names the first difference by topic, tick and field.
- Evolving lines: the bag carries the schedule (``evolution`` in its description), which the
  replay node runs by; ``events/evolution`` is compared like the other topics. The recording must
  start at the node's first reset (episode 1, tick 0: the schedule counts episodes and ticks from
  the node's start), and there is no handshake reset (it would be an episode of the schedule).
  ``cmd/sort_mode`` is sent while the recorded line had sort modes (its ``events/evolution`` say
  when), once the replay node's subscription, which appears with the machine upgrade, is matched.
  ``sensors/ratio`` is not compared: its publisher appears with the sensor upgrade, and which of
  its first messages a recorder had matched in time is discovery timing, not the line (the
  reading itself is compared, in every state's ``observation_category``).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..line.errors import BridgeTimeout
from ..line.process import NodeProcess, private_namespace
from ..ros.links import LineLink
from ..workarounds.late_matching import retried_handshake
from .bagfile import Bag, BagError, BagMessage, open_bag
from .compare import Comparison, Difference, compare, shifted
from .foreign import REQUIRED, flags_for, with_setup
from .rosnode import ToolNode
from .schema import CLOCK, COMMANDS, GLOBAL_TYPES, HARDWARE, LINE_TYPES, PUBLISHED, decode, join, stamp_ns, typestore

HANDSHAKE_ATTEMPTS = 3


@dataclass
class ReplayResult:
    bag: Bag
    options: dict
    resets: int = 0
    commands: int = 0
    tick_shift: int = 0  # ticks: bag tick = replay tick + tick_shift
    episode_shift: int = 0
    comparison: Comparison | None = None
    difference: Difference | None = None
    seconds: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def identical(self) -> bool:
        return self.difference is None

    def report(self) -> str:
        counts = ", ".join(f"{t} {n}" for t, n in sorted((self.comparison.compared if self.comparison else {}).items()))
        head = (
            f"replayed {self.bag.path}: {self.resets} resets and {self.commands} commands into a fresh lock-step "
            f"node ({', '.join(f'{k}={self.options[k]}' for k in REQUIRED)}) in {self.seconds:.1f} s; "
            f"lined up as bag tick = replay tick {self.tick_shift:+d}, bag episode = replay episode "
            f"{self.episode_shift:+d}"
        )
        lines = [head, f"compared: {counts or 'nothing'}"]
        lines += self.notes
        if self.difference is None:
            lines.append("identical: every recorded message was reproduced field by field")
        else:
            lines.append(f"first difference: {self.difference}")
        return "\n".join(lines)


def line_namespace(bag: Bag) -> str:
    """The recorded line's namespace: from the bag's description, else the one ``.../state``."""
    if bag.info:
        return bag.info.namespace
    states = [t for t, ty in bag.types.items() if ty == LINE_TYPES["state"]]
    if len(states) != 1:
        raise BagError(f"{bag.path}: cannot tell which line the bag recorded (state topics: {states or 'none'})")
    return states[0][: -len("/state")] or "/"


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


def node_options(bag: Bag, overrides: dict | None) -> dict:
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


def _order_drivers(resets: list[BagMessage], commands: list[tuple[str, BagMessage]]) -> list[tuple[str, BagMessage]]:
    """Resets and commands in the order they reached the recorded node: each command after the
    reset that started the episode of the tick it answers, commands in the order they were
    received. (Stamps, not receive times, place a command relative to the resets: receive times
    of different writers' messages are only roughly ordered.)"""
    starts = [stamp_ns(r.plain) for r in resets]
    keyed = [((k, 0, r.log_time), ("events/reset", r)) for k, r in enumerate(resets)]
    for rel, m in commands:
        group = sum(1 for s in starts if s <= stamp_ns(m.plain)) - 1
        keyed.append(((group, 1, m.log_time), (rel, m)))
    keyed.sort(key=lambda x: x[0])
    return [item for _, item in keyed]


class _Capture:
    """What the replay node publishes, per relative topic (and /clock), as (stamp, raw bytes)."""

    def __init__(self, tool: ToolNode, namespace: str, topics: list[str]):
        self.raw: dict[str, list[bytes]] = {t: [] for t in topics}
        self.states: dict[int, dict] = {}
        self.subs = {}
        for rel in topics:
            name = join(namespace, rel) if rel != CLOCK else join(namespace, "clock")
            msgtype = LINE_TYPES.get(rel) or GLOBAL_TYPES[rel]
            self.subs[rel] = tool.raw_subscription(name, msgtype, self._keeper(rel))

    def _keeper(self, rel: str):
        store = self.raw[rel]

        def keep(data: bytes, _received: int) -> None:
            store.append(data)
            if rel == "state":
                m = decode(data, LINE_TYPES["state"])
                self.states[stamp_ns(m)] = m

        return keep

    def plain(self, rel: str) -> list[dict]:
        msgtype = LINE_TYPES.get(rel) or GLOBAL_TYPES[rel]
        return [decode(d, msgtype) for d in self.raw[rel]]


def replay(
    path,
    overrides: dict | None = None,
    *,
    step_timeout: float = 5.0,
    startup_timeout: float = 20.0,
    progress: bool = False,
) -> ReplayResult:
    """Replays the bag at ``path`` (see the module docstring) in three phases: plan (what to send,
    from the bag alone), drive (a fresh node, fed resets and commands tick by tick) and compare
    (what it published against the recording). Raises BagError for a bag that cannot be
    replayed, BridgeError when the replay node fails; a difference is a result."""
    started = time.monotonic()
    plan = _plan(open_bag(path), overrides)
    result = ReplayResult(plan.bag, plan.options)
    if plan.ineffective:
        result.notes.append(
            f"not sent: {plan.ineffective} commands for ticks the recorded node did not step from "
            "(the episode was over, a reset came first, or the recording ended)"
        )
    replay_ns = private_namespace()
    scratch = tempfile.TemporaryDirectory(prefix="sorting_line_replay_")
    if plan.evolution is not None:
        result.notes.append(
            "evolving line: replayed with the schedule stored in the bag; sensors/ratio not compared "
            "(its publisher appears with the sensor upgrade; the reading is compared in state)"
        )
    process = lockstep_node(
        plan,
        replay_ns,
        Path(scratch.name),
        ("-r", f"/clock:={replay_ns}/clock", "-r", f"/diagnostics:={replay_ns}/diagnostics"),
    )
    tool = None
    try:
        tool = ToolNode("sorting_line_bag_replay", process)
        capture = _Replay(plan, result, tool, replay_ns, step_timeout).drive(startup_timeout, progress)
        _compare(plan, result, capture)
        result.seconds = time.monotonic() - started
        return result
    finally:
        if tool is not None:
            tool.close()
        process.stop()
        scratch.cleanup()


def lockstep_node(plan: _Plan, namespace: str, scratch: Path, ros_args: tuple[str, ...] = ()) -> NodeProcess:
    """A fresh one-line lock-step node with the plan's options in ``namespace`` (an evolving line's
    schedule, stored in the bag, written to ``scratch`` for it)."""
    options = dict(plan.options, mode="lockstep", lines=1)
    if plan.evolution is not None:
        schedule = scratch / "evolution.yaml"
        schedule.write_text(plan.evolution)
        options["evolution"] = str(schedule)
    return NodeProcess(namespace, options, ros_args=ros_args)


@dataclass
class _Plan:
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

    def had_sort_modes(self, stamp: int) -> bool:
        """Whether the recorded line took sort modes for the step answering ``stamp``."""
        modes = False
        for at, on in self.sort_modes:
            if at > stamp:
                break
            modes = on
        return modes


def _plan(bag: Bag, overrides: dict | None) -> _Plan:
    namespace = line_namespace(bag)
    options = node_options(bag, overrides)
    period = round(float(options["tick_period"]) * 1e9)
    rel_msgs = bag.by_relative_topic()
    evolution = evolution_text(bag)
    if evolution is not None:
        announced = [m.plain for m in rel_msgs.get("events/evolution", [])]
        first = next((e for e in announced if e["at_reset"]), None)
        if first is None or (first["episode"], first["tick"]) != (1, 0):
            where = f"episode {first['episode']}, tick {first['tick']}" if first else "no events/evolution at a reset"
            raise BagError(
                f"{bag.path} records an evolving line from {where}: its schedule counts episodes and ticks "
                "from the node's start, so a replay needs the recording to start at the node's first reset "
                "(episode 1, tick 0)"
            )
    resets = rel_msgs.get("events/reset", [])
    if not resets:
        raise BagError(f"{bag.path}: no {join(namespace, 'events/reset')} in the bag: a replay starts at a reset")
    first = resets[0].plain
    start = stamp_ns(first)
    if not first.get("seeded", True) and (start != period or first["episode"] != 1):
        raise BagError(
            f"{bag.path} starts with a reset without a seed at tick {start // period} (episode {first['episode']}): "
            "the node's random streams had already moved on, so that episode cannot be reproduced. Record from a "
            "fresh node, or start the recording with a seeded reset"
        )
    bag_states = {stamp_ns(m.plain): m.plain for m in rel_msgs.get("state", [])}
    # A command for a tick the recorded node never stepped from (the episode was over, a reset
    # came first, or the recording ended) changed nothing there; sent here it might step the node.
    stepped = {s - period for s, m in bag_states.items() if m["step"] > 0}
    commands = [(rel, m) for rel in COMMANDS for m in rel_msgs.get(rel, []) if stamp_ns(m.plain) >= start]
    effective = [c for c in commands if stamp_ns(c[1].plain) in stepped]
    compared = [t for t in (*PUBLISHED, CLOCK) if rel_msgs.get(t) and not (evolution and t == "sensors/ratio")]
    modes = sort_modes_by_stamp([m.plain for m in rel_msgs.get("events/evolution", [])]) if evolution else []
    return _Plan(
        bag,
        options,
        period,
        rel_msgs,
        start,
        bag_states,
        _order_drivers(resets, effective),
        compared,
        len(commands) - len(effective),
        evolution,
        modes,
    )


class _Replay:
    """The drive phase: one fresh lock-step node fed the plan's resets and commands, each once
    the node has reached the tick the bag sent it at."""

    def __init__(self, plan: _Plan, result: ReplayResult, tool: ToolNode, namespace: str, step_timeout: float):
        self.plan, self.result, self.tool, self.namespace, self.step_timeout = (
            plan,
            result,
            tool,
            namespace,
            step_timeout,
        )
        # An evolving line's cmd/sort_mode comes with its machine upgrade: created when needed.
        self.link = LineLink(tool.node, namespace, plan.options["variant"] == "advanced" and plan.evolution is None)
        self.capture = _Capture(tool, namespace, plan.compared_topics)
        self.publishers = {"cmd/speed": self.link.speed_pub, "cmd/sort_mode": self.link.mode_pub}
        self.store = typestore()

    def drive(self, startup_timeout: float, progress: bool) -> _Capture:
        """Sends every driver; stops at the first tick the node does not reach (result.difference)."""
        link, tool, plan = self.link, self.tool, self.plan
        fixed = [s for rel, s in self.capture.subs.items() if not (plan.evolution and rel in HARDWARE)]
        tool.until(
            lambda: link.endpoints_matched(tool.node) and all(s.get_publisher_count() for s in fixed),
            startup_timeout,
            f"the replay node serving {self.namespace} (its reset service and topics)",
        )
        if plan.evolution is None:
            _handshake(tool, link, int(plan.options["seed"]), self.step_timeout)
        else:
            # No handshake reset: it would be an episode of the schedule. The first reset is the
            # bag's; a moment for the node to match our readers first (volatile topics).
            tool.spin_for(0.5)
        bar = _progress(len(plan.drivers), progress)
        try:
            for rel, m in plan.drivers:
                bar.update(1)
                sent = self._reset(m) if rel == "events/reset" else self._command(rel, m)
                if not sent:
                    return self.capture
            later = [s for s in plan.bag_states if s >= plan.start]
            if later:
                self._reached(max(later), "the bag's last state")
            tool.spin_for(0.3)  # /clock and anything else still in flight
        finally:
            bar.close()
        return self.capture

    def _reached(self, bag_stamp: int, why: str) -> bool:
        """Waits for the replay node's state of the bag's tick ``bag_stamp``; False (and the
        result's difference set) when it does not come."""
        period = self.plan.period
        want = bag_stamp - self.result.tick_shift * period
        try:
            self.tool.until(
                lambda: want in self.capture.states,
                self.step_timeout,
                f"{self.namespace}/state of tick {want // period} ({why})",
            )
            return True
        except BridgeTimeout:
            self.result.difference = _missing_state(bag_stamp, period, self.plan.rel_msgs)
            return False

    def _reset(self, m: BagMessage) -> bool:
        plain, stamp, result = m.plain, stamp_ns(m.plain), self.result
        earlier = [s for s in self.plan.bag_states if self.plan.start <= s < stamp]
        if result.resets and earlier and not self._reached(max(earlier), "the last state before a reset"):
            return False
        self.link.send_reset(int(plain["seed"]) if plain.get("seeded", True) else None)
        self.tool.until(self.link.reset_done, self.step_timeout, f"the reply of {self.namespace}/reset")
        reply = self.link.finish_reset()
        if result.resets == 0:
            result.tick_shift = (stamp - (reply.stamp.sec * 1_000_000_000 + reply.stamp.nanosec)) // self.plan.period
            result.episode_shift = int(plain["episode"]) - int(reply.episode)
        result.resets += 1
        return True

    def _command(self, rel: str, m: BagMessage) -> bool:
        # Wait until the replay node is at the command's tick, if the recorded one got there.
        stamp = stamp_ns(m.plain)
        if stamp in self.plan.bag_states and not self._reached(stamp, f"to answer with the bag's {rel}"):
            return False
        pub = self.publishers.get(rel)
        if pub is None:  # a sort mode sent to a basic line: the node refuses it, as it did then
            pub = self.publishers[rel] = self.tool.publisher(join(self.namespace, rel), LINE_TYPES[rel])
        if self.plan.evolution is not None and rel == "cmd/sort_mode":
            if not self.plan.had_sort_modes(stamp):
                return True  # the recorded node had no cmd/sort_mode then: it never got this command
            self.tool.until(
                lambda: pub.get_subscription_count() > 0,
                self.step_timeout,
                f"{self.namespace}/cmd/sort_mode, subscribed since the machine upgrade, to match",
            )
        pub.publish(_restamped(self.store, m, stamp - self.result.tick_shift * self.plan.period))
        self.result.commands += 1
        return True


def _compare(plan: _Plan, result: ReplayResult, capture: _Capture) -> None:
    """The compare phase: every recorded message from the first reset on against the replayed
    one of the same (shifted) tick; up to where the node stopped, if it stopped short."""
    shift = result.tick_shift * plan.period
    recorded = {t: [m.plain for m in plan.rel_msgs[t] if stamp_ns(m.plain) >= plan.start] for t in plan.compared_topics}
    replayed = {}
    for t in plan.compared_topics:
        items = [shifted(m, shift, result.episode_shift) for m in capture.plain(t)]
        replayed[t] = [m for m in items if stamp_ns(m) >= plan.start]
    if result.difference is not None:
        # The node stopped short; anything before that point may still differ earlier.
        cut = result.difference.stamp_ns
        recorded = {t: [m for m in ms if stamp_ns(m) < cut] for t, ms in recorded.items()}
        replayed = {t: [m for m in ms if stamp_ns(m) < cut] for t, ms in replayed.items()}
    result.comparison = compare(recorded, replayed, plan.period)
    if result.comparison.difference is not None:
        result.difference = result.comparison.difference
    if result.comparison.ignored_after_end:
        result.notes.append(
            f"not compared: {result.comparison.ignored_after_end} replayed messages after the end of the recording"
        )


def _handshake(tool: ToolNode, link: LineLink, seed: int, timeout: float) -> None:
    """A seeded reset, repeated until its reply and its step-0 state arrive (either can be lost
    while the node is still matching our endpoints, ``workarounds.late_matching``; a seeded reset
    repeated is the same)."""

    def attempt(limit: float) -> None:
        link.send_reset(seed)
        tool.until(link.reset_done, limit, f"the reply of {link.namespace}/reset (handshake)")
        link.finish_reset()
        tool.until(link.saw_state_of_current_tick, limit, f"{link.state_topic} after the handshake reset")

    def drop_pending_request() -> None:
        if link._reset_future is not None:
            link.reset_client.remove_pending_request(link._reset_future)
            link._reset_future = None

    limits = [min(2.0, timeout)] * HANDSHAKE_ATTEMPTS
    retried_handshake(attempt, limits, BridgeTimeout, after_loss=drop_pending_request)


def _restamped(store, m: BagMessage, stamp: int) -> bytes:
    msg = store.deserialize_cdr(m.data, m.msgtype)
    header = msg.header
    new_stamp = dataclasses.replace(header.stamp, sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
    msg = dataclasses.replace(msg, header=dataclasses.replace(header, stamp=new_stamp))
    return bytes(store.serialize_cdr(msg, m.msgtype))


def _missing_state(stamp: int, period: int, rel_msgs: dict[str, list[BagMessage]]) -> Difference:
    recorded = next((m.plain for m in rel_msgs.get("state", []) if stamp_ns(m.plain) == stamp), {})
    return Difference(
        "state",
        stamp // period,
        stamp,
        "<message>",
        "has it",
        "the replay node did not publish it (it did not step as the recorded node did)",
        recorded.get("episode"),
        recorded.get("step"),
    )


class _NoBar:
    def update(self, _n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, enabled: bool, desc: str = "replay", unit: str = "msg"):
    """A tqdm bar on stderr (the caller enables it where stderr is a terminal), or nothing."""
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, leave=False)
