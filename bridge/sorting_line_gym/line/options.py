"""What a user chooses about the line(s) an environment drives, as one checked, frozen object.

Each environment face (``SortingLineEnv``, ``SortingLineVectorEnv``, ``SortingLineSB3VecEnv``)
keeps its public keyword arguments (``gymnasium.make`` passes them; the README's tables
name them), turns them into a :class:`LineOptions` once, and hands that to its bank of lines: the
checks and the node's options are written here only. No ROS: constructing options starts nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .vocabulary import MAX_EPISODE_STEPS, SETUPS, THRESHOLD, check_setup, check_variant

#: How an environment reaches its node: ``spawn`` starts, owns and stops a node process in a
#: namespace of its own; ``shared`` leases a line of this host's line server; ``attach`` uses the
#: node serving ``namespace``.
NODE_MODES = ("spawn", "shared", "attach")


@dataclass(frozen=True, kw_only=True)
class LineOptions:
    """The line's setup and variant, how the node is reached, its episode length and the
    bridge's timeouts (seconds). Invalid values raise ValueError naming the value and the allowed
    ones when the object is made."""

    setup: str = "A"
    variant: str = "basic"
    namespace: str | None = None
    node: str = "spawn"
    #: None: the node never truncates (its longest episode); a TimeLimit wrapper does.
    max_episode_steps: int | None = None
    step_timeout: float = 2.0
    startup_timeout: float = 20.0
    threshold: float = THRESHOLD
    #: An evolution schedule file the node runs the line by (``--evolution``), or None.
    evolution: str | None = None

    def __post_init__(self) -> None:
        check_variant(self.variant)
        check_setup(self.setup)
        if self.node not in NODE_MODES:
            raise ValueError(
                f"node = {self.node!r} is not valid: allowed 'spawn' (start a node), 'shared' (lease a line of "
                "this host's line server) or 'attach'"
            )
        if self.step_timeout <= 0 or self.startup_timeout <= 0:
            raise ValueError("step_timeout and startup_timeout must be positive (seconds)")
        if self.node == "attach" and not self.namespace:
            raise ValueError("node='attach' needs the namespace of the running node")

    @property
    def advanced(self) -> bool:
        return self.variant == "advanced"

    def node_options(self, lines: int) -> dict[str, Any]:
        """The options of a node serving ``lines`` lines with these settings (what
        ``NodeProcess`` turns into flags and the line server matches leases on)."""
        options = dict(SETUPS[self.setup], variant=self.variant, threshold=self.threshold, lines=lines)
        options["max_steps"] = self.max_episode_steps if self.max_episode_steps is not None else MAX_EPISODE_STEPS
        if self.evolution is not None:
            options["evolution"] = self.evolution
        return options
