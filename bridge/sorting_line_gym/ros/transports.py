"""How a bank reaches its lines: through each line's own topics (:class:`PerLineTransport`, the
documented per-line protocol the single-line env uses) or through the node's batch topics
(:class:`BatchTransport`, two messages per round trip whatever the number of lines, for the vector
envs). Both offer a bank the same :class:`Transport` interface for matching, resetting and
stepping; what a step returns differs (each line's ``LineState``, or one batch of arrays).
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Protocol

import numpy as np
from rclpy.node import Node
from sorting_line_interfaces.msg import LineState

from ..line.topics import RESET
from .links import BatchLink, LineLink, ResetResult


class Transport(Protocol):
    """What a bank asks of the way it reaches its lines (``seeds``: line index -> seed or None)."""

    links: list[LineLink]

    def missing(self, node: Node) -> list[str]:
        """The node's endpoints not yet discovered, e.g. "/ns/line_3 reset service"."""
        ...

    def send_reset(self, seeds: dict[int, int | None]) -> None: ...

    def reset_done(self, seeds: dict[int, int | None]) -> bool: ...

    def awaited_reply(self, seeds: dict[int, int | None]) -> str:
        """The reset replies still awaited, for a timeout's message."""
        ...

    def finish_reset(self, seeds: dict[int, int | None]) -> dict[int, ResetResult]: ...

    def saw_first_states(self, seeds: dict[int, int | None]) -> bool:
        """Whether the step-0 state of each reset line arrived (the handshake's proof)."""
        ...

    def state_subscriptions(self) -> list:
        """The subscriptions a step waits on."""
        ...

    def send(self, speed_indices, modes) -> None:
        """Answers every line's current tick with (speed index, mode)."""
        ...

    def take_next_states(self) -> bool:
        """Takes what arrived; True once every line's next state is in."""
        ...

    def describe_wait(self) -> str: ...


class PerLineTransport:
    """Each line's ``reset`` service, command topics and ``state`` topic."""

    def __init__(self, node: Node, namespaces: list[str], advanced: bool):
        self.links = [LineLink(node, ns, advanced) for ns in namespaces]
        self._pending: set[int] = set()

    def missing(self, node: Node) -> list[str]:
        return [f"{link.namespace} {what}" for link in self.links for what, ok in link.matching(node).items() if not ok]

    def send_reset(self, seeds: dict[int, int | None]) -> None:
        for k, seed in seeds.items():
            self.links[k].send_reset(seed)

    def reset_done(self, seeds: dict[int, int | None]) -> bool:
        return all(self.links[k].reset_done() for k in seeds)

    def awaited_reply(self, seeds: dict[int, int | None]) -> str:
        return "the reply of " + ", ".join(
            f"{self.links[k].namespace}/{RESET}" for k in seeds if not self.links[k].reset_done()
        )

    def finish_reset(self, seeds: dict[int, int | None]) -> dict[int, ResetResult]:
        return {k: self.links[k].finish_reset() for k in seeds}

    def saw_first_states(self, seeds: dict[int, int | None]) -> bool:
        return all(self.links[k].saw_state_of_current_tick() for k in seeds)

    def state_subscriptions(self) -> list:
        return [link.state_sub for link in self.links]

    def send(self, speed_indices, modes) -> None:
        for link, speed, mode in zip(self.links, speed_indices, modes, strict=False):
            link.send_action(speed, mode)
        self._pending = set(range(len(self.links)))

    def take_next_states(self) -> bool:
        pending = self._pending
        for k in list(pending):
            link = self.links[k]
            if link.take_next_state():
                pending.discard(k)
                continue
            link.drain()
            if link.take_next_state():
                pending.discard(k)
        return not pending

    def describe_wait(self) -> str:
        return "; ".join(self.links[k].describe_wait() for k in sorted(self._pending))

    def states(self) -> list[LineState]:
        """Each line's newest state."""
        return [link.last_state for link in self.links]


class BatchTransport:
    """The node's ``batch/reset``, ``batch/cmd`` and ``batch/state``; the lines' own topics unused
    (their :class:`LineLink` keeps each line's position and creates no endpoints)."""

    def __init__(self, node: Node, namespace: str, namespaces: list[str], advanced: bool):
        self.links = [LineLink(node, ns, advanced, per_line_topics=False) for ns in namespaces]
        self.batch = BatchLink(node, namespace, self.links)
        self._namespace = namespace

    def missing(self, node: Node) -> list[str]:
        return [f"{self._namespace} {what}" for what, ok in self.batch.matching(node).items() if not ok]

    def send_reset(self, seeds: dict[int, int | None]) -> None:
        self.batch.send_reset(seeds)

    def reset_done(self, seeds: dict[int, int | None]) -> bool:
        return self.batch.reset_done()

    def awaited_reply(self, seeds: dict[int, int | None]) -> str:
        return f"the reply of {self.batch.reset_name}"

    def finish_reset(self, seeds: dict[int, int | None]) -> dict[int, ResetResult]:
        return self.batch.finish_reset(seeds)

    def saw_first_states(self, seeds: dict[int, int | None]) -> bool:
        return self.batch.saw_current_ticks()

    def state_subscriptions(self) -> list:
        return [self.batch.state_sub]

    def send(self, speed_indices: np.ndarray, modes: np.ndarray) -> None:
        self.batch.check_started()
        self.batch.send(speed_indices, modes)

    def take_next_states(self) -> bool:
        return self.batch.take_next_states()

    def describe_wait(self) -> str:
        return self.batch.describe_wait()

    def states(self) -> SimpleNamespace:
        """The newest batch: arrays, entry k = line k."""
        return self.batch.position
