"""The test harness's rclpy client of one line (:class:`LineClient`): every topic of the line
recorded, commands published, the reset service called with retries, readiness proven by a real
reply. Built on ros_harness's session and recorders."""

from __future__ import annotations

import functools
import sys
import time
from collections import defaultdict
from typing import Any

from sorting_line_gym.line.topics import (
    BELT_OCCUPANCY,
    DIAGNOSTICS,
    INPUT,
    RESET,
    RESET_EVENT,
    SENSORS_RATIO,
    SORT_MODE_CMD,
    SPEED_CMD,
    STATE,
)
from sorting_line_gym.workarounds.late_matching import repeated_while_unanswered
from support.ros_harness import (
    NS_PER_S,
    NodeProcess,
    RosSession,
    WaitTimeout,
    decode_action,
    diagnostic_values,
    join_ns,
    show_ns,
    stamp_ns,
)


class LineClient:
    """One line of the node, seen from rclpy: its topics, its `reset` service, lock-step stepping.

    `msgs[topic]` lists every message received per topic (topic names relative to the line), and
    `by_stamp[topic][stamp_ns]` the messages per tick stamp.
    """

    TOPICS = [INPUT, BELT_OCCUPANCY, SENSORS_RATIO, STATE, RESET_EVENT]

    def __init__(
        self,
        session: RosSession,
        namespace: str,
        variant: str = "basic",
        tick_period: float = 1.0,
        node=None,
        node_proc: NodeProcess | None = None,
        topics: list[str] | None = None,
        mode_topic: bool = False,
        depth: int = 10,
    ):
        from diagnostic_msgs.msg import DiagnosticArray
        from sorting_line_interfaces.msg import (
            BeltOccupancy,
            LineState,
            MaterialInput,
            MaterialRatio,
            ResetEvent,
            SortModeCommand,
            SpeedCommand,
        )
        from sorting_line_interfaces.srv import ResetLine

        self.session, self.ns, self.variant = session, namespace, variant
        self.period_ns = round(tick_period * NS_PER_S)
        self.node_proc = node_proc
        self.own_node = node is None
        self.node = node if node is not None else session.make_node()
        self.msgs: dict[str, list] = defaultdict(list)
        self.source_times: dict[str, list[int]] = defaultdict(list)  # parallel to msgs
        self.by_stamp: dict[str, dict[int, list]] = defaultdict(lambda: defaultdict(list))
        self.stamp: int | None = None  # the tick the line waits at (ns), known after reset()
        self.first_reset: int | None = None  # stamp of the first reset() of this client
        # /diagnostics first: a status of our line arriving on it proves that the node sends to
        # this participant's readers (see wait_connected); (receive time, values) per status.
        self.diagnostics: list[tuple[float, dict[str, str]]] = []
        self.diag_sub = self.node.create_subscription(DiagnosticArray, DIAGNOSTICS, self._on_diagnostics, 10)
        types = {
            INPUT: MaterialInput,
            BELT_OCCUPANCY: BeltOccupancy,
            SENSORS_RATIO: MaterialRatio,
            STATE: LineState,
            RESET_EVENT: ResetEvent,
        }
        wanted = topics if topics is not None else self.TOPICS
        if variant != "advanced":
            wanted = [t for t in wanted if t != SENSORS_RATIO]
        # depth: the node's QoS is keep-last 10; a deeper reader queue lets a stalled client (a busy
        # machine) catch up on a realtime stream without losing samples.
        self.subs = {t: self.node.create_subscription(types[t], self.name(t), self._recorder(t), depth) for t in wanted}
        self.speed_pub = self.node.create_publisher(SpeedCommand, self.name(SPEED_CMD), 10)
        # The basic line has no cmd/sort_mode: publish it there only on request (mode_topic=True).
        self.mode_pub = (
            self.node.create_publisher(SortModeCommand, self.name(SORT_MODE_CMD), 10)
            if variant == "advanced" or mode_topic
            else None
        )
        self.reset_client = self.node.create_client(ResetLine, self.name(RESET))
        self._SpeedCommand, self._SortModeCommand, self._ResetLine = SpeedCommand, SortModeCommand, ResetLine

    def name(self, rel: str) -> str:
        return join_ns(self.ns, rel)

    def since_reset(self, topic: str) -> list:
        """The messages of `topic` from the first reset() of this client on. (Whether the node's
        start-up tick, published before anyone can have matched, reaches us depends on timing.)"""
        assert self.first_reset is not None, "reset() first"
        return [m for m in self.msgs[topic] if stamp_ns(m.header.stamp) >= self.first_reset]

    def _on_diagnostics(self, array) -> None:
        values = diagnostic_values(array, self.ns)
        if values is not None:
            self.diagnostics.append((time.monotonic(), values))

    def _recorder(self, topic: str):
        msgs, by_stamp, sent = self.msgs[topic], self.by_stamp[topic], self.source_times[topic]

        def record(msg, info):
            msgs.append(msg)
            by_stamp[stamp_ns(msg.header.stamp)].append(msg)
            sent.append(info["source_timestamp"])  # ns, the node's clock when it published

        return record

    def destroy(self) -> None:
        if self.own_node:
            self.session.destroy_node(self.node)

    # ---- diagnostics for error messages

    def context(self) -> str:
        states = [show_ns(stamp_ns(s.header.stamp)) for s in self.msgs[STATE][-5:]]
        matched = {t: s.get_publisher_count() for t, s in self.subs.items()}
        matched[f"{SPEED_CMD} (subscribers)"] = self.speed_pub.get_subscription_count()
        if self.mode_pub is not None:
            matched[f"{SORT_MODE_CMD} (subscribers)"] = self.mode_pub.get_subscription_count()
        lines = [
            f"line {self.ns}: waiting at stamp {show_ns(self.stamp) if self.stamp is not None else '?'}; "
            f"last states seen: {states or 'none'}; matched endpoints: {matched}; "
            f"nodes in the graph: {sorted(self.node.get_node_names_and_namespaces())}"
        ]
        if self.node_proc is not None:
            lines.append(self.node_proc.describe())
        return "\n".join(lines)

    def node_gone(self) -> str | None:
        if self.node_proc is not None and not self.node_proc.running():
            return f"the node process exited with {self.node_proc.proc.returncode}"
        return None

    # ---- waiting

    def wait_connected(self, timeout: float = 10.0) -> None:
        """Waits until our command publishers and subscriptions are matched with the node (our view),
        and until a /diagnostics status of this line (1 Hz) has arrived (the node's view: it has
        discovered this participant and sends to its readers).

        A match count alone proves nothing (stale endpoints linger ~50 s after a node exits), and
        the node's side may lag ours: a `reset` reply sent before the node has matched our reply
        reader is lost for good (volatile). The first reset() reply is the proof the node serves."""

        def matched():
            ok = self.speed_pub.get_subscription_count() >= 1 and self.subs[STATE].get_publisher_count() >= 1
            if self.variant == "advanced":
                ok = ok and self.mode_pub.get_subscription_count() >= 1
            return ok and all(s.get_publisher_count() >= 1 for s in self.subs.values())

        self.session.spin_until(
            matched,
            timeout,
            f"{self.ns}: command publishers and topic subscriptions to match",
            self.context,
            abort=self.node_gone,
        )
        self.session.spin_until(
            lambda: self.diagnostics,
            timeout,
            f"{DIAGNOSTICS}: a status of {self.ns}",
            self.context,
            abort=self.node_gone,
        )

    def wait_message(self, topic: str, stamp: int, timeout: float = 5.0):
        """The first message on `topic` stamped `stamp` (ns)."""
        found = self.by_stamp[topic]
        return self.session.spin_until(
            lambda: found.get(stamp, [None])[0],
            timeout,
            f"{self.name(topic)} for the tick stamped {show_ns(stamp)}",
            self.context,
            abort=self.node_gone,
        )

    def wait_state(self, stamp: int, timeout: float = 5.0):
        return self.wait_message(STATE, stamp, timeout)

    # ---- the service

    def _until(self, done, timeout: float, what: str):
        """Spins until ``done()`` is truthy (its value), failing after ``timeout`` or when the node is gone."""
        return self.session.spin_until(done, timeout, what, self.context, abort=self.node_gone)

    def _reset_evidence(self, events_before: int, episodes_before, called: float) -> str | None:
        """Whether a reset called at ``called`` (monotonic) without a reply happened: "event" (its
        events/reset arrived), "diag-reset" or "diag-same" (a /diagnostics status received well
        after the call counts another or the same number of episodes), None (no evidence yet)."""
        if len(self.msgs[RESET_EVENT]) > events_before:
            return "event"
        late = [v for t, v in self.diagnostics if t > called + 1.5]
        if late:
            return "diag-reset" if late[-1].get("episodes") != episodes_before else "diag-same"
        return None

    def _rebuilt_reset_response(self, event):
        """The reply of a reset whose reply was lost, from its events/reset and the new tick's state."""
        state = self.wait_state(stamp_ns(event.header.stamp))
        return self._ResetLine.Response(
            success=True,
            seed=event.seed,
            episode=event.episode,
            stamp=event.header.stamp,
            quantity=state.observation_quantity,
            category=state.observation_category,
            message=f"(reply lost: rebuilt from {RESET_EVENT} and {STATE}) seed {event.seed}",
        )

    def _call_reset(self, request, what: str, attempt: int) -> tuple[str, Any]:
        """One call of the reset service: ("reply", the response), or, without a reply within 3 s,
        what the evidence says happened ("event", the index of its events/reset; "diag-reset" or
        "diag-same", the number of events/reset before the call)."""
        events_before = len(self.msgs[RESET_EVENT])
        episodes_before = self.diagnostics[-1][1].get("episodes") if self.diagnostics else None
        called = time.monotonic()
        future = self.reset_client.call_async(request)
        try:
            return "reply", self.session.wait_future(
                future, 3.0, f"a reply from {what} (attempt {attempt}/3)", self.context, self.node_gone
            )
        except WaitTimeout:
            pass
        # No reply. Did the reset happen? Look for evidence before calling again.
        evidence = functools.partial(self._reset_evidence, events_before, episodes_before, called)
        found = self._until(evidence, 5.0, f"{what}: a reply, {RESET_EVENT} or {DIAGNOSTICS}")
        if future.done():
            return "reply", future.result()
        self.reset_client.remove_pending_request(future)
        print(f"ros_harness: no reply from {what} within 3 s (attempt {attempt}/3); evidence: {found}", file=sys.stderr)
        return found, events_before

    def reset(self, seed: int | None = None, timeout: float = 10.0, wait_tick: bool = True):
        """Calls `reset` and returns its response; waits for the new tick's state.

        Waits (bounded) for the service, then calls it. A call without a reply within 3 s is retried
        only when the line has evidently not been reset meanwhile (no events/reset, and a /diagnostics
        status received well after the call still counts the same episodes), so a reset is never
        executed twice. If the reset did happen but its reply was lost, the response is rebuilt from
        events/reset and the state of the new tick (`response.message` says so)."""
        what = f"{self.name(RESET)} (seed {seed})"
        request = self._ResetLine.Request(has_seed=seed is not None, seed=seed or 0)
        self._until(self.reset_client.service_is_ready, timeout, f"service {what} to be available")
        outcome, value = repeated_while_unanswered(
            functools.partial(self._call_reset, request, what), lambda result: result[0] == "diag-same", 3
        )
        if outcome == "reply":
            response = value
        elif outcome == "event":
            response = self._rebuilt_reset_response(self.msgs[RESET_EVENT][value])
        elif outcome == "diag-reset":
            raise WaitTimeout(
                f"{what}: the line was reset ({DIAGNOSTICS} counts it) but neither the reply nor "
                f"{RESET_EVENT} nor the state arrived\n{self.context()}"
            )
        else:  # "diag-same" three times: the request never reached the node
            raise WaitTimeout(f"no reply from {what} after 3 attempts\n{self.context()}")
        assert response.success, f"{self.name(RESET)} failed: {response.message}"
        self.stamp = stamp_ns(response.stamp)
        if self.first_reset is None:
            self.first_reset = self.stamp
        if wait_tick:
            self.wait_state(self.stamp)
        return response

    # ---- commands

    def _time(self, stamp: int):
        from builtin_interfaces.msg import Time

        return Time(sec=stamp // NS_PER_S, nanosec=stamp % NS_PER_S)

    def send_speed(self, speed: float, stamp: int | None = None) -> None:
        msg = self._SpeedCommand(speed=float(speed))
        msg.header.stamp = self._time(self.stamp if stamp is None else stamp)
        self.speed_pub.publish(msg)

    def send_mode(self, mode: int, stamp: int | None = None) -> None:
        msg = self._SortModeCommand(mode=int(mode))
        msg.header.stamp = self._time(self.stamp if stamp is None else stamp)
        self.mode_pub.publish(msg)

    def step(self, speed: float, mode: int | None = None, timeout: float = 5.0):
        """Answers the current tick (speed, and mode on the advanced line); returns the next tick's state."""
        assert self.stamp is not None, "reset() first: the client does not know the current tick"
        if self.variant == "advanced":
            assert mode is not None, "the advanced line needs a sort mode every tick"
            self.send_mode(mode)
        self.send_speed(speed)
        state = self.wait_state(self.stamp + self.period_ns, timeout)
        self.stamp += self.period_ns
        return state

    def act(self, action: int, timeout: float = 5.0):
        """Steps with a Gymnasium action (as `sorting_line trace` takes them)."""
        speed, mode = decode_action(self.variant, action)
        return self.step(speed, mode, timeout)
