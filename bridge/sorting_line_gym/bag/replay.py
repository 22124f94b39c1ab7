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
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

from ..transport import BridgeTimeout, LineLink, NodeProcess, private_namespace
from .bagfile import Bag, BagError, BagMessage, open_bag
from .compare import Comparison, Difference, compare, shifted
from .rosnode import ToolNode
from .schema import CLOCK, COMMANDS, GLOBAL_TYPES, LINE_TYPES, PUBLISHED, decode, join, stamp_ns, typestore

#: Node options a replay needs, as `sorting_line node` flags (underscores).
REQUIRED = ("variant", "input", "obs_noise", "action_penalty", "threshold", "max_steps", "seed", "tick_period")
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
        head = (f"replayed {self.bag.path}: {self.resets} resets and {self.commands} commands into a fresh lock-step "
                f"node ({', '.join(f'{k}={self.options[k]}' for k in REQUIRED)}) in {self.seconds:.1f} s; "
                f"lined up as bag tick = replay tick {self.tick_shift:+d}, bag episode = replay episode "
                f"{self.episode_shift:+d}")
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


def node_options(bag: Bag, overrides: dict | None) -> dict:
    options = dict(bag.info.node if bag.info else {})
    options.update({k: v for k, v in (overrides or {}).items() if v is not None})
    if options.get("mode", "lockstep") != "lockstep" and not (overrides or {}).get("mode"):
        raise BagError(f"{bag.path} was recorded from a {options['mode']} node: replay reproduces lock-step "
                       "recordings only (a realtime node applies commands when they arrive, which a bag does not show)")
    missing = [k for k in REQUIRED if k not in options]
    if missing:
        flags = " ".join(f"--{k.replace('_', '-')} ..." for k in missing)
        raise BagError(f"{bag.path} does not say the node's {', '.join(missing)}: pass {flags}")
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


def replay(path, overrides: dict | None = None, *, step_timeout: float = 5.0, startup_timeout: float = 20.0,
           progress: bool = False) -> ReplayResult:
    """Replays the bag at ``path`` (see the module docstring). Raises BagError for a bag that
    cannot be replayed, transport.BridgeError when the replay node fails; a difference is a result."""
    started = time.monotonic()
    bag = open_bag(path)
    namespace = line_namespace(bag)
    options = node_options(bag, overrides)
    period = round(float(options["tick_period"]) * 1e9)
    rel_msgs = bag.by_relative_topic()
    resets = rel_msgs.get("events/reset", [])
    if not resets:
        raise BagError(f"{bag.path}: no {join(namespace, 'events/reset')} in the bag: a replay starts at a reset")
    first = resets[0].plain
    start = stamp_ns(first)
    if not first.get("seeded", True) and (start != period or first["episode"] != 1):
        raise BagError(
            f"{bag.path} starts with a reset without a seed at tick {start // period} (episode {first['episode']}): "
            "the node's random streams had already moved on, so that episode cannot be reproduced. Record from a "
            "fresh node, or start the recording with a seeded reset")
    bag_states = {stamp_ns(m.plain): m.plain for m in rel_msgs.get("state", [])}
    # A command for a tick the recorded node never stepped from (the episode was over, a reset
    # came first, or the recording ended) changed nothing there; sent here it might step the node.
    stepped = {s - period for s, m in bag_states.items() if m["step"] > 0}
    commands = [(rel, m) for rel in COMMANDS for m in rel_msgs.get(rel, []) if stamp_ns(m.plain) >= start]
    ineffective = [c for c in commands if stamp_ns(c[1].plain) not in stepped]
    commands = [c for c in commands if stamp_ns(c[1].plain) in stepped]
    drivers = _order_drivers(resets, commands)
    compared_topics = [t for t in (*PUBLISHED, CLOCK) if rel_msgs.get(t)]
    result = ReplayResult(bag, options)
    if ineffective:
        result.notes.append(f"not sent: {len(ineffective)} commands for ticks the recorded node did not step from "
                            "(the episode was over, a reset came first, or the recording ended)")
    advanced = options["variant"] == "advanced"

    replay_ns = private_namespace()
    process = NodeProcess(replay_ns, dict(options, mode="lockstep", lines=1),
                          ros_args=("-r", f"/clock:={replay_ns}/clock", "-r", f"/diagnostics:={replay_ns}/diagnostics"))
    tool = None
    try:
        tool = ToolNode("sorting_line_bag_replay", process)
        link = LineLink(tool.node, replay_ns, advanced)
        capture = _Capture(tool, replay_ns, compared_topics)
        publishers = {"cmd/speed": link.speed_pub, "cmd/sort_mode": link.mode_pub}
        tool.until(lambda: link.endpoints_matched(tool.node) and all(s.get_publisher_count() for s in capture.subs.values()),
                   startup_timeout, f"the replay node serving {replay_ns} (its reset service and topics)")
        _handshake(tool, link, int(options["seed"]), step_timeout)

        def wait_state(bag_stamp: int, why: str) -> bool:
            want = bag_stamp - result.tick_shift * period
            try:
                tool.until(lambda: want in capture.states, step_timeout,
                           f"{replay_ns}/state of tick {want // period} ({why})")
                return True
            except BridgeTimeout:
                return False

        store = typestore()
        bar = _progress(len(drivers), progress)
        try:
            for rel, m in drivers:
                bar.update(1)
                plain = m.plain
                stamp = stamp_ns(plain)
                if rel == "events/reset":
                    earlier = [s for s in bag_states if start <= s < stamp]
                    if result.resets and earlier and not wait_state(max(earlier), "the last state before a reset"):
                        result.difference = _missing_state(max(earlier), period, rel_msgs)
                        break
                    link.send_reset(int(plain["seed"]) if plain.get("seeded", True) else None)
                    tool.until(link.reset_done, step_timeout, f"the reply of {replay_ns}/reset")
                    reply = link.finish_reset()
                    if result.resets == 0:
                        result.tick_shift = (stamp - (reply.stamp.sec * 1_000_000_000 + reply.stamp.nanosec)) // period
                        result.episode_shift = int(plain["episode"]) - int(reply.episode)
                    result.resets += 1
                    continue
                # A command: wait until the replay node is at its tick, if the recorded one got there.
                if stamp in bag_states and not wait_state(stamp, f"to answer with the bag's {rel}"):
                    result.difference = _missing_state(stamp, period, rel_msgs)
                    break
                pub = publishers.get(rel)
                if pub is None:  # a sort mode sent to a basic line: the node refuses it, as it did then
                    pub = publishers[rel] = tool.publisher(join(replay_ns, rel), LINE_TYPES[rel])
                pub.publish(_restamped(store, m, stamp - result.tick_shift * period))
                result.commands += 1
            else:
                later = [s for s in bag_states if s >= start]
                if later and not wait_state(max(later), "the bag's last state"):
                    result.difference = _missing_state(max(later), period, rel_msgs)
                tool.spin_for(0.3)  # /clock and anything else still in flight
        finally:
            bar.close()
        recorded = {t: [m.plain for m in rel_msgs[t] if stamp_ns(m.plain) >= start] for t in compared_topics}
        replayed = {}
        for t in compared_topics:
            items = [shifted(m, result.tick_shift * period, result.episode_shift) for m in capture.plain(t)]
            replayed[t] = [m for m in items if stamp_ns(m) >= start]
        if result.difference is not None:
            # The node stopped short; anything before that point may still differ earlier.
            cut = result.difference.stamp_ns
            recorded = {t: [m for m in ms if stamp_ns(m) < cut] for t, ms in recorded.items()}
            replayed = {t: [m for m in ms if stamp_ns(m) < cut] for t, ms in replayed.items()}
            earlier = compare(recorded, replayed, period)
            result.comparison = earlier
            if earlier.difference is not None:
                result.difference = earlier.difference
        else:
            result.comparison = compare(recorded, replayed, period)
            result.difference = result.comparison.difference
        if result.comparison.ignored_after_end:
            result.notes.append(f"not compared: {result.comparison.ignored_after_end} replayed messages after the "
                                "end of the recording")
        result.seconds = time.monotonic() - started
        return result
    finally:
        if tool is not None:
            tool.close()
        process.stop()


def _handshake(tool: ToolNode, link: LineLink, seed: int, timeout: float) -> None:
    """A seeded reset, repeated until its reply and its step-0 state arrive (either can be lost
    while the node is still matching our endpoints; a seeded reset repeated is the same)."""
    for attempt in range(1, HANDSHAKE_ATTEMPTS + 1):
        try:
            link.send_reset(seed)
            tool.until(link.reset_done, min(2.0, timeout), f"the reply of {link.namespace}/reset (handshake)")
            link.finish_reset()
            tool.until(link.saw_state_of_current_tick, min(2.0, timeout),
                       f"{link.state_topic} after the handshake reset")
            return
        except BridgeTimeout:
            if link._reset_future is not None:
                link.reset_client.remove_pending_request(link._reset_future)
                link._reset_future = None
            if attempt == HANDSHAKE_ATTEMPTS:
                raise


def _restamped(store, m: BagMessage, stamp: int) -> bytes:
    msg = store.deserialize_cdr(m.data, m.msgtype)
    header = msg.header
    new_stamp = dataclasses.replace(header.stamp, sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
    msg = dataclasses.replace(msg, header=dataclasses.replace(header, stamp=new_stamp))
    return bytes(store.serialize_cdr(msg, m.msgtype))


def _missing_state(stamp: int, period: int, rel_msgs: dict[str, list[BagMessage]]) -> Difference:
    recorded = next((m.plain for m in rel_msgs.get("state", []) if stamp_ns(m.plain) == stamp), {})
    return Difference("state", stamp // period, stamp, "<message>", "has it",
                      "the replay node did not publish it (it did not step as the recorded node did)",
                      recorded.get("episode"), recorded.get("step"))


class _NoBar:
    def update(self, _n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, enabled: bool):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc="replay", unit="msg", leave=False)
