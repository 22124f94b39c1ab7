"""The native backend (``backend="native"``): the line model of the Rust library in this process,
through the extension ``sorting_line_gym._native`` (the crate in native/), with no node, no ROS and
no DDS. A step is a function call instead of a round trip, and everything a user sees is the ROS
backend's: the same spaces, info keys and types, ``action_masks()``, seeding rules, autoreset and
trajectory (``Line::step`` is what the node runs; tests/python/test_native.py holds the two equal step
for step, tests/python/unit/test_native_backend.py the native one and ``sorting_line trace``).

- :class:`NativeLineEnv`: one line (``SortingLine-v0``, ``SortingLineAdvanced-v0`` and, with an
  evolution schedule, ``SortingLineEvolving-v0``); its step is one call into Rust, which builds the
  observation and the info dict.
- :class:`NativeLines`: N lines with the face of ``vector.Lines``, so the Gymnasium ``VectorEnv``
  and the SB3 ``VecEnv`` run on it unchanged; a step of all lines is one call with the GIL released,
  writing into arrays allocated once, and its info is built in Rust too.

Nothing here imports rclpy: the native backend works in a venv without the ROS wheels.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import sorting_line_gym._native as _native  # always built with the package (line.vocabulary says how, if not)

from ..line.errors import BridgeError
from ..line.options import LineOptions
from .env import SEED_BOUND, action_space, observation_space
from .seeding import SeededLines

#: The backends an environment runs on.
BACKENDS = ("ros", "native")


#: What the ROS backend needs beyond this package: the ROS 2 Python wheels and our interfaces.
ROS_MODULES = ("rclpy", "sorting_line_interfaces", "simulation_interfaces", "rosgraph_msgs", "std_msgs")


def ros_backend(make):
    """``make()`` of a ROS backend's env or lines; where the ROS 2 modules are missing (a venv with
    only the wheel of ``pip wheel ./bridge``), an ImportError naming what is missing and the way out."""
    try:
        return make()
    except ModuleNotFoundError as e:
        if (e.name or "").split(".")[0] not in ROS_MODULES:
            raise
        raise ImportError(
            f"backend='ros' needs the ROS 2 Python modules, and this environment lacks {e.name!r}: install "
            "rclpy and the interfaces as launch_scripts/setup.sh does (plus the sorting_line binary), or use "
            "backend='native', which runs the line in this process without ROS"
        ) from e


def line_settings(options: LineOptions) -> dict:
    """The keyword arguments of the extension's lines for ``options`` (the node's options, checked
    by the library as the node checks them)."""
    settings = options.node_options(lines=1)
    del settings["lines"]
    return settings


def check_native_options(options: LineOptions, render_mode: str | None = None) -> None:
    """Refuses what only the ROS backend has: a node to attach to or share, and the dashboard."""
    if options.node != "spawn" or options.namespace is not None:
        raise ValueError(
            f"node = {options.node!r}, namespace = {options.namespace!r}: the native backend runs the line in "
            "this process; node and namespace are the ROS backend's (backend='ros')"
        )
    if render_mode is not None:
        raise ValueError(f"render_mode = {render_mode!r}: the dashboard needs backend='ros' (its sensor topics)")
    if options.foxglove is not None:
        raise ValueError(f"foxglove = {options.foxglove!r}: the live view is the node's: it needs backend='ros'")


class NativeLineEnv(gym.Env):
    """One line in this process (see the module docstring; the ROS env's docstring describes the
    spaces, reward and info). ``evolution`` (a schedule file) makes it the evolving line."""

    metadata = {"render_modes": []}

    def __init__(self, options: LineOptions, render_mode: str | None = None):
        check_native_options(options, render_mode)
        self.variant = "advanced" if options.evolution else options.variant
        self.observation_space = observation_space(self.variant)
        self.action_space = action_space(self.variant)
        self.render_mode = None
        self.setup = options.setup
        self._line = _native.NativeLine(line_settings(options))
        self._evolving = options.evolution is not None
        self._closed = False

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._check_open()
        # As the ROS env: one seed reproduces a whole run; without one, the line's seed comes from np_random.
        line_seed = int(seed) if seed is not None else int(self.np_random.integers(0, SEED_BOUND))
        return self._line.reset(line_seed)

    def step(self, action):
        self._check_open()
        return self._line.step(action)

    def action_masks(self) -> np.ndarray:
        """Which actions are valid now (sb3-contrib's MaskablePPO reads this): all of them, but on
        the evolving line only mode 0 before its machine upgrade."""
        return self._line.action_mask()

    @property
    def settings(self) -> dict:
        """The evolving line's setup for the next step (after the events announced for it)."""
        if not self._evolving or self._line.episode == 0:
            raise RuntimeError("settings are known after the first reset() of the evolving line")
        return self._line.settings()

    def _check_open(self) -> None:
        if self._closed:
            raise BridgeError("the environment is closed (close() was called): make a new one to reset or step")

    def close(self):
        self._closed = True
        super().close()


class NativeLines(SeededLines):
    """N lines in this process with the face of ``vector.Lines`` (what the vector envs call)."""

    def __init__(self, num_envs: int, options: LineOptions):
        check_native_options(options)
        super().__init__(num_envs)
        self.variant = options.variant
        self._lines = _native.NativeLines(num_envs, line_settings(options))
        self._obs = self._lines.observations
        self._closed = False

    def reset(self, seeds: dict[int, int]) -> dict[int, np.ndarray]:
        self._check_open()
        indices = np.fromiter(seeds, dtype=np.int64, count=len(seeds))
        self._lines.reset(indices, np.fromiter(seeds.values(), dtype=np.uint64, count=len(seeds)))
        return {k: self._obs[k].copy() for k in seeds}

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        self._check_open()
        self._lines.step(checked_actions(actions, len(self.rngs)))
        # The info is the library's (native/src/info.rs: the single line's keys, one array each).
        return self._obs.copy(), self._lines.rewards(), self._lines.truncated.copy(), self._lines.info()

    def action_masks(self) -> np.ndarray:
        return self._lines.masks.copy()

    def _check_open(self) -> None:
        if self._closed:
            raise BridgeError("the environment is closed (close() was called): make a new one to reset or step")

    def close(self):
        self._closed = True


def checked_actions(actions, num_envs: int) -> np.ndarray:
    """A batch of Gymnasium actions as the extension takes them (int64, one per line); anything
    else (floats, NaN, a wrong shape) is a ValueError naming it."""
    a = np.asarray(actions)
    if a.dtype == np.int64 and a.shape == (num_envs,):
        return np.ascontiguousarray(a)
    if a.shape != (num_envs,):
        raise ValueError(f"actions of shape {a.shape}: allowed one action per line, shape ({num_envs},)")
    if a.dtype.kind not in "iub":
        raise ValueError(f"actions {a!r} of dtype {a.dtype}: allowed integers (Gymnasium's Discrete actions)")
    return a.astype(np.int64)
