"""The lines of one node, driven together: what both the single-line environment and the
vector environments stand on.

A bank owns one rclpy node and one executor, and (with ``node="spawn"``) the node process, or
(``node="shared"``) the lease of a line server's line. One call to :meth:`LineBank.step` (or
:meth:`LineBank.step_batch`) publishes the commands of every line and waits for every line's next
state: one round trip steps all lines. It reaches the lines through a :mod:`.transports` class.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable, Sequence

import rclpy
from builtin_interfaces.msg import Time
from rclpy.executors import SingleThreadedExecutor
from sorting_line_interfaces.msg import BeltOccupancy, LineState, MaterialInput

from ..line import line_server
from ..line.errors import BridgeError
from ..line.line_server import Lease
from ..line.options import LineOptions
from ..line.process import STOP_TIMEOUT, NodeProcess, private_namespace
from ..line.topics import BELT_OCCUPANCY, INPUT, join
from ..line.vocabulary import NODE_LINES
from ..workarounds.fork_unsafe_dds import fork_error
from ..workarounds.late_matching import (
    FRESH_NODE_ATTEMPTS,
    HANDSHAKE_TIMEOUTS,
    repeated_while_unanswered,
    retried_handshake,
)
from ..workarounds.participant_deletion_hang import retire_node
from ..workarounds.simultaneous_discovery import joining_graph
from .context import acquire_rclpy, release_rclpy
from .links import QOS, BatchLink, LineLink, ResetResult, stamp_key
from .transports import BatchTransport, PerLineTransport, Transport
from .waits import Waiter

_bank_ids = itertools.count()

#: Waits of a first exchange (:meth:`LineBank._first_exchange`): the reset's reply, the step-0
#: state, the first proof.
EXCHANGE_WAITS = 3

#: Seconds the executor is given to shut down when a bank is torn down.
EXECUTOR_SHUTDOWN = 0.5


class LineBank:
    """N lines hosted by one `sorting_line node`, stepped in lock-step together: with
    ``batch=False`` through each line's own topics (:class:`PerLineTransport`, :meth:`step`), with
    ``batch=True`` through the node's ``batch/cmd`` and ``batch/state`` (:class:`BatchTransport`,
    :meth:`step_batch`)."""

    def __init__(
        self,
        options: LineOptions,
        *,
        lines: int = 1,
        watch_sensors: bool = False,
        batch: bool = False,
        watch: dict | None = None,
        on_fresh_node: Callable[[], None] | None = None,
        first_proof: Callable[[dict[int, ResetResult]], str | None] | None = None,
    ):
        if options.node == "shared" and (lines != 1 or batch):
            raise ValueError("node='shared' leases one line: it is for single-line environments")
        if not 1 <= lines <= NODE_LINES:
            raise ValueError(f"lines = {lines} is out of range: allowed 1 ..= {NODE_LINES}")
        self.options = options
        self.variant = options.variant
        self.advanced = options.advanced
        self.setup = options.setup
        self.step_timeout = options.step_timeout
        self.startup_timeout = options.startup_timeout
        self.namespace = options.namespace or private_namespace()
        #: The node process this bank started, or the line it leased; None when it attaches.
        self.process: NodeProcess | Lease | None = None
        self._closed = False
        self._opened_in: int | None = None  # the pid that opened the bank (see open())
        self._node_mode = options.node
        self._lines = lines
        self._node_options = options.node_options(lines)
        self._watch_sensors = watch_sensors
        self._batch = batch
        #: Extra topics of line 0 to subscribe to when the bank opens, {relative topic: (type,
        #: callback)}; the first reset waits until each is matched with a publisher (e.g. events/evolution).
        self._watch = dict(watch or {})
        #: Called when the first reset's node is replaced by a fresh one (see _counted_handshake),
        #: e.g. to drop what the watch callbacks kept from the old node.
        self._on_fresh_node = on_fresh_node
        #: What else the first reset's exchange must deliver, beyond its reply and step-0 state, to
        #: count as done: given the replies, it names what has not arrived, or returns None (e.g.
        #: the evolving line's announcement of the episode's setup, on a watched topic).
        self._first_proof = first_proof
        #: Whether each reset is an event for the node (an evolving line: its schedule's next
        #: episode), so that the handshake must not repeat one (workarounds.late_matching).
        self.resets_count = options.evolution is not None
        self.transport: Transport | None = None
        self.links: list[LineLink] = []
        #: The batch topics (with ``batch=True``), for a fleet that steps several banks together.
        self.batch: BatchLink | None = None
        #: Whether the first reset's handshake is done (the bank joined the graph and found the node).
        self.connected = False

    def open(self) -> None:
        """Starts the node process (``node="spawn"``), rclpy and this bank's endpoints: what the
        constructor leaves to the first reset, so that an environment costs nothing until it is
        used (Gymnasium's AsyncVectorEnv builds one in the parent only to read its spaces, then
        forks) and a forked child never inherits a live rclpy context."""
        self._check_not_closed()
        if self._opened_in is not None:
            if self._opened_in != os.getpid():
                raise fork_error() or BridgeError(f"{self.namespace}: this bank was opened in pid {self._opened_in}")
            return
        acquire_rclpy()
        self._opened_in = os.getpid()
        lines = self._lines
        try:
            if self._node_mode == "spawn":
                self.process = NodeProcess(self.namespace, self._node_options)
            elif self._node_mode == "shared":
                options = {k: v for k, v in self._node_options.items() if k != "lines"}
                self.process = line_server.lease(options, self.startup_timeout)
                self.namespace = self.process.namespace
            # No parameter services or rosout: every entity is one more thing each wait scans.
            self.node = rclpy.create_node(
                f"sorting_line_gym_{os.getpid()}_{next(_bank_ids)}",
                start_parameter_services=False,
                enable_rosout=False,
            )
            self.executor = SingleThreadedExecutor()
            self.executor.add_node(self.node)
            base = self.namespace.rstrip("/")
            spaces = [base] if lines == 1 else [f"{base}/line_{k}" for k in range(lines)]
            if self._batch:
                self.transport = BatchTransport(self.node, self.namespace, spaces, self.advanced)
                self.batch = self.transport.batch
            else:
                self.transport = PerLineTransport(self.node, spaces, self.advanced)
            self.links = self.transport.links
            self.waiter = Waiter(self.executor, self.process)
            self.sensors: list[dict[str, dict]] = [{"input": {}, "belt": {}} for _ in spaces]
            self._watched = [
                self.node.create_subscription(msg_type, f"{spaces[0]}/{topic}", callback, QOS)
                for topic, (msg_type, callback) in self._watch.items()
            ]
            if self._watch_sensors:
                for k, ns in enumerate(spaces):
                    self.node.create_subscription(MaterialInput, join(ns, INPUT), self._keep(k, "input"), QOS)
                    self.node.create_subscription(BeltOccupancy, join(ns, BELT_OCCUPANCY), self._keep(k, "belt"), QOS)
        except BaseException:
            self.close()
            raise

    def _keep(self, k: int, kind: str):
        store = self.sensors[k][kind]

        def keep(message):
            store[stamp_key(message.header.stamp)] = message
            while len(store) > 8:  # the renderer needs the current tick only
                store.pop(next(iter(store)))

        return keep

    def __len__(self) -> int:
        return self._lines

    def sensor_readings(self, k: int, stamp: Time, timeout: float = 2.0) -> tuple[MaterialInput, BeltOccupancy]:
        """Line k's ``input`` and ``belt/occupancy`` messages of the tick stamped ``stamp`` (needs
        ``watch_sensors``). They travel on their own topics and may arrive after the tick's state,
        so this spins until both are in."""
        key = stamp_key(stamp)
        store = self.sensors[k]
        self.waiter.until(
            lambda: key in store["input"] and key in store["belt"],
            timeout,
            lambda: (
                f"the {INPUT} and {BELT_OCCUPANCY} messages of tick {key[0]}.{key[1]:09d} s "
                f"on {self.links[k].namespace}"
            ),
        )
        return store["input"][key], store["belt"][key]

    # ----------------------------------------------------------------------------------------
    def _connect(self, deadline: float) -> None:
        self.waiter.until_deadline(
            lambda: (
                not self.transport.missing(self.node) and all(sub.get_publisher_count() > 0 for sub in self._watched)
            ),
            deadline,
            self.startup_timeout,
            lambda: (
                f"the sorting_line node serving {self.namespace} (its reset service and topics; {self._unmatched()})"
            ),
        )
        self.connected = True

    def _unmatched(self) -> str:
        """What discovery still lacks, e.g. "not yet discovered: /ns/line_3 reset service" (when a
        node's endpoints go missing, which ones is the first clue to why)."""
        missing = self.transport.missing(self.node)
        return "not yet discovered: " + ", ".join(missing) if missing else "all discovered"

    def reset(self, seeds: dict[int, int | None]):
        """Resets the given lines (index -> seed, None = the node's streams carry on) and returns
        their :class:`ResetResult`. The first reset is a handshake: its reply and the step-0 state
        after it must both arrive. Either can be lost right after discovery (the node may match
        our request writer before our reply reader, or our state reader), so the handshake is
        retried; with explicit seeds a repeated reset gives the same episode.

        Joining the DDS graph (rclpy's participant, the node's, discovery of the node's endpoints)
        happens one bank at a time per host and domain (:func:`joining_graph`): participants that
        join together lose endpoint announcements for good (docs/many-envs.md)."""
        if self.connected:
            self.check_usable()
            return self._reset_once(seeds)
        with joining_graph(self._longest_join()):
            # Once it is this bank's turn, startup_timeout bounds the rest of the start: rclpy,
            # the node (or the lease), discovery.
            deadline = time.monotonic() + self.startup_timeout
            self.open()
            return self._handshake(seeds, deadline)

    def _longest_join(self) -> float:
        """The longest this bank can hold the host's join lock, every wait in its turn at its
        bound: the start (``startup_timeout``, which bounds open and discovery) and the first
        reset, three waits per exchange (:meth:`_first_exchange`): with resets that count up to
        ``FRESH_NODE_ATTEMPTS`` exchanges of ``step_timeout``, each after the first on a fresh
        node (a tear-down, a start); otherwise the retried handshake's short attempts; and the
        tear-down of a start that failed. Waiters on the lock wait this long for this bank
        (:func:`joining_graph`), not their own bound."""
        tear_down = EXECUTOR_SHUTDOWN + 2 * STOP_TIMEOUT  # a start that fails tears its node down
        if self.resets_count:
            exchanges = FRESH_NODE_ATTEMPTS * EXCHANGE_WAITS * self.step_timeout
            handshake = exchanges + (FRESH_NODE_ATTEMPTS - 1) * (tear_down + self.startup_timeout)
        else:
            handshake = sum(EXCHANGE_WAITS * min(limit, self.step_timeout) for limit in HANDSHAKE_TIMEOUTS)
        return self.startup_timeout + handshake + tear_down

    def _handshake(self, seeds: dict[int, int | None], deadline: float):
        self._connect(deadline)
        if self.resets_count:
            return self._counted_handshake(seeds)
        return retried_handshake(
            lambda limit: self._first_exchange(seeds, min(limit, self.step_timeout)),
            HANDSHAKE_TIMEOUTS,
            BridgeError,
            hopeless=self._node_died,
        )

    def _first_exchange(self, seeds: dict[int, int | None], timeout: float):
        """One reset whose reply, step-0 state and ``first_proof`` must each arrive within
        ``timeout``. Each travels from its own writer, which may not have matched our reader yet."""
        responses = self._reset_once(seeds, timeout=timeout)
        self.waiter.until(
            lambda: self.transport.saw_first_states(seeds),
            timeout,
            lambda: f"the first state of {self.namespace} after reset",
        )
        proof = self._first_proof
        if proof is not None:
            self.waiter.until(lambda: proof(responses) is None, timeout, lambda: f"{self.namespace}/{proof(responses)}")
        return responses

    def _counted_handshake(self, seeds: dict[int, int | None]):
        """The first reset of a line whose resets count: sent once to each node, its reply and
        step-0 state waited for as any reset's (a slow reply is waited out, never repeated: the
        repetition would be the schedule's next episode). A node whose first exchange did not
        complete is replaced (``node="spawn"``) by a fresh one, which has had no reset; an
        attached node cannot be, so the error goes on."""

        def attempt(_k: int):
            try:
                return self._first_exchange(seeds, self.step_timeout)
            except BridgeError as error:
                return error

        def unanswered(result) -> bool:
            return isinstance(result, BridgeError) and not self._node_died()

        attempts = FRESH_NODE_ATTEMPTS if self._node_mode == "spawn" else 1
        result = repeated_while_unanswered(attempt, unanswered, attempts, before_repeat=lambda _: self._fresh_node())
        if isinstance(result, BridgeError):
            raise result
        return result

    def _fresh_node(self) -> None:
        """Replaces the node process and this bank's endpoints by new ones (in a new private
        namespace unless one was given), discovered and ready for a first reset."""
        deadline = time.monotonic() + self.startup_timeout
        self._tear_down()
        self._opened_in = None
        if self.options.namespace is None:
            self.namespace = private_namespace()
        if self._on_fresh_node is not None:
            self._on_fresh_node()
        self.open()
        self._connect(deadline)

    def _node_died(self) -> bool:
        return bool(self.process and not self.process.alive())

    def _reset_once(self, seeds: dict[int, int | None], timeout: float | None = None):
        timeout = self.step_timeout if timeout is None else timeout
        self.transport.send_reset(seeds)
        self.waiter.until(
            lambda: self.transport.reset_done(seeds), timeout, lambda: self.transport.awaited_reply(seeds)
        )
        return self.transport.finish_reset(seeds)

    def step(self, actions: Sequence[tuple[int, int]]) -> list[LineState]:
        """Sends (speed index, mode) to every line and waits for each line's next state."""
        self.check_usable()
        if len(actions) != len(self.links):
            raise ValueError(f"{len(actions)} actions for {len(self.links)} lines")
        for link in self.links:
            if link.tick is None:
                raise BridgeError(f"{link.namespace}: step() before reset()")
        if not isinstance(self.transport, PerLineTransport):
            raise BridgeError("a bank of several lines steps with step_batch()")
        self._round_trip([speed for speed, _ in actions], [mode for _, mode in actions])
        return self.transport.states()

    def step_batch(self, speed_indices, modes):
        """Steps every line through ``batch/cmd`` and returns the ``batch/state`` message (arrays,
        entry k = line k)."""
        self.check_usable()
        if not isinstance(self.transport, BatchTransport):
            raise BridgeError("a single-line bank steps with step()")
        self._round_trip(speed_indices, modes)
        return self.transport.states()

    def _round_trip(self, speed_indices, modes) -> None:
        transport = self.transport
        transport.send(speed_indices, modes)
        self.waiter.until_received(
            transport.state_subscriptions(), transport.take_next_states, self.step_timeout, transport.describe_wait
        )

    def check_usable(self) -> None:
        """Raises unless this bank was opened (by a reset) in this very process: a bank
        used before its first reset, or inherited by a forked child, cannot step."""
        self._check_not_closed()
        if self._opened_in is None:
            raise BridgeError(f"{self.namespace}: step() before reset()")
        if self._opened_in != os.getpid():
            raise fork_error() or BridgeError(f"{self.namespace}: this bank was opened in pid {self._opened_in}")

    def _check_not_closed(self) -> None:
        """A closed environment fails with our error, not rclpy's InvalidHandle of a destroyed node."""
        if self._closed:
            raise BridgeError(
                f"{self.namespace}: the environment is closed (close() was called): make a new one to reset or step"
            )

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._opened_in is None:
            return  # never opened: nothing was started
        if self._opened_in != os.getpid():
            return  # a forked copy: the rclpy entities and the node process belong to the parent
        self._tear_down()

    def _tear_down(self) -> None:
        """Destroys this bank's rclpy node and stops its node process (see close())."""
        node = getattr(self, "node", None)
        if node is not None:
            self.executor.remove_node(node)
            retire_node(node)
            self.executor.shutdown(timeout_sec=EXECUTOR_SHUTDOWN)
            self.node = None
        # The participant goes (if this bank was its last user) before the node process does: the
        # node's departure is a discovery event, and one in flight when the participant is deleted
        # can make the deletion spin (workarounds.participant_deletion_hang).
        release_rclpy()
        if self.process is not None:
            # A node killed from outside (a fault test) is not an error of close().
            self.process.stop()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
