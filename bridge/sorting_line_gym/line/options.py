"""What a user chooses about the line(s) an environment drives, as one checked, frozen object.

Each environment face (``SortingLineEnv``, ``SortingLineVectorEnv``, ``SortingLineSB3VecEnv``,
``SortingLineEvolvingEnv``, and the native backend's through the Gymnasium ids) takes these
fields as its keyword arguments (``gymnasium.make`` passes them; ``envs/keywords.py`` checks them
and writes them into the constructors' signatures and docstrings), turns them into a
:class:`LineOptions` once, and hands that to its bank of lines: the names, defaults, meanings,
checks and the node's options are written here only. No ROS: constructing options starts nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .vocabulary import (
    BELOW_THRESHOLD_REWARD,
    INPUTS,
    MAX_EPISODE_STEPS,
    SETTING_RANGES,
    SETUPS,
    THRESHOLD,
    VARIANTS,
    check,
    check_setup,
    check_variant,
)

#: How an environment reaches its node: ``spawn`` starts, owns and stops a node process in a
#: namespace of its own; ``shared`` leases a line of this host's line server; ``attach`` uses the
#: node serving ``namespace``.
NODE_MODES = ("spawn", "shared", "attach")


def option(default: Any, meaning: str) -> Any:
    """A field of :class:`LineOptions`: its default and what it means (the env constructors'
    signatures and docstrings show both)."""
    return field(default=default, metadata={"meaning": meaning})


def _quoted(values: Any) -> str:
    """``"a", "b" or "c"``: a text option's allowed values as its meaning names them."""
    quoted = [f'"{v}"' for v in values]
    return f"{', '.join(quoted[:-1])} or {quoted[-1]}"


def _range(name: str) -> str:
    """``(0.0 ..= 1.0)``: a setting's range as the library checks it (``SETTING_RANGES``)."""
    low, high, high_allowed = SETTING_RANGES[name]
    return f"({low} {'..=' if high_allowed else '..<'} {high})"


@dataclass(frozen=True, kw_only=True)
class LineOptions:
    """The line's setup and variant, how the node is reached, its episode length and the
    bridge's timeouts (seconds). Invalid values raise ValueError naming the value and the allowed
    ones when the object is made. The env constructors take these fields as keyword arguments
    (``envs/keywords.py``): a field renamed here is renamed for all of them."""

    setup: str = option(
        "A",
        f'"{min(SETUPS)}".."{max(SETUPS)}", the paper\'s setups: the input generator, sensor noise and switching'
        " penalty",
    )
    variant: str = option("basic", f"{_quoted(VARIANTS)} (ratio sensor and sort modes; set by the Gymnasium id)")
    namespace: str | None = option(None, 'the node\'s namespace (needed with node="attach")')
    node: str = option(
        "spawn",
        '"spawn" (start, own and stop a node in a namespace of its own), "shared" (lease a line of this '
        'host\'s line server) or "attach" (use the node serving namespace)',
    )
    max_episode_steps: int | None = option(
        None, "the node truncates each episode after this many steps (None: it never does; a TimeLimit may)"
    )
    step_timeout: float = option(2.0, "seconds a step's round trip may take (the error names the topic and tick)")
    startup_timeout: float = option(20.0, "seconds the node may take to start or answer the first reset")
    threshold: float = option(
        THRESHOLD, f"the accuracy below which a batch is rewarded {BELOW_THRESHOLD_REWARD} {_range('threshold')}"
    )
    input: str | None = option(None, f"{_quoted(INPUTS)} instead of the setup's input generator")
    obs_noise: float | None = option(
        None, f"the input sensor's relative noise instead of the setup's {_range('obs_noise')}"
    )
    action_penalty: float | None = option(
        None, f"the switching penalty instead of the setup's {_range('action_penalty')}"
    )
    evolution: str | None = option(None, "an evolution schedule file the node runs the line by (--evolution)")
    foxglove: int | str | None = option(
        None,
        'serve the Foxglove live view of the node the env spawns on this port, or "ADDR:PORT" (node="spawn", '
        "backend='ros'; docs/foxglove.md)",
    )

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
        if self.foxglove is not None:
            if isinstance(self.foxglove, bool) or not isinstance(self.foxglove, (int, str)):
                raise ValueError(f"foxglove = {self.foxglove!r} is not valid: allowed a port or 'ADDR:PORT'")
            if self.node != "spawn":
                raise ValueError(
                    f"foxglove = {self.foxglove!r} with node = {self.node!r}: the live view is served by a node the "
                    "env spawns (node='spawn'); give a node you start yourself --foxglove instead"
                )
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
        if self.foxglove is not None:
            options["foxglove"] = str(self.foxglove)  # the node checks the port and address at start
        return options
