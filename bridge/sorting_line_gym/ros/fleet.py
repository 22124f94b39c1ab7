"""Lines on several nodes (several namespaces, possibly on several hosts of one DDS domain)
driven as one bank: what the vector environments stand on when ``namespace`` names more than one
node.

Each node is a :class:`LineBank` in batch mode (its ``batch/cmd``, ``batch/state`` and
``batch/reset``). A step publishes every node's command first and then waits for every node's
state: one round trip per node, all of them in flight at once, so a step over K hosts costs about
the slowest host's round trip, not the sum. Line i of the fleet is line i - offset of its node, in
the order the namespaces were given.

A node that does not answer (its host's link is down, its process died) makes the wait fail after
``step_timeout`` with an error naming that node's namespace and the fleet's lines it hosts; the
other nodes are left as they were, so envs on them go on working.
"""

from __future__ import annotations

import time
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
from sorting_line_interfaces.msg import LineStates

from ..line.errors import BridgeError, BridgeTimeout
from ..line.options import LineOptions
from .bank import LineBank
from .batch_codec import BatchCodec, row_bytes
from .waits import Waiter

#: How long each pending node's executor is spun per turn while resets of several nodes are in
#: flight (their replies are futures served by each bank's own executor).
_RESET_SLICE = 0.002


def split_lines(num_envs: int, nodes: int) -> int:
    """Lines per node when ``num_envs`` lines are spread evenly over ``nodes`` nodes."""
    if nodes < 1 or num_envs % nodes:
        raise ValueError(
            f"num_envs = {num_envs} lines cannot be spread evenly over {nodes} nodes: give a multiple of {nodes}"
        )
    return num_envs // nodes


class _FleetNodes:
    """The banks' node processes as one ``line.process.HeldNode`` (a ``Waiter`` watches one): alive
    while every one is, and a wait fails at once, naming the dead ones, when one is not."""

    def __init__(self, banks: list[LineBank]):
        self.banks = banks

    def alive(self) -> bool:
        return all(b.process is None or b.process.alive() for b in self.banks)

    def death_notice(self) -> str:
        return "; ".join(
            b.process.death_notice() for b in self.banks if b.process is not None and not b.process.alive()
        )


class NodeFleet:
    """The lines of several nodes, ``lines_per_node`` each, stepped and reset together."""

    def __init__(self, options: LineOptions, namespaces: list[str], lines_per_node: int):
        if len(set(namespaces)) != len(namespaces):
            raise ValueError(f"namespace lists a node twice: {namespaces}")
        if options.node == "shared":
            raise ValueError("node='shared' leases single lines: several namespaces need node='attach' or 'spawn'")
        self.namespaces = list(namespaces)
        self.lines_per_node = lines_per_node
        self.banks = [LineBank(replace(options, namespace=ns), lines=lines_per_node, batch=True) for ns in namespaces]
        self._waiter: Waiter | None = None
        self.step_timeout = options.step_timeout
        #: Each node's newest state batch, gathered as one row a node for the step's result.
        self._states = BatchCodec(LineStates, lines_per_node)
        self._rows = self._states.records(len(namespaces))
        self._row_bytes = row_bytes(self._rows)

    def __len__(self) -> int:
        return self.lines_per_node * len(self.banks)

    def where(self, b: int) -> str:
        """The node of bank b and the fleet's lines on it, for errors."""
        first = b * self.lines_per_node
        return f"the node serving {self.namespaces[b]} (lines {first}..{first + self.lines_per_node - 1} of this env)"

    def _by_bank(self, seeds: dict[int, int | None]) -> dict[int, dict[int, int | None]]:
        per: dict[int, dict[int, int | None]] = {}
        for k, seed in seeds.items():
            per.setdefault(k // self.lines_per_node, {})[k % self.lines_per_node] = seed
        return per

    def reset(self, seeds: dict[int, int | None]):
        """Resets the given lines (fleet index -> seed): a node's first reset is its handshake
        (one node after another, as joining the graph is); later resets of several nodes are in
        flight together."""
        results = {}
        fresh, joined = {}, {}
        for b, local in self._by_bank(seeds).items():
            (joined if self.banks[b].connected else fresh)[b] = local
        for b, local in fresh.items():
            try:
                answers = self.banks[b].reset(local)
            except BridgeError as e:
                raise type(e)(f"{self.where(b)}: {e}") from e
            results.update({b * self.lines_per_node + k: r for k, r in answers.items()})
        if joined:
            results.update(self._reset_together(joined))
        return results

    def _reset_together(self, per_bank: dict[int, dict[int, int | None]]):
        for b, local in per_bank.items():
            self.banks[b].check_usable()
            self.banks[b].batch.send_reset(local)
        pending = set(per_bank)
        deadline = time.monotonic() + self.step_timeout
        while pending:
            for b in list(pending):
                bank = self.banks[b]
                if bank.batch.reset_done():
                    pending.discard(b)
                    continue
                if bank.process is not None and not bank.process.alive():
                    raise BridgeError(f"{self.where(b)}: {bank.process.death_notice()}")
                bank.executor.spin_once(timeout_sec=_RESET_SLICE)
            if pending and time.monotonic() > deadline:
                names = "; ".join(
                    f"{self.where(b)}: the reply of {self.banks[b].batch.reset_name}" for b in sorted(pending)
                )
                raise BridgeTimeout(f"timed out after {self.step_timeout:g} s waiting for {names}")
        results = {}
        for b, local in per_bank.items():
            answers = self.banks[b].batch.finish_reset(local)
            results.update({b * self.lines_per_node + k: r for k, r in answers.items()})
        return results

    def step_batch(self, speed_indices, modes) -> SimpleNamespace:
        """Steps every line: every node's ``batch/cmd`` goes out, then every node's next
        ``batch/state`` is awaited on one wait set. Returns the states as one batch (entry i =
        fleet line i)."""
        n = self.lines_per_node
        speed_indices = np.asarray(speed_indices)
        modes = np.asarray(modes)
        for bank in self.banks:
            bank.check_usable()
            bank.batch.check_started()
        for b, bank in enumerate(self.banks):
            bank.batch.send(speed_indices[b * n : (b + 1) * n], modes[b * n : (b + 1) * n])
        pending = set(range(len(self.banks)))

        def arrived() -> bool:
            for b in list(pending):
                if self.banks[b].batch.take_next_states():
                    pending.discard(b)
            return not pending

        if self._waiter is None:
            first = self.banks[0]
            self._waiter = Waiter(first.executor, _FleetNodes(self.banks))
        self._waiter.until_received(
            [bank.batch.state_sub for bank in self.banks],
            arrived,
            self.step_timeout,
            lambda: "; ".join(f"{self.where(b)}: {self.banks[b].batch.describe_wait()}" for b in sorted(pending)),
        )
        for b, bank in enumerate(self.banks):
            self._row_bytes[b] = bank.batch.position_bytes
        return self._states.fields(self._rows)

    def close(self) -> None:
        for bank in self.banks:
            bank.close()
