"""The controller node behind `sorting-line-controller` (its command line: ``controller_cli``): an
agent (rule-based, or a learned policy) as an rclpy node that drives a line live.

    sorting_line node --mode realtime --rate 10 --variant advanced --input seasonal \\
        --action-penalty 0.5 --ros-args -r __ns:=/plant &
    sorting-line-controller --namespace /plant --setup B --variant advanced --agent rba-hold

This is the model of a controller for the line, written as a user would: it knows nothing of the
node's internals, only its topics (docs/ros-node.md). Each tick the node publishes, stamped
with the tick's simulated time, the input sensor (``input``: the reading of the next batch), the
belt (``belt/occupancy``: its current ``speed``) and, on the advanced line, the ratio sensor
(``sensors/ratio``: the next batch's category). The controller collects the readings of one stamp
from those topics (they arrive as separate messages, in any order), and once it has what its agent
needs (the reading; the category on the advanced line; the current speed for ``rba-hold``) it
decides and answers that tick: ``cmd/sort_mode`` (advanced) then ``cmd/speed``, both carrying the
tick's stamp.

- realtime node: the node ticks on its own clock and holds the last command it received, so a
  command that arrives after the next tick takes effect one tick later.
- lock-step node: each answer makes the node advance one tick, so the controller drives the line
  as fast as the round trip allows. It answers every tick it sees, also the last of an episode,
  which a lock-step node refuses (``episode_over``) until someone calls ``reset``.

A learned policy (``learned_policy.LearnedAgent``) gets the observation the env would give and, on
an evolving line (``evolving``), the env's action mask: the controller follows the line's hardware
through ``events/evolution`` (``sort_modes``, ``ratio_sensor``; a ``sensors/ratio`` message also
says the sensor is fitted); without a ratio sensor a tick needs no category and the observation
reads it as unknown. Where the agent fails on a tick, ``fallback`` answers it (logged, counted on
``/diagnostics``: ``controller_diagnostics``); without one the node sets ``failure`` and the
command line stops.

``--setup`` and ``--variant`` must describe the node's line (the table depends on the input
generator, the sensor noise and the penalty). QoS is the node's: reliable, volatile, keep-last 10.
``--ros-args`` (e.g. ``-r __ns:=/plant``) is handed to rclpy; a ``__ns`` remap sets the namespace as
for any ROS node, over ``--namespace`` (`sorting-line-bag check --controller` appends one). SIGINT
or SIGTERM stops it cleanly (within 0.1 s), logging how many decisions it made.
"""

from __future__ import annotations

import json
import time
from collections import deque
from dataclasses import dataclass
from typing import IO

from rclpy.node import Node
from sorting_line_interfaces.msg import (
    BeltOccupancy,
    EvolutionEvent,
    MaterialInput,
    MaterialRatio,
    SortModeCommand,
    SpeedCommand,
)

from ..line.topics import BELT_OCCUPANCY, EVOLUTION_EVENT, INPUT, SENSORS_RATIO, SORT_MODE_CMD, SPEED_CMD
from ..line.vocabulary import CATEGORIES, CATEGORY_UNKNOWN_CODE, SPEED_COUNT, SPEEDS, alternatives, speed_index_of
from ..ros.links import QOS, publish_commands
from .controller_diagnostics import ControllerDiagnostics
from .policies import Agent

NS_PER_S = 1_000_000_000
#: Ticks whose readings are still incomplete that the controller keeps; older ones are dropped.
MAX_PENDING = 32
#: Decisions whose latency the exit summary describes (the most recent ones).
LATENCY_WINDOW = 10_000
#: Longest wait of the executor: how soon a signal stops the controller.
SPIN_PERIOD = 0.1
#: The ratio categories' wire numbers as a refused reading's warning lists them ("0, 1 or 2").
_CATEGORY_NUMBERS = alternatives(CATEGORIES.values())


def stamp_ns(stamp) -> int:
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


@dataclass
class _Readings:
    """What has arrived for one tick."""

    stamp: object  # builtin_interfaces/Time, echoed in the commands
    first_seen: float  # time.monotonic() of the first reading
    last_seen: float = 0.0  # ... and of the reading that completed the tick
    quantity: float | None = None
    category: int | None = None
    speed_index: int | None = None
    episode: int = 0
    step: int = 0


class ControllerNode(Node):
    """Answers every tick of one line with ``agent``'s decision (see the module's docstring).

    ``decision_log``: an open text file that gets one JSON line per decision (stamp, episode, step,
    readings, decision, ``latency_ms`` from the tick's first reading to the publication and
    ``decision_ms`` from its last reading, the one that completed it)."""

    def __init__(
        self,
        agent: Agent,
        variant: str,
        namespace: str | None = None,
        node_name: str = "sorting_line_controller",
        decision_log: IO[str] | None = None,
        fallback: Agent | None = None,
        evolving: bool = False,
    ):
        super().__init__(node_name, namespace=namespace)
        self.agent, self.variant, self.fallback = agent, variant, fallback
        self.advanced = variant == "advanced"
        self.needs_speed = any(getattr(a, "hold", False) for a in (agent, fallback))
        self.decision_log = decision_log
        # The evolving line's hardware, as its events say (a fixed line has all of it).
        self.evolving, self.ratio_sensor = evolving, not evolving
        self.failure: str | None = None  # why the policy could not answer, without a fallback
        self.decisions = 0
        self.skipped = 0  # ticks whose readings never became complete before a newer tick's
        self.stale = 0  # readings for ticks already answered or skipped
        self.invalid = 0  # readings that cannot be decided on (unknown category, off-grid speed)
        # Readings-to-command latencies (ms) of the most recent decisions, for the summary.
        self.latencies: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self._pending: dict[int, _Readings] = {}
        self._newest_answered: int | None = None
        self._newest_input: int | None = None
        self._warned_incomplete = False

        self.speed_pub = self.create_publisher(SpeedCommand, SPEED_CMD, QOS)
        self.mode_pub = self.create_publisher(SortModeCommand, SORT_MODE_CMD, QOS) if self.advanced else None
        self.subs = [self.create_subscription(MaterialInput, INPUT, self._on_input, QOS)]
        if self.advanced:
            self.subs.append(self.create_subscription(MaterialRatio, SENSORS_RATIO, self._on_ratio, QOS))
        if self.needs_speed:
            self.subs.append(self.create_subscription(BeltOccupancy, BELT_OCCUPANCY, self._on_belt, QOS))
        if evolving:
            self.events = self.create_subscription(EvolutionEvent, EVOLUTION_EVENT, self._on_evolution, QOS)
            self._hardware(sort_modes=False, ratio_sensor=False)
        self.diagnostics = ControllerDiagnostics(self, agent, fallback)
        self._connect_timer = self.create_timer(0.1, self._check_connected)
        topics = ", ".join(s.topic_name for s in self.subs)
        self.get_logger().info(
            f"{getattr(agent, 'name', type(agent).__name__)} on the {variant} line"
            f"{' of setup ' + agent.setup if hasattr(agent, 'setup') else ''}: reading {topics}; "
            f"commanding {self.resolve_topic_name(SPEED_CMD)}"
            + (f" and {self.resolve_topic_name(SORT_MODE_CMD)}" if self.advanced else "")
        )

    # -- graph ---------------------------------------------------------------------------------
    def _check_connected(self) -> None:
        """Logs once that every topic has a peer (a hint for users and scripts, not a guarantee
        that the node has matched us too)."""
        pubs = [self.speed_pub] + ([self.mode_pub] if self.mode_pub else [])
        subs = self.subs
        if self.evolving:
            # The ratio sensor and sort modes come and go with the hardware: not there is no fault.
            pubs = [self.speed_pub]
            subs = [s for s in self.subs if not s.topic_name.endswith(f"/{SENSORS_RATIO}")]
        if all(p.get_subscription_count() > 0 for p in pubs) and all(s.get_publisher_count() > 0 for s in subs):
            self.get_logger().info("connected: every sensor topic has a publisher and every command topic a subscriber")
            self._connect_timer.cancel()
            self.destroy_timer(self._connect_timer)

    # -- readings ------------------------------------------------------------------------------
    def _on_input(self, msg: MaterialInput) -> None:
        key = stamp_ns(msg.header.stamp)
        # One writer delivers in order: an input older than the newest one is a new node (or a
        # restarted one) whose clock starts again. Start over instead of ignoring it for good.
        if self._newest_input is not None and key < self._newest_input:
            self.get_logger().warning(
                f"input went back in time ({key / NS_PER_S:.3f} s after {self._newest_input / NS_PER_S:.3f} s):"
                " the node restarted? starting over"
            )
            self._pending.clear()
            self._newest_answered = None
        self._newest_input = key
        self._reading(msg.header.stamp, msg.episode, msg.step, quantity=float(msg.quantity))

    def _on_evolution(self, msg) -> None:
        """The evolving line's setup changed: follow its hardware (the ratio sensor, sort modes)."""
        self._hardware(sort_modes=bool(msg.sort_modes), ratio_sensor=bool(msg.ratio_sensor))

    def _hardware(self, sort_modes: bool, ratio_sensor: bool) -> None:
        self.ratio_sensor = ratio_sensor
        for agent in (self.agent, self.fallback):
            if hasattr(agent, "sort_modes"):
                agent.sort_modes = sort_modes

    def _on_ratio(self, msg: MaterialRatio) -> None:
        if self.evolving:
            self.ratio_sensor = True  # it publishes: it is fitted (whether or not we saw the event)
        if msg.category not in CATEGORIES.values():
            self.invalid += 1
            self.get_logger().warning(
                f"{SENSORS_RATIO}: category {msg.category} is not {_CATEGORY_NUMBERS}", throttle_duration_sec=5.0
            )
            return
        self._reading(msg.header.stamp, msg.episode, msg.step, category=int(msg.category))

    def _on_belt(self, msg: BeltOccupancy) -> None:
        index = speed_index_of(msg.speed)
        if index is None:
            self.invalid += 1
            self.get_logger().warning(
                f"{BELT_OCCUPANCY}: speed {msg.speed} is not one of the {SPEED_COUNT} speeds", throttle_duration_sec=5.0
            )
            return
        self._reading(msg.header.stamp, msg.episode, msg.step, speed_index=index)

    def _reading(self, stamp, episode: int, step: int, **values) -> None:
        key = stamp_ns(stamp)
        if self._newest_answered is not None and key <= self._newest_answered:
            self.stale += 1
            return
        tick = self._pending.get(key)
        if tick is None:
            tick = self._pending[key] = _Readings(stamp, time.monotonic(), episode=episode, step=step)
            if len(self._pending) > MAX_PENDING:
                self._drop(min(self._pending), persistent=True)
        for name, value in values.items():
            setattr(tick, name, value)
        tick.last_seen = time.monotonic()
        if self._complete(tick):
            self._answer(key, tick)

    def _missing(self, tick: _Readings) -> list[str]:
        missing = []
        if tick.quantity is None:
            missing.append(INPUT)
        if self.advanced and self.ratio_sensor and tick.category is None:
            missing.append(SENSORS_RATIO)
        if self.needs_speed and tick.speed_index is None:
            missing.append(BELT_OCCUPANCY)
        return missing

    def _complete(self, tick: _Readings) -> bool:
        return not self._missing(tick)

    def _drop(self, key: int, persistent: bool = False) -> None:
        """Gives up on a tick. ``persistent``: ticks keep arriving incomplete (a topic is silent),
        which is worth a warning; a tick overtaken by a newer complete one (e.g. while the
        subscriptions were still matching) is only counted."""
        tick = self._pending.pop(key)
        self.skipped += 1
        if persistent and not self._warned_incomplete:
            self._warned_incomplete = True
            self.get_logger().warning(
                f"{MAX_PENDING} ticks without complete readings, e.g. the tick stamped {key / NS_PER_S:.3f} s: "
                f"nothing on {', '.join(self._missing(tick))} (does --variant match the node's line?)"
            )

    # -- decisions -----------------------------------------------------------------------------
    def _answer(self, key: int, tick: _Readings) -> None:
        del self._pending[key]
        # Older ticks can no longer be answered usefully (the node refuses a stamp older than one
        # it has accepted): drop them.
        for older in [k for k in self._pending if k < key]:
            self._drop(older)
        self._newest_answered = key
        current = tick.speed_index if tick.speed_index is not None else 0
        category = tick.category if tick.category is not None else (0 if self.ratio_sensor else CATEGORY_UNKNOWN_CODE)
        decision = self._decide(key, tick, category, current)
        if decision is None:
            return
        speed_index, mode = decision
        publish_commands(self.speed_pub, self.mode_pub, tick.stamp, speed_index, mode)
        published = time.monotonic()
        self.decisions += 1
        latency_ms = (published - tick.first_seen) * 1e3
        self.latencies.append(latency_ms)
        if self.decisions == 1:
            self.get_logger().info(
                f"first decision: tick {key / NS_PER_S:.3f} s (episode {tick.episode}, "
                f"step {tick.step}) -> speed {SPEEDS[speed_index]}, mode {mode}"
            )
        if self.decision_log is not None:
            record = {
                "stamp_ns": key,
                "episode": tick.episode,
                "step": tick.step,
                "quantity": tick.quantity,
                "category": tick.category,
                "current_speed_index": tick.speed_index,
                "speed_index": speed_index,
                "mode": mode,
                "latency_ms": round(latency_ms, 3),
                "decision_ms": round((published - tick.last_seen) * 1e3, 3),
                "first_seen_monotonic": tick.first_seen,
                "published_monotonic": published,
            }
            self.decision_log.write(json.dumps(record) + "\n")
            self.decision_log.flush()

    def _decide(self, key: int, tick: _Readings, category: int, current: int) -> tuple[int, int] | None:
        """The agent's decision; where it fails, the fallback's (logged and counted), else None
        with ``failure`` set (the controller stops)."""
        try:
            return self.agent.act(tick.quantity, category, current)
        except Exception as e:  # noqa: BLE001 - a policy runtime fails in its own ways
            reason = f"the policy could not answer the tick stamped {key / NS_PER_S:.3f} s: {type(e).__name__}: {e}"
        if self.fallback is None:
            self.failure = f"{reason}; stopping (--fallback rba-hold answers such ticks instead)"
            self.get_logger().error(self.failure)
            return None
        self.diagnostics.fallbacks += 1
        self.get_logger().warning(f"{reason}; {self.fallback.name} answers it (fallback {self.diagnostics.fallbacks})")
        return self.fallback.act(tick.quantity, min(category, 2), current)

    def summary(self) -> str:
        lat = sorted(self.latencies)
        timing = ""
        if lat:
            p50, p99 = lat[len(lat) // 2], lat[min(len(lat) - 1, int(len(lat) * 0.99))]
            timing = f"; readings-to-command latency p50 {p50:.2f} ms, p99 {p99:.2f} ms"
            if len(lat) == LATENCY_WINDOW:
                timing += f" (last {LATENCY_WINDOW} decisions)"
        return (
            f"{self.decisions} decisions, {self.skipped} ticks skipped (incomplete readings), "
            f"{self.stale} stale readings, {self.invalid} invalid readings, "
            f"{self.diagnostics.fallbacks} fallbacks{timing}"
        )
