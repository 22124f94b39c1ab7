"""What a user chooses about the line(s) an environment drives, as one checked, frozen object.

Each environment face (``SortingLineEnv``, ``SortingLineVectorEnv``, ``SortingLineSB3VecEnv``)
keeps its public keyword arguments (``gymnasium.make`` passes them; the README's tables
name them), turns them into a :class:`LineOptions` once, and hands that to its bank of lines: the
checks and the node's options are written here only. No ROS: constructing options starts nothing.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from .vocabulary import INPUTS, MAX_EPISODE_STEPS, SETUPS, THRESHOLD, check, check_setup, check_variant

#: How an environment reaches its node: ``spawn`` starts, owns and stops a node process in a
#: namespace of its own; ``shared`` leases a line of this host's line server; ``attach`` uses the
#: node serving ``namespace``.
NODE_MODES = ("spawn", "shared", "attach")

#: The line's settings an environment takes beside its setup, as the node's options of the same name,
#: with their ranges (low, high, whether high is allowed): src/sim/config.rs checks the same.
SETTING_RANGES = {"obs_noise": (0.0, 1.0, True), "action_penalty": (0.0, 10.0, True), "threshold": (0.0, 1.0, False)}


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
    #: The setup's input generator, sensor noise and switching penalty, unless given here.
    input: str | None = None
    obs_noise: float | None = None
    action_penalty: float | None = None
    #: An evolution schedule file the node runs the line by (``--evolution``), or None.
    evolution: str | None = None

    @classmethod
    def among(cls, arguments: dict[str, object], **overrides: object) -> LineOptions:
        """The options among an env constructor's ``arguments`` (its ``locals()``: the parameters of
        the same names as the fields), with ``overrides``; the others keep their defaults."""
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in arguments.items() if k in names and k not in overrides}, **overrides)

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
        if self.input is not None:
            check("input", self.input, INPUTS)
        for name, (low, high, high_allowed) in SETTING_RANGES.items():
            value = getattr(self, name)
            if value is not None and not (low <= value <= high and (high_allowed or value < high)):
                bound = "..=" if high_allowed else "..<"
                raise ValueError(f"{name} = {value!r} is out of range: allowed {low} {bound} {high}")

    @property
    def advanced(self) -> bool:
        return self.variant == "advanced"

    def node_options(self, lines: int) -> dict[str, Any]:
        """The options of a node serving ``lines`` lines with these settings (what
        ``NodeProcess`` turns into flags and the line server matches leases on)."""
        options = dict(SETUPS[self.setup], variant=self.variant, threshold=self.threshold, lines=lines)
        options.update({k: v for k in ("input", "obs_noise", "action_penalty") if (v := getattr(self, k)) is not None})
        options["max_steps"] = self.max_episode_steps if self.max_episode_steps is not None else MAX_EPISODE_STEPS
        if self.evolution is not None:
            options["evolution"] = self.evolution
        return options
