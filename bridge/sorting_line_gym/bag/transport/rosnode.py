"""The rclpy side the bag tools share: a context, node and executor of their own (so that the
tools run inside a process that uses rclpy for something else, such as a test session, without
touching its context), QoS, raw endpoints, and waiting through :class:`~sorting_line_gym.ros.waits.Waiter`
(every wait has a timeout and an error naming what it waited for), and the rclpy class of each
message type a bag names."""

from __future__ import annotations

import importlib
import os
import time
from collections.abc import Callable

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ...line.process import NodeProcess
from ...line.topics import BATCH_CMD, DIAGNOSTICS, INPUT, SPEED_CMD
from ...ros.context import check_domain_id
from ...ros.waits import Waiter
from ..format.topics import COMMANDS, join

#: Deep reliable queues: a tool that falls behind for a moment (a busy machine) catches up
#: instead of losing samples (the node's own depth is 10).
DEEP_QOS = QoSProfile(
    depth=1000,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


def received_ns(info) -> int:
    """When DDS received a message (its message info), else now (ns since the epoch)."""
    received = info.get("received_timestamp") if isinstance(info, dict) else None
    return int(received) if received else time.time_ns()


def rclpy_class(msgtype: str):
    """The rclpy message class of ``pkg/msg/Name`` (raises ImportError naming it if missing)."""
    package, kind, name = msgtype.split("/")
    module = importlib.import_module(f"{package}.{kind}")
    try:
        return getattr(module, name)
    except AttributeError:
        raise ImportError(f"{package}.{kind} has no {name}") from None


def controller_seen(node, namespace: str, own_speed_writers: int = 0) -> bool:
    """Whether ``node`` sees a controller of the line in ``namespace``: a reader of its input and a
    writer of its speed commands, on the line's own topic (besides the caller's own
    ``own_speed_writers``) or on the node's batch topic."""
    speed = node.count_publishers(join(namespace, SPEED_CMD)) > own_speed_writers
    batch = node.count_publishers(join(namespace, BATCH_CMD)) > 0
    return node.count_subscribers(join(namespace, INPUT)) > 0 and (speed or batch)


class InputMatches:
    """The input readers the node says each line has matched (``input_readers``, /diagnostics).

    A tick's input reaches only the readers the node's ``input`` writer has matched, so a
    controller seen in the graph (:func:`controller_seen`, this process's view) may still miss a
    tick the node sends before matching it; :meth:`all_matched` is the node's own word."""

    def __init__(self, node):
        self.node = node
        self.readers: dict[str, int] = {}
        node.create_subscription(rclpy_class("diagnostic_msgs/msg/DiagnosticArray"), DIAGNOSTICS, self._on, 10)

    def _on(self, msg) -> None:
        for status in msg.status:
            for kv in status.values:
                if kv.key == "input_readers":
                    self.readers[status.hardware_id.rstrip("/")] = int(kv.value)

    def all_matched(self, namespace: str) -> bool:
        """Whether the node matched every input reader of ``namespace`` seen here (one at least).

        Judged by the node's last status of that line against this process's view of the graph."""
        matched = self.readers.get(namespace.rstrip("/"))
        return matched is not None and matched >= max(1, self.node.count_subscribers(join(namespace, INPUT)))


class CommandMatches:
    """How many writers of a command topic have matched this process's readers, as far as they say.

    Matching is one-sided: our reader matching a controller's writer does not mean that the writer
    has matched our reader, and a writer sends only to readers it has matched. Under load the two
    sides can be far apart, and a lock-step episode runs its course in 60 ms: a recorder that
    counted its own side alone once stored a golden bag without a single command.
    sorting-line-controller says on ``/diagnostics`` how many readers its command writers have
    matched (``cmd_speed_readers``, ``cmd_sort_mode_readers``, once a second, ``hardware_id`` its
    node's name). A writer counts once its node says that it matched every reader of the topic
    seen here; a writer whose node has said nothing about it ``SILENT`` s after we first saw it (a
    controller of your own) counts from then on, trusted without proof."""

    SILENT = 2.5

    def __init__(self, node):
        self.node = node
        self.readers: dict[tuple[str, str], int] = {}  # (writer's node, key) -> readers matched
        self.first_seen: dict[tuple[str, str], float] = {}
        node.create_subscription(rclpy_class("diagnostic_msgs/msg/DiagnosticArray"), DIAGNOSTICS, self._on, 10)

    def _on(self, msg) -> None:
        for status in msg.status:
            for kv in status.values:
                if kv.key.startswith("cmd_") and kv.key.endswith("_readers"):
                    self.readers[(status.hardware_id, kv.key)] = int(kv.value)

    def matched(self, topic: str, ours: int) -> int:
        """Of the ``ours`` writers of ``topic`` our reader has matched, how many count (see above);
        all of them on a topic that is not a line's command topic (:data:`..format.topics.COMMANDS`)."""
        command = next((c for c in COMMANDS if topic.endswith("/" + c)), None)
        if command is None:
            return ours
        key = command.replace("/", "_") + "_readers"  # cmd/speed -> cmd_speed_readers
        readers = self.node.count_subscribers(topic)
        now = time.monotonic()
        waiting = 0
        for info in self.node.get_publishers_info_by_topic(topic):
            writer = (join(info.node_namespace, info.node_name), key)
            said = self.readers.get(writer)
            first = self.first_seen.setdefault(writer, now)
            if said is None and now - first >= self.SILENT:
                continue
            waiting += said is None or said < readers
        return max(0, ours - waiting)


class ToolNode:
    """One rclpy context with one node and one executor; ``close()`` shuts all three down."""

    def __init__(self, name: str, process: NodeProcess | None = None):
        check_domain_id()
        self.context = rclpy.Context()
        # A context of our own: rclpy installs no signal handlers for it (the caller decides).
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(
            f"{name}_{os.getpid()}", context=self.context, start_parameter_services=False, enable_rosout=False
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.waiter = Waiter(self.executor, process)

    def until(self, done: Callable[[], bool], timeout: float, what: Callable[[], str] | str) -> None:
        self.waiter.until(done, timeout, what if callable(what) else (lambda: what))

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.executor.spin_once(timeout_sec=min(left, 0.05))

    def raw_subscription(self, topic: str, msgtype: str, callback: Callable[[bytes, int], None], qos=DEEP_QOS):
        """Subscribes ``topic`` without deserialising: ``callback(cdr_bytes, received_ns)``."""

        # Two parameters: rclpy then passes the message info, whose receive time is the DDS
        # layer's. (The time the executor gets round to the callback would reorder topics.)
        def on_message(data, info):
            callback(data, received_ns(info))

        return self.node.create_subscription(rclpy_class(msgtype), topic, on_message, qos, raw=True)

    def take_into(self, subscriptions: list[tuple[object, Callable[[bytes, int], None]]]) -> None:
        """Hands every message the raw ``subscriptions`` already received to their callbacks
        (``(subscription, callback)`` pairs), without the executor: for a loop that waits on them
        with ``waiter.until_received``, whose round trip is shorter than the executor's."""
        for sub, callback in subscriptions:
            with sub.handle:
                while (taken := sub.handle.take_message(sub.msg_type, True)) is not None:
                    callback(taken[0], received_ns(taken[1]))

    def publisher(self, topic: str, msgtype: str, qos=DEEP_QOS):
        """A publisher of ``msgtype``; ``publish(bytes)`` sends CDR bytes as they are."""
        return self.node.create_publisher(rclpy_class(msgtype), topic, qos)

    def close(self) -> None:
        try:
            self.executor.remove_node(self.node)
            self.node.destroy_node()
            self.executor.shutdown(timeout_sec=0.5)
        finally:
            rclpy.try_shutdown(context=self.context)
