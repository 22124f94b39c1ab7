"""`sorting-line-bag record`: records a running line's topics into a ROS 2 bag.

By default it records every topic of the line in namespace NS (``input``, ``belt/occupancy``,
``sensors/ratio`` on the advanced line, ``state``, ``events/reset`` - the resets, since services
are not recorded - and the commands ``cmd/speed`` and ``cmd/sort_mode``) and ``/clock``. Messages
are stored as the CDR bytes rclpy received (``raw=True``), stamped with their receive time, in a
bag directory with metadata.yaml and MCAP files whose schemas are the .msg definitions, written
by :mod:`..storage.writer`: on disk within about half a second of arriving (a recorder killed outright
leaves a bag ``sorting-line-bag reindex`` recovers), split by ``--max-bag-size`` /
``--max-bag-duration`` and chunk-compressed by ``--compression`` as rosbag2 does.

It also asks the node serving the line for its parameters (``get_parameters``) and stores them in
the bag (see :mod:`..format.description`), which is what makes ``sorting-line-bag replay BAG`` self-contained.

Recording starts once every topic the node publishes is matched and a ``/diagnostics`` status of
the line has arrived (proof that the node sends to this recorder); then it prints
``recording ...`` on stdout, and ``matched TOPIC: N publisher(s)`` whenever that count changes
(a controller that joins later: wait for its line before driving, or its first commands are
not in the bag). A command writer counts once it has matched the recorder too, as far as it says
(sorting-line-controller does; a writer that says nothing counts 2.5 s after it was seen).
It stops on SIGINT/SIGTERM, after ``--duration`` seconds, or once
``--max-ticks`` states were recorded, and drains what is still in flight before closing the bag.
At the end it compares what it received with the node's own counters (:mod:`..storage.losses`) and says
how many messages it missed, on which topics; metadata.yaml keeps that for ``info``. A full disk
ends the recording with exit code 3, a message, and the bag as far as it got (readable).
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters

from ...line.topics import DIAGNOSTICS, SENSORS_RATIO, STATE
from ...workarounds.late_matching import retried_handshake
from ..format.description import META_KEY, LineInfo
from ..format.errors import BagError
from ..format.options import WriteOptions
from ..format.topics import (
    CLOCK,
    GLOBAL_TYPES,
    HARDWARE,
    LINE_OPTIONS,
    LINE_TYPES,
    PUBLISHED,
    join,
    line_topics,
    relative_to,
)
from ..storage.losses import LossCounter, describe_losses
from ..storage.schema import typestore
from ..storage.writer import BagWriter
from .rosnode import CommandMatches, ToolNode

#: The node's parameters the recorder asks for: the line's options and the node's publishing rate.
NODE_PARAMETERS = (*LINE_OPTIONS, "rate")
#: Seconds the recorder lets messages queue up (in DDS) before it takes them all.
BATCH_PAUSE = 0.01
#: Parameters a node may lack (older nodes): recorded as "" then.
OPTIONAL_PARAMETERS = ("evolution_file",)


@dataclass
class RecordResult:
    path: Path
    counts: dict[str, int] = field(default_factory=dict)
    info: LineInfo | None = None
    seconds: float = 0.0
    losses: dict | None = None
    files: int = 1

    def summary(self) -> str:
        total = sum(self.counts.values())
        size = sum(f.stat().st_size for f in self.path.iterdir() if f.is_file()) if self.path.exists() else 0
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))
        return (
            f"{self.path}: {total} messages in {self.seconds:.1f} s, {size / 1024:.1f} KiB in {self.files} "
            f"file(s) ({per_topic})\n{describe_losses(self.losses)}"
        )


def _ask(tool, client, service: str, timeout: float):
    """One GetParameters call of ``client``, its reply within ``timeout`` (TimeoutError else)."""
    future = client.call_async(GetParameters.Request(names=list(NODE_PARAMETERS)))
    try:
        tool.until(future.done, timeout, f"a reply from {service}")
    except TimeoutError:
        client.remove_pending_request(future)
        raise
    return future.result()


def _parameter_value(v):
    return {
        ParameterType.PARAMETER_BOOL: v.bool_value,
        ParameterType.PARAMETER_INTEGER: v.integer_value,
        ParameterType.PARAMETER_DOUBLE: v.double_value,
        ParameterType.PARAMETER_STRING: v.string_value,
    }.get(v.type)


def node_options(tool: ToolNode, namespace: str, timeout: float) -> dict | None:
    """The parameters of the node that publishes ``<namespace>/state``, with ``seed`` made the
    line's own (node seed + k for ``<ns>/line_k``); None if no such node answers in time.

    The call is repeated (it is idempotent): right after discovery the node may match our request
    writer before our reply reader, and a reply sent before that is lost for good (volatile)."""
    state = join(namespace, STATE)
    # Until the node's ros_discovery_info arrives, its endpoints belong to "_CREATED_BY_BARE_DDS_APP_".
    named = []

    def publishers_named() -> bool:
        named[:] = [i for i in tool.node.get_publishers_info_by_topic(state) if not i.node_name.startswith("_")]
        return bool(named)

    try:
        tool.until(publishers_named, timeout, f"the name of the node publishing {state}")
    except TimeoutError:
        return None
    for info in named:
        service = join(info.node_namespace, f"{info.node_name}/get_parameters")
        client = tool.node.create_client(GetParameters, service)
        values = None
        try:
            tool.until(client.service_is_ready, timeout, f"service {service}")
            # A reply can be lost while the node still matches our reply reader (late_matching).
            reply = retried_handshake(functools.partial(_ask, tool, client, service), (2.0, 2.0, 2.0), TimeoutError)
            values = [_parameter_value(v) for v in reply.values]
            values = [
                "" if v is None and n in OPTIONAL_PARAMETERS else v
                for n, v in zip(NODE_PARAMETERS, values, strict=False)
            ]
        except TimeoutError:
            pass
        finally:
            tool.node.destroy_client(client)
        if values is None or None in values:
            continue
        options = dict(zip(NODE_PARAMETERS, values, strict=False))
        line = 0
        tail = namespace.rstrip("/").rsplit("/", 1)[-1]
        if options["lines"] > 1 and tail.startswith("line_") and tail[5:].isdigit():
            line = int(tail[5:])
        options["seed"] = int(options["seed"]) + line
        options["line"] = line
        _store_schedule(options)
        return options
    return None


def _store_schedule(options: dict) -> None:
    """An evolving line's schedule goes into the bag as text (``evolution``), so a replay needs
    nothing but the bag; the node's file is read here, on the node's host."""
    path = options.get("evolution_file") or ""
    if not path:
        options.pop("evolution_file", None)
        return
    try:
        options["evolution"] = Path(path).read_text()
    except OSError as e:
        print(
            f"sorting-line-bag record: warning: cannot read the node's evolution schedule {path} ({e}); "
            "`replay` will need it",
            file=sys.stderr,
            flush=True,
        )


def record(
    namespace: str,
    out: str | Path,
    topics: list[str] | None = None,
    *,
    duration: float | None = None,
    max_ticks: int | None = None,
    wait: float = 10.0,
    stop: Callable[[], bool] = lambda: False,
    on_ready: Callable[[str], None] = print,
    diagnostics: bool = False,
    options: WriteOptions | None = None,
) -> RecordResult:
    """Records until ``stop()`` says so, ``duration`` seconds pass or ``max_ticks`` states arrived.

    ``topics``: absolute names or names relative to ``namespace``; None = the line's topics and
    /clock (plus /diagnostics with ``diagnostics=True``). ``options``: splitting and compression.
    Raises BagError for bad input (an unknown topic, an existing or unwritable output, a bad
    option), BagWriteError when writing fails on the way (a full disk), and TimeoutError when the
    line does not show up.

    Two phases: match (find the line's node and its parameters, the topics and their types, and
    wait until the node's topics are matched) and write (store what arrives until the end, then
    drain what is in flight, and compare with the node's counters: :mod:`..storage.losses`)."""
    namespace = "/" + namespace.strip("/")
    out = Path(out)
    options = (options or WriteOptions()).check()
    _check_output(out)
    tool = ToolNode("sorting_line_bag_record")
    writer = None
    try:
        node_options, types = _match(tool, namespace, topics, diagnostics, wait)
        info = LineInfo(namespace, node_options or {})
        writer = BagWriter(out, {META_KEY: info.to_json()}, options)
        for name, msgtype in types.items():
            writer.add_topic(name, msgtype)
        evolving = bool(node_options and node_options.get("evolution_file"))
        counter = LossCounter(
            namespace, list(types), info.node.get("variant"), evolving, float(info.node.get("tick_period") or 1.0)
        )
        diag = _line_reports(tool, namespace, counter)
        subs, states = _subscribe(tool, writer, counter, types, join(namespace, STATE))
        _await_matched(tool, namespace, subs, wait, evolving=evolving)
        on_ready(f"recording {len(types)} topics of {namespace} into {out}")
        started = time.monotonic()
        _write(
            tool, writer, subs, lambda: states[0], duration=duration, max_ticks=max_ticks, stop=stop, on_ready=on_ready
        )
        seconds = time.monotonic() - started
        losses = _compare_and_close(tool, writer, counter, diag)
        return RecordResult(out, dict(writer.counts), info, seconds, losses, len(writer.files))
    finally:
        if writer is not None:
            writer.close(state="stopped by an error")
        tool.close()


def _subscribe(
    tool: ToolNode, writer: BagWriter, counter: LossCounter, types: dict[str, str], state: str
) -> tuple[dict, list[int]]:
    """A subscription per topic, each storing what arrives and counting it for the loss report; and
    the number of ``state`` messages so far (in a one-item list the callbacks update)."""
    states = [0]

    def keep(name):
        def on(data: bytes, received: int):
            writer.write(name, received, data)
            counter.on_message(name, data)
            if name == state:
                states[0] += 1

        return on

    return {name: tool.raw_subscription(name, msgtype, keep(name)) for name, msgtype in types.items()}, states


def _compare_and_close(tool: ToolNode, writer: BagWriter, counter: LossCounter, diag) -> dict:
    """Waits for one more report of the node's counters, compares, stores the result, closes the bag."""
    last = counter.last
    with contextlib.suppress(TimeoutError):  # a report after the drain: the window covers (nearly) all
        tool.until(lambda: counter.last != last, 1.5, f"a {DIAGNOSTICS} report of the line")
        tool.spin_for(0.3)  # the line's messages sent before that report (other topics may come later)
    tool.node.destroy_subscription(diag)
    losses = counter.report()
    writer.set_losses(losses)
    writer.close()
    return losses


def _check_output(out: Path) -> None:
    """Fails before any waiting when the bag directory cannot be made."""
    if out.exists():
        raise BagError(f"{out} exists already: choose a new output directory")
    parent = out.absolute().parent
    if not parent.is_dir():
        raise BagError(f"{out}: cannot create the bag directory: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise BagError(f"{out}: cannot create the bag directory: {parent} is not writable")


def _line_reports(tool: ToolNode, namespace: str, counter: LossCounter):
    """Feeds the line's /diagnostics reports (its counters) to ``counter``."""

    def on(array):
        for status in array.status:
            if status.hardware_id == namespace:
                counter.on_status({kv.key: kv.value for kv in status.values})

    return tool.node.create_subscription(DiagnosticArray, DIAGNOSTICS, on, 10)


def _match(
    tool: ToolNode, namespace: str, topics: list[str] | None, diagnostics: bool, wait: float
) -> tuple[dict | None, dict[str, str]]:
    """The line's node options (None if it does not tell) and the recorded topics with their types."""
    state = join(namespace, STATE)
    tool.until(
        lambda: tool.node.count_publishers(state) > 0,
        wait,
        f"a sorting_line node publishing {state} (is the namespace right?)",
    )
    options = node_options(tool, namespace, min(wait, 5.0))
    if options is None:
        print(
            f"sorting-line-bag record: warning: could not read the parameters of the node serving {namespace}; "
            "`replay` will need its options as flags",
            file=sys.stderr,
            flush=True,
        )
    variant = (
        options["variant"]
        if options
        else ("advanced" if tool.node.count_publishers(join(namespace, SENSORS_RATIO)) else "basic")
    )
    evolving = bool(options and options.get("evolution_file"))
    wanted = topics if topics else [*line_topics(variant, evolving), CLOCK] + ([DIAGNOSTICS] if diagnostics else [])
    types = {}
    for name in {join(namespace, t): t for t in wanted}:
        rel = relative_to(namespace, name)
        msgtype = LINE_TYPES.get(rel) if rel is not None else GLOBAL_TYPES.get(name)
        types[name] = msgtype if msgtype is not None else _graph_type(tool, name, min(wait, 3.0))
    return options, types


def _await_matched(tool: ToolNode, namespace: str, subs: dict, wait: float, evolving: bool = False) -> None:
    """Ready when the node's topics are matched and the node has shown it sends to us (a
    /diagnostics status of the line). An evolving line's hardware topics may not exist yet."""
    seen_status = []
    diag = tool.node.create_subscription(
        DiagnosticArray,
        DIAGNOSTICS,
        lambda a: seen_status.append(1) if any(s.hardware_id == namespace for s in a.status) else None,
        10,
    )
    node_side = [
        n
        for n in subs
        if (relative_to(namespace, n) in PUBLISHED or n == CLOCK)
        and not (evolving and relative_to(namespace, n) in HARDWARE)
    ]
    tool.until(
        lambda: all(subs[n].get_publisher_count() > 0 for n in node_side) and seen_status,
        wait,
        lambda: (
            f"the topics of {namespace} to match and a {DIAGNOSTICS} status of the line "
            f"(unmatched: {[n for n in node_side if subs[n].get_publisher_count() == 0]})"
        ),
    )
    tool.node.destroy_subscription(diag)


def _write(
    tool: ToolNode,
    writer: BagWriter,
    subs: dict,
    states: Callable[[], int],
    *,
    duration: float | None,
    max_ticks: int | None,
    stop: Callable[[], bool],
    on_ready: Callable[[str], None],
) -> None:
    """Spins (the subscriptions write) until the end, telling who joins (a controller's writer
    once it has matched us too, as far as it says: :class:`.rosnode.CommandMatches`); then drains."""
    started = time.monotonic()
    matched: dict[str, int] = {}
    commands = CommandMatches(tool.node)
    next_check = 0.0

    def done() -> bool:
        if stop() or (max_ticks is not None and states() >= max_ticks):
            return True
        return duration is not None and time.monotonic() - started >= duration

    while not done():
        now = time.monotonic()
        if now >= next_check:  # tell who joins (a controller started later, say), so scripts can wait for it
            next_check = now + 0.2
            for name, sub in subs.items():
                n = commands.matched(name, sub.get_publisher_count())
                if matched.get(name) != n:
                    matched[name] = n
                    on_ready(f"matched {name}: {n} publisher(s)")
        # The recorded topics are taken here, every message each holds, without the executor: it
        # builds a wait set of every subscription per wait and runs each callback as a Task, ~195 us
        # a message. The executor still serves the rest (the node's /diagnostics reports).
        for sub in subs.values():
            with sub.handle:
                while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                    sub.callback(*taken)
            if done():
                break
        tool.executor.spin_once(timeout_sec=0)
        writer.tick()  # what arrived more than FLUSH_INTERVAL ago goes to disk, even when nothing more comes
        time.sleep(BATCH_PAUSE)
    # Drain what is in flight: spin until nothing has arrived for 0.2 s (at most 2 s).
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        before = sum(writer.counts.values())
        tool.spin_for(0.2)
        if sum(writer.counts.values()) == before:
            break


def _graph_type(tool: ToolNode, name: str, timeout: float) -> str:
    """The type of a topic the graph knows (any publisher or subscriber), else BagError."""
    found: list[str] = []

    def look() -> bool:
        for topic, types in tool.node.get_topic_names_and_types():
            if topic == name and types:
                found.append(types[0])
                return True
        return False

    try:
        tool.until(look, timeout, f"topic {name} in the graph")
    except TimeoutError:
        raise BagError(f"unknown topic {name}: nothing publishes or subscribes it (waited {timeout:g} s)") from None
    if found[0] not in typestore().fielddefs:
        raise BagError(f"topic {name} has type {found[0]}, which this tool cannot embed a schema for")
    return found[0]
