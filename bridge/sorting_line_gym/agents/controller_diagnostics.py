"""The controller's status on ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``, once a
second): which agent decides (a learned policy: what it was trained for), how many decisions it
made and how many ticks the fallback answered instead, so that a plant's monitoring sees a
policy that keeps failing. Level OK, WARN from the first fallback on.

It also says how many readers each command writer has matched (``cmd_speed_readers``,
``cmd_sort_mode_readers``): a writer sends only to readers it has matched, and only the writer's
process knows which; a recorder reads it to tell when this controller's commands reach it
(:class:`..bag.transport.rosnode.CommandMatches`)."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from ..line.topics import DIAGNOSTICS

#: Seconds between two status messages (the node's own diagnostics rate).
PERIOD = 1.0


class ControllerDiagnostics:
    """Publishes ``node``'s status (see the module's docstring); ``fallbacks`` is the count."""

    def __init__(self, node: Node, agent, fallback):
        self.node, self.agent, self.fallback = node, agent, fallback
        self.fallbacks = 0
        self.publisher = node.create_publisher(DiagnosticArray, DIAGNOSTICS, 10)
        self.timer = node.create_timer(PERIOD, self.publish)

    def status(self) -> DiagnosticStatus:
        policy = getattr(self.agent, "policy", None)
        values = {
            "agent": getattr(self.agent, "name", type(self.agent).__name__),
            "policy": policy.describe() if policy is not None else "",
            "fallback": getattr(self.fallback, "name", "none") if self.fallback else "none",
            "decisions": str(self.node.decisions),
            "fallbacks": str(self.fallbacks),
            "skipped_ticks": str(self.node.skipped),
            "cmd_speed_readers": str(self.node.speed_pub.get_subscription_count()),
        }
        if self.node.mode_pub is not None:
            values["cmd_sort_mode_readers"] = str(self.node.mode_pub.get_subscription_count())
        level = DiagnosticStatus.WARN if self.fallbacks else DiagnosticStatus.OK
        message = f"{self.fallbacks} ticks answered by the fallback" if self.fallbacks else "deciding"
        return DiagnosticStatus(
            level=level,
            name=f"{self.node.get_fully_qualified_name()}: controller",
            message=message,
            # Not the namespace: that is the line's own status's hardware_id, by which monitoring
            # (and test_reliability) tells the line's status from others on the topic.
            hardware_id=self.node.get_fully_qualified_name(),
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )

    def publish(self) -> None:
        msg = DiagnosticArray(status=[self.status()])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.publisher.publish(msg)
