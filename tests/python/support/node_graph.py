"""What a node publishes beside its lines, as the tests record and wait for it: the simulated /clock, the
/diagnostics status of each line (waited on until a status holds given values), and the graph's topics."""

from __future__ import annotations

from sorting_line_gym.line.topics import CLOCK, DIAGNOSTICS
from support import ros_harness as h


def clock_recorder(ros, probe):
    from rosgraph_msgs.msg import Clock

    return h.TopicRecorder(ros, probe, CLOCK, Clock)


def diagnostics_recorder(ros, probe):
    from diagnostic_msgs.msg import DiagnosticArray

    return h.TopicRecorder(ros, probe, DIAGNOSTICS, DiagnosticArray)


def wait_diagnostics(
    diag: h.TopicRecorder, hardware_id: str, want: dict[str, str], timeout: float = 5.0, context=lambda: ""
) -> dict[str, str]:
    """Waits (the node publishes at 1 Hz) for a status of `hardware_id` whose values include `want`."""

    def matches(array):
        values = h.diagnostic_values(array, hardware_id)
        return values is not None and all(values.get(k) == v for k, v in want.items())

    def last_seen():
        for array in reversed(diag.msgs):
            values = h.diagnostic_values(array, hardware_id)
            if values is not None:
                return f"want {want}\nlast status of {hardware_id}: {values}\n{context()}"
        return f"no status of {hardware_id} at all ({len(diag.msgs)} arrays received)\n{context()}"

    array = diag.wait_for(matches, timeout, f"a status of {hardware_id} with {want}", last_seen)
    return h.diagnostic_values(array, hardware_id)


def topic_types(node) -> dict[str, list[str]]:
    return dict(node.get_topic_names_and_types())
