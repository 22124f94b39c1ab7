"""The rule-based controller under test as a process (`sorting-line-controller` with its log and decision log),
and what the tests watch of the line it drives: timed recorders of its state and command topics, the
(context, abort) pair for waits, and a seeded reset repeated until the controller answers its tick.
Used by the controller, learned-controller, bag, bag-check, reliability tests and the golden bags."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from sorting_line_gym.line.topics import SORT_MODE_CMD, SPEED_CMD, STATE
from support import ros_harness as h
from support.ros_harness import stamp_ns


class ControllerProcess(h.ScriptProcess):
    """`sorting-line-controller ARGS` (the installed console script) with its log and decision log;
    stop() sends SIGINT and wants it to exit in time, having logged its summary."""

    def __init__(self, tmp_path: Path, tag: str, args: list[str]):
        self.decision_path = tmp_path / f"decisions_{tag}.jsonl"
        super().__init__(
            "sorting-line-controller",
            [*args, "--decision-log", self.decision_path],
            tmp_path / f"controller_{tag}.log",
            label="controller",
        )

    def decision_rows(self) -> list[dict]:
        """The decision log, a row per decision, in order (a restarted node's ticks repeat stamps)."""
        if not self.decision_path.exists():
            return []
        return [json.loads(line) for line in self.decision_path.read_text().splitlines() if line.strip()]

    def decisions(self) -> dict[int, dict]:
        """The decision log, by tick stamp (ns): for one node's run, where stamps do not repeat."""
        return {r["stamp_ns"]: r for r in self.decision_rows()}


class TimedRecorder:
    """Every message of one topic with the monotonic time it was received (this process).

    Reliable, volatile like every endpoint of the line, but keeping the last 500 samples instead of
    10: the recorder shares one executor with everything else in this process, and a keep-last-10
    reader that falls behind by more than 10 messages (a busy machine) overwrites them unseen."""

    def __init__(self, node, topic: str, msg_type):
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        qos = QoSProfile(
            depth=500,
            history=HistoryPolicy.KEEP_LAST,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
        )
        self.topic = topic
        self.items: list[tuple[float, object]] = []
        self.sub = node.create_subscription(msg_type, topic, lambda m: self.items.append((time.monotonic(), m)), qos)

    def by_stamp(self) -> dict[int, tuple[float, object]]:
        """First message per stamp (ns) -> (receive time, message)."""
        out = {}
        for t, m in self.items:
            out.setdefault(stamp_ns(m.header.stamp), (t, m))
        return out


def line_recorders(probe, ns: str) -> dict[str, TimedRecorder]:
    from sorting_line_interfaces.msg import LineState, SortModeCommand, SpeedCommand

    return {
        STATE: TimedRecorder(probe, h.join_ns(ns, STATE), LineState),
        SPEED_CMD: TimedRecorder(probe, h.join_ns(ns, SPEED_CMD), SpeedCommand),
        SORT_MODE_CMD: TimedRecorder(probe, h.join_ns(ns, SORT_MODE_CMD), SortModeCommand),
    }


def watch(client, controller):
    """(context, abort) for waits on a line driven by a controller process: what to show when a
    wait fails, and why to stop waiting early (the node or the controller is gone)."""

    def context():
        return f"{client.context()}\n{controller.describe()}"

    def abort():
        return client.node_gone() or (
            None if controller.running() else f"the controller exited with {controller.proc.returncode}"
        )

    return context, abort


def reset_until_answered(ros, c, rec, seed: int, context, abort) -> int:
    """Resets the line with ``seed`` until the controller answers the reset's tick (up to 3 times);
    the episode. Its first tick can be lost while the node is still matching the controller's
    endpoints: then nothing moves, and a new seeded reset (the same episode again) is the remedy.

    The reset's tick is awaited on the deep recorder ``rec``, not on the client's keep-last-10
    reader: the controller drives the lock-step line through its 50 ticks as fast as the round
    trip allows, and on a busy machine that burst overwrites the client's copy of the first tick
    before it is taken (seen in CI: states 47..51 arrived, tick 1 never did)."""
    for attempt in range(1, 4):
        episode = c.reset(seed, wait_tick=False).episode

        def steps_seen(episode=episode):
            return max((s.step for _, s in rec["state"].items if s.episode == episode), default=0)

        try:
            ros.spin_until(lambda: steps_seen() >= 1, 3.0, f"{c.ns}: the controller's first step", context, abort=abort)
            return episode
        except h.WaitTimeout:
            print(f"attempt {attempt}: the controller did not answer the reset's tick; resetting again")
    pytest.fail(f"the controller never answered a reset's tick\n{context()}")
