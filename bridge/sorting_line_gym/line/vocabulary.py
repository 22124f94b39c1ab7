"""The sorting line's vocabulary in Python: its setups, variants, speeds and sort modes, the
numbers of a reset and an episode, the Gymnasium ids, the checks of a setup or variant name, and
the codec between Gymnasium's actions/observations/infos and the node's messages.

Every other Python module takes these facts from here; none imports ROS, so tools that never
talk to a node (plots, argument parsers, the agents' tables) can use them too. The Rust library
(src/sim) is the source of truth and this module states none of its facts again: the constants,
ranges, action counts, info keys, start contents and the observation and mask builders are the
extension's (``sorting_line_gym._native``, native/src/vocabulary.rs), re-exported here.
tests/python/unit/test_vocabulary.py holds them to ``sorting_line vocabulary`` (the CLI's own print
of them), tests/python/unit/test_line_facts.py what Python still states about the line to the library.

The codec works on one line (a ``LineState`` message: Python scalars) and on N lines at once (a
decoded ``LineStates`` batch: numpy arrays, entry k = line k) with the same functions.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

try:
    import sorting_line_gym._native as _native
except ImportError as e:  # every install builds it (setup.sh, `pip install ./bridge`, the wheel)
    raise ImportError(
        "sorting_line_gym needs its extension sorting_line_gym._native (the line's facts and model come from "
        "the Rust library), which this installation lacks: build it with launch_scripts/setup.sh, or install "
        "the wheel of `pip wheel ./bridge`"
    ) from e

# -- The line --------------------------------------------------------------------------------

#: Line variants: ``basic`` (speed only) and ``advanced`` (speed x sort mode, ratio sensor).
VARIANTS: tuple[str, ...] = _native.VARIANTS

#: Input generators of the node's ``--input`` (src/sim/config.rs InputKind).
INPUTS: tuple[str, ...] = _native.INPUTS

#: The paper's setups: input generator, relative sensor noise, switching penalty
#: (src/sim/config.rs ``LineConfig::for_setup``). Read-only: every module shares it.
SETUPS: Mapping[str, Mapping[str, Any]] = MappingProxyType(
    {name: MappingProxyType(dict(setup)) for name, setup in _native.SETUPS.items()}
)

#: The ten belt speeds; speed index i is speed ``SPEEDS[i]`` (the reference's literals, as
#: src/sim/speed.rs keeps them: ``0.1 * 3`` is not 0.3).
SPEEDS: tuple[float, ...] = _native.SPEEDS
SPEED_COUNT = len(SPEEDS)
#: How far a speed may be from one of the ten and still count as it (``0.1 * 3`` means 0.3).
SPEED_TOLERANCE: float = _native.SPEED_TOLERANCE

#: Sort modes of the advanced line by name, with their wire values (``cmd/sort_mode``,
#: ``LineState.mode``).
MODES: Mapping[str, int] = MappingProxyType(dict(_native.MODES))
MODE_COUNT: int = _native.MODE_COUNT
#: Ratio categories of a batch (``sensors/ratio``, the advanced observation): the number of the
#: mode made for them.
CATEGORIES: Mapping[str, int] = MappingProxyType(dict(_native.CATEGORIES))
#: The category code on the wire while an evolving line has no ratio sensor (before its sensor
#: upgrade), and the value its observation slot then holds: inside the advanced Box(0, 2), and no
#: category's value, so "no sensor" differs from "mixed batch" (src/sim/evolution.rs).
CATEGORY_UNKNOWN_CODE: int = _native.CATEGORY_UNKNOWN_CODE
CATEGORY_UNKNOWN_OBSERVATION: float = _native.CATEGORY_UNKNOWN_OBSERVATION
#: What each mode number is for, as the dashboard and reports label it (the node's scene too:
#: src/sim/material.rs ``SortMode::label``).
MODE_LABELS: Mapping[int, str] = MappingProxyType(dict(_native.MODE_LABELS))

#: Speed index every reset starts the belt at (speed 0.6).
START_SPEED_INDEX: int = _native.START_SPEED_INDEX
START_SPEED = SPEEDS[START_SPEED_INDEX]
#: What a reset puts on the line (src/sim/line.rs): (A, B) units in the input, on the belt and in
#: the sorting machine; the accuracy the first batches travel with and the belt's occupancy.
START_CONTENTS: Mapping[str, tuple[int, int]] = MappingProxyType(dict(_native.START_CONTENTS))
START_ACCURACY: float = _native.START_ACCURACY
START_OCCUPANCY: float = _native.START_OCCUPANCY

#: Accuracy below which a step earns a flat -0.1 (the node's ``--threshold`` default).
THRESHOLD: float = _native.THRESHOLD
#: The flat reward of a step below the threshold (src/sim/reward.rs BELOW_THRESHOLD_REWARD).
BELOW_THRESHOLD_REWARD: float = _native.BELOW_THRESHOLD_REWARD
#: Episode length of the paper and the node's ``--max-steps`` default.
EPISODE_STEPS: int = _native.EPISODE_STEPS
#: The paper's evaluation: EVAL_EPISODES episodes of EPISODE_STEPS steps, episode i from seed
#: ``EVAL_FIRST_SEED + i`` (``sorting_line eval``'s defaults; src/sim/config.rs).
EVAL_FIRST_SEED: int = _native.EVAL_FIRST_SEED
EVAL_EPISODES: int = _native.EVAL_EPISODES
#: Longest episode the node accepts (src/sim/config.rs MAX_EPISODE_STEPS).
MAX_EPISODE_STEPS: int = _native.MAX_EPISODE_STEPS
#: The most lines one node serves (``sorting_line node --lines``; src/sim/config.rs MAX_NODE_LINES).
NODE_LINES: int = _native.NODE_LINES

#: The line's settings an environment takes beside its setup, as the node's options of the same
#: name, with their ranges: name -> (low, high, whether high itself is allowed), as
#: src/sim/config.rs checks them.
SETTING_RANGES: Mapping[str, tuple[float, float, bool]] = MappingProxyType(dict(_native.SETTING_RANGES))

#: Gymnasium id of each variant (registered in the package's ``__init__``; the keys of the
#: hyperparameter files).
ENV_IDS: Mapping[str, str] = MappingProxyType({"basic": "SortingLine-v0", "advanced": "SortingLineAdvanced-v0"})

#: Gymnasium actions per variant: the speed index, or speed index * MODE_COUNT + mode.
ACTION_COUNTS: Mapping[str, int] = MappingProxyType(dict(_native.ACTION_COUNTS))


# -- Texts: the facts above as help texts, plot labels and reports name them ---------------------


def alternatives(values: Iterable[object]) -> str:
    """The values as a text names a choice among them: ``"A, B, C or D"``, ``"basic or advanced"``."""
    texts = [str(v) for v in values]
    return " or ".join([", ".join(texts[:-1]), texts[-1]] if len(texts) > 1 else texts)


#: The setups' span, ``"A..D"``.
SETUP_SPAN = f"{min(SETUPS)}..{max(SETUPS)}"
#: The variants as a choice, ``"basic or advanced"``.
VARIANT_CHOICE = alternatives(VARIANTS)
#: The paper's evaluation seeds, ``"42..51"``.
EVAL_SEEDS = f"{EVAL_FIRST_SEED}..{EVAL_FIRST_SEED + EVAL_EPISODES - 1}"


def speed_index_of(speed: float) -> int | None:
    """The index of one of the ten belt speeds, or None for anything else (NaN, out of
    0.1..1.0, between two speeds): src/sim/speed.rs ``index_of_speed``."""
    return _native.speed_index_of(float(speed))


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
    yet) reads :data:`CATEGORY_UNKNOWN_OBSERVATION`. Built by the library (the native lines'
    builder)."""
    return _native.observations(variant, quantity, category)


def action_mask(variant: str, sort_modes: bool = True) -> np.ndarray:
    """Which Gymnasium actions the line takes now, as ``action_masks()`` gives them (and what a
    deployed policy is masked with): all of them, but on an advanced line whose machine has no
    sort modes yet (an evolving line before its upgrade) only the ten with mode 0 (the library's
    mask rule)."""
    return _native.action_mask(check_variant(variant), bool(sort_modes))


def reward(accuracy, speed_index: int, threshold: float = THRESHOLD, penalty: float = 0.0) -> np.ndarray:
    """The step reward for accuracy value(s) in 0..1 at a speed index, float64 of the accuracies'
    shape: the library's (src/sim/reward.rs ``reward``), a flat -0.1 below ``threshold``, else the
    accuracy and speed terms minus ``penalty`` (what a change of speed costs). A value out of its
    range raises ValueError naming it and the range."""
    return _native.reward(accuracy, speed_index, threshold, penalty)


def sim_seconds(sec, nanosec):
    """Simulated seconds of a stamp (or of arrays of stamps)."""
    return sec + nanosec * 1e-9


#: The info keys of a step, in order (docs/gymnasium.md lists them); ``containers`` is (a, a_false, b, b_false).
INFO_KEYS: tuple[str, ...] = _native.INFO_KEYS
#: Each info key with the kind of its value (float, int, containers, seed, time) and the
#: ``LineState`` fields it is read from: what :func:`state_info` builds an info with.
INFO_FIELDS: tuple[tuple[str, str, tuple[str, ...]], ...] = _native.INFO_FIELDS


def state_info(state, sim_time) -> dict[str, Any]:
    """The KPIs of a state as a step's info, keys :data:`INFO_KEYS`, read by :data:`INFO_FIELDS`.

    ``state`` is one line's ``LineState`` (Python scalars in, Python scalars out, containers a
    tuple) or a batch of N lines with one array per field (arrays out, entry k = line k,
    containers an (N, 4) array). ``sim_time`` is the simulated seconds since the episode's reset.
    Nothing here may depend on the node's history (its episode counter or absolute clock): the
    same seed and actions must give the same info, and the key ``episode`` belongs to
    episode-statistics wrappers (SB3's Monitor, Gymnasium's RecordEpisodeStatistics)."""
    batched = isinstance(state.accuracy, np.ndarray)
    info: dict[str, Any] = {}
    for key, kind, fields in INFO_FIELDS:
        values = [getattr(state, f) for f in fields]
        if kind == "time":
            info[key] = sim_time
        elif kind == "containers":
            info[key] = np.stack(values, axis=1) if batched else tuple(map(int, values))
        elif kind == "int":
            info[key] = values[0].astype(np.int64) if batched else int(values[0])
        elif kind == "seed":  # a batch keeps uint64: seeds reach 2**64 - 1
            info[key] = values[0] if batched else int(values[0])
        else:
            info[key] = values[0]
    return info


def line_infos(info: Mapping[str, np.ndarray]) -> list[dict[str, Any]]:
    """Every line's entry of a batched info, as the single-line env reports it (Python scalars,
    containers as a tuple), converting each array once."""
    columns = {key: (list(map(tuple, v.tolist())) if key == "containers" else v.tolist()) for key, v in info.items()}
    keys = list(columns)
    return [dict(zip(keys, values, strict=False)) for values in zip(*columns.values(), strict=False)]
