"""The sorting line's vocabulary in Python: its setups, variants, speeds and sort modes, the
numbers of a reset and an episode, the Gymnasium ids, the checks of a setup or variant name, and
the codec between Gymnasium's actions/observations/infos and the node's messages.

Every other Python module takes these facts from here; none imports ROS, so tools that never
talk to a node (plots, argument parsers, the agents' tables) can use them too. The Rust library
(src/sim) is the source of truth: ``sorting_line vocabulary`` prints its values, and
tests/python/test_vocabulary.py fails when the two sides differ.

The codec works on one line (a ``LineState`` message: Python scalars) and on N lines at once (a
decoded ``LineStates`` batch: numpy arrays, entry k = line k) with the same functions.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

# -- The line --------------------------------------------------------------------------------

#: Line variants: ``basic`` (speed only) and ``advanced`` (speed x sort mode, ratio sensor).
VARIANTS = ("basic", "advanced")

#: Input generators of the node's ``--input`` (src/sim/config.rs InputKind).
INPUTS = ("random", "seasonal", "seasonal3")

#: The paper's setups: input generator, relative sensor noise, switching penalty
#: (src/sim/config.rs ``LineConfig::for_setup``). Read-only: every module shares it.
SETUPS: Mapping[str, Mapping[str, Any]] = MappingProxyType(
    {
        "A": MappingProxyType({"input": "random", "obs_noise": 0.0, "action_penalty": 0.0}),
        "B": MappingProxyType({"input": "seasonal", "obs_noise": 0.0, "action_penalty": 0.5}),
        "C": MappingProxyType({"input": "random", "obs_noise": 0.3, "action_penalty": 0.0}),
        "D": MappingProxyType({"input": "seasonal", "obs_noise": 0.3, "action_penalty": 0.5}),
    }
)

#: The ten belt speeds; speed index i is speed ``SPEEDS[i]`` (the reference's literals, as
#: src/sim/speed.rs keeps them: ``0.1 * 3`` is not 0.3).
SPEEDS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
SPEED_COUNT = len(SPEEDS)
#: How far a speed may be from one of the ten and still count as it (``0.1 * 3`` means 0.3).
SPEED_TOLERANCE = 1e-6

#: Sort modes of the advanced line by name, with their wire values (``cmd/sort_mode``,
#: ``LineState.mode``).
MODES: Mapping[str, int] = MappingProxyType({"basic": 0, "positive": 1, "negative": 2})
MODE_COUNT = len(MODES)
#: Ratio categories of a batch (``sensors/ratio``, the advanced observation): the number of the
#: mode made for them.
CATEGORIES: Mapping[str, int] = MappingProxyType({"basic": 0, "positive": 1, "negative": 2})
#: The category code on the wire while an evolving line has no ratio sensor (before its sensor
#: upgrade), and the value its observation slot then holds: inside the advanced Box(0, 2), and no
#: category's value, so "no sensor" differs from "mixed batch" (src/sim/evolution.rs).
CATEGORY_UNKNOWN_CODE = 3
CATEGORY_UNKNOWN_OBSERVATION = 0.5
#: What each mode number is for, as the dashboard and reports label it.
MODE_LABELS: Mapping[int, str] = MappingProxyType({0: "basic", 1: "positive (A-rich)", 2: "negative (B-rich)"})

#: Speed index every reset starts the belt at (speed 0.6).
START_SPEED_INDEX = 5
START_SPEED = SPEEDS[START_SPEED_INDEX]

#: Accuracy below which a step earns a flat -0.1 (the node's ``--threshold`` default).
THRESHOLD = 0.7
#: Episode length of the paper and the node's ``--max-steps`` default.
EPISODE_STEPS = 50
#: Longest episode the node accepts (src/sim/config.rs MAX_EPISODE_STEPS).
MAX_EPISODE_STEPS = 1_000_000

#: Gymnasium id of each variant (registered in the package's ``__init__``; the keys of the
#: hyperparameter files).
ENV_IDS: Mapping[str, str] = MappingProxyType({"basic": "SortingLine-v0", "advanced": "SortingLineAdvanced-v0"})

#: Gymnasium actions per variant: the speed index, or speed index * MODE_COUNT + mode.
ACTION_COUNTS: Mapping[str, int] = MappingProxyType({"basic": SPEED_COUNT, "advanced": SPEED_COUNT * MODE_COUNT})


def speed_index_of(speed: float) -> int | None:
    """The index of one of the ten belt speeds, or None for anything else (NaN, out of
    0.1..1.0, between two speeds): src/sim/speed.rs ``index_of_speed``."""
    speed = float(speed)
    if not math.isfinite(speed):
        return None
    i = round(speed * 10) - 1
    return i if 0 <= i < SPEED_COUNT and abs(speed - SPEEDS[i]) <= SPEED_TOLERANCE else None


# -- Checks ----------------------------------------------------------------------------------


def check(name: str, value: Any, allowed: Iterable[Any]) -> Any:
    """``value`` if it is one of ``allowed``; otherwise a ValueError naming the argument, the
    value and the allowed values (``setup = 'E' is not valid: allowed A, B, C, D``)."""
    allowed = tuple(allowed)
    if value not in allowed:
        raise ValueError(f"{name} = {value!r} is not valid: allowed {', '.join(map(str, allowed))}")
    return value


def check_setup(setup: Any) -> str:
    return check("setup", setup, SETUPS)


def check_variant(variant: Any) -> str:
    return check("variant", variant, VARIANTS)


# -- Codec: Gymnasium <-> the node's messages -------------------------------------------------


def decode_actions(variant: str, actions) -> tuple[np.ndarray, np.ndarray]:
    """(speed indices, modes) of Gymnasium actions, as int64 arrays of the actions' shape (a
    single action gives 0-d arrays). The basic line's mode is always 0."""
    a = np.asarray(actions, dtype=np.int64)
    if variant == "advanced":
        return a // MODE_COUNT, a % MODE_COUNT
    return a, np.zeros_like(a)


def decode_action(variant: str, action) -> tuple[int, int]:
    """(speed index, mode) of one Gymnasium action, as Python ints."""
    speed_index, mode = decode_actions(variant, action)
    return int(speed_index), int(mode)


def encode_actions(variant: str, speed_index, mode):
    """The Gymnasium action(s) for (speed index, mode): the inverse of :func:`decode_actions`;
    Python ints in, a Python int out, arrays in, an array out."""
    return speed_index * MODE_COUNT + mode if variant == "advanced" else speed_index


def observations(variant: str, quantity, category) -> np.ndarray:
    """The observation(s) for the input sensor's reading(s) and ratio category(ies): shape
    ``(1,)``/``(2,)`` for one line, ``(N, 1)``/``(N, 2)`` for N (basic: the reading; advanced:
    reading, category), float32 as the observation space. An unknown category (no ratio sensor
    yet) reads :data:`CATEGORY_UNKNOWN_OBSERVATION`."""
    q = np.asarray(quantity, dtype=np.float32)
    if variant == "advanced":
        c = np.asarray(category, dtype=np.float32)
        c = np.where(c == CATEGORY_UNKNOWN_CODE, np.float32(CATEGORY_UNKNOWN_OBSERVATION), c).astype(np.float32)
        return np.stack([q, c], axis=-1)
    return q[..., None]


def action_mask(variant: str, sort_modes: bool = True) -> np.ndarray:
    """Which Gymnasium actions the line takes now, as ``action_masks()`` gives them (and what a
    deployed policy is masked with): all of them, but on an advanced line whose machine has no
    sort modes yet (an evolving line before its upgrade) only the ten with mode 0."""
    n = ACTION_COUNTS[check_variant(variant)]
    if variant == "basic" or sort_modes:
        return np.ones(n, dtype=bool)
    return np.arange(n) % MODE_COUNT == 0


def sim_seconds(sec, nanosec):
    """Simulated seconds of a stamp (or of arrays of stamps)."""
    return sec + nanosec * 1e-9


#: The info keys of a step, in order (docs/gymnasium.md lists them); ``containers`` is (a, a_false, b, b_false).
INFO_KEYS = (
    "accuracy",
    "purity",
    "recall_a",
    "recall_b",
    "speed",
    "speed_index",
    "mode",
    "occupancy",
    "containers",
    "speed_changes",
    "cumulative_reward",
    "step",
    "sim_time",
    "seed",
)


def state_info(state, sim_time) -> dict[str, Any]:
    """The KPIs of a state as a step's info, keys :data:`INFO_KEYS`.

    ``state`` is one line's ``LineState`` (Python scalars in, Python scalars out, containers a
    tuple) or a batch of N lines with one array per field (arrays out, entry k = line k,
    containers an (N, 4) array). ``sim_time`` is the simulated seconds since the episode's reset.
    Nothing here may depend on the node's history (its episode counter or absolute clock): the
    same seed and actions must give the same info, and the key ``episode`` belongs to
    episode-statistics wrappers (SB3's Monitor, Gymnasium's RecordEpisodeStatistics)."""
    batched = isinstance(state.accuracy, np.ndarray)
    as_int = (lambda v: v.astype(np.int64)) if batched else int
    containers = (state.container_a, state.container_a_false, state.container_b, state.container_b_false)
    return {
        "accuracy": state.accuracy,
        "purity": state.purity,
        "recall_a": state.recall_a,
        "recall_b": state.recall_b,
        "speed": state.speed,
        "speed_index": as_int(state.speed_index),
        "mode": as_int(state.mode),
        "occupancy": state.occupancy,
        "containers": np.stack(containers, axis=1) if batched else tuple(map(int, containers)),
        "speed_changes": as_int(state.speed_changes),
        "cumulative_reward": state.cumulative_reward,
        "step": as_int(state.step),
        "sim_time": sim_time,
        "seed": state.seed if batched else int(state.seed),
    }


def line_infos(info: Mapping[str, np.ndarray]) -> list[dict[str, Any]]:
    """Every line's entry of a batched info, as the single-line env reports it (Python scalars,
    containers as a tuple), converting each array once."""
    columns = {key: (list(map(tuple, v.tolist())) if key == "containers" else v.tolist()) for key, v in info.items()}
    keys = list(columns)
    return [dict(zip(keys, values, strict=False)) for values in zip(*columns.values(), strict=False)]
