"""The Python vocabulary (sorting_line_gym.line.vocabulary) against the Rust library, the source of
truth, and its codec against itself: one line and N lines give the same answers.

No ROS: the Rust side speaks through ``sorting_line vocabulary`` (its own constants as JSON), so a
setup, speed or mode changed on one side only fails here.
"""

from __future__ import annotations

import json
import subprocess
from types import SimpleNamespace

import numpy as np
import pytest

from sorting_line_gym.line import vocabulary as v
from support import ros_harness as h


@pytest.fixture(scope="module")
def rust():
    r = subprocess.run([str(h.node_binary()), "vocabulary"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_setups_equal_the_rust_librarys(rust):
    assert {name: dict(s) for name, s in v.SETUPS.items()} == rust["setups"]
    assert list(v.SETUPS) == sorted(rust["setups"])


def test_speeds_modes_and_numbers_equal_the_rust_librarys(rust):
    assert v.SPEEDS == tuple(rust["speeds"])  # exact floats, not within a tolerance
    assert v.START_SPEED_INDEX == rust["start_speed_index"]
    assert dict(v.MODES) == rust["modes"]
    assert dict(v.CATEGORIES) == rust["categories"]
    assert v.VARIANTS == tuple(rust["variants"])
    assert v.INPUTS == tuple(rust["inputs"])
    assert v.THRESHOLD == rust["threshold"]
    assert (v.CATEGORY_UNKNOWN_CODE, v.CATEGORY_UNKNOWN_OBSERVATION) == (
        rust["category_unknown_code"],
        rust["category_unknown_observation"],
    )
    assert v.EPISODE_STEPS == rust["episode_steps"]
    assert v.MAX_EPISODE_STEPS == rust["max_episode_steps"]
    assert v.NODE_LINES == rust["node_lines"]
    assert set(v.MODE_LABELS) == set(v.MODES.values())


def test_the_harness_setup_flags_are_the_vocabularys():
    for name, setup in v.SETUPS.items():
        flags = h.SETUP_FLAGS[name]
        values = dict(zip(flags[::2], flags[1::2], strict=False))
        assert values == {
            "--input": setup["input"],
            "--obs-noise": str(setup["obs_noise"]),
            "--action-penalty": str(setup["action_penalty"]),
        }


def test_checks_name_the_argument_the_value_and_the_allowed_values():
    assert v.check_setup("C") == "C" and v.check_variant("advanced") == "advanced"
    with pytest.raises(ValueError, match=r"^setup = 'E' is not valid: allowed A, B, C, D$"):
        v.check_setup("E")
    with pytest.raises(ValueError, match=r"^variant = 'fancy' is not valid: allowed basic, advanced$"):
        v.check_variant("fancy")
    with pytest.raises(ValueError, match=r"^node = 'x' is not valid: allowed spawn, attach$"):
        v.check("node", "x", ("spawn", "attach"))


@pytest.mark.parametrize("variant", v.VARIANTS)
def test_actions_round_trip_one_at_a_time_and_batched(variant):
    actions = np.arange(v.ACTION_COUNTS[variant])
    speeds, modes = v.decode_actions(variant, actions)
    assert speeds.dtype == np.int64 and set(speeds) == set(range(v.SPEED_COUNT))
    assert set(modes) == (set(v.MODES.values()) if variant == "advanced" else {0})
    assert (v.encode_actions(variant, speeds, modes) == actions).all()
    for a in actions:
        pair = v.decode_action(variant, np.int64(a))
        assert pair == (int(speeds[a]), int(modes[a])) and all(type(x) is int for x in pair)
        assert v.encode_actions(variant, *pair) == a


@pytest.mark.parametrize("variant", v.VARIANTS)
def test_observations_of_one_line_are_rows_of_the_batch(variant):
    quantity, category = np.array([0.25, 0.5, 1.0]), np.array([0, 2, 1], dtype=np.uint8)
    batch = v.observations(variant, quantity, category)
    width = 2 if variant == "advanced" else 1
    assert batch.shape == (3, width) and batch.dtype == np.float32
    for k in range(3):
        one = v.observations(variant, float(quantity[k]), int(category[k]))
        assert one.shape == (width,) and one.dtype == np.float32
        np.testing.assert_array_equal(one, batch[k])


def test_the_info_of_one_line_is_its_entry_of_the_batched_info():
    fields = {
        "accuracy": [0.9, 0.65],
        "purity": [0.8, 0.7],
        "recall_a": [0.75, 0.5],
        "recall_b": [1.0, 0.25],
        "speed": [0.6, 0.1],
        "speed_index": [5, 0],
        "mode": [0, 2],
        "occupancy": [0.4, 0.9],
        "container_a": [10, 1],
        "container_a_false": [2, 3],
        "container_b": [7, 4],
        "container_b_false": [0, 5],
        "speed_changes": [1, 4],
        "cumulative_reward": [1.5, -0.2],
        "step": [3, 9],
        "seed": [2**63 + 5, 7],
    }
    kinds = {
        "speed_index": np.uint8,
        "mode": np.uint8,
        "speed_changes": np.uint32,
        "step": np.uint32,
        "seed": np.uint64,
        **{f: np.uint32 for f in fields if f.startswith("container")},
    }
    batch = SimpleNamespace(**{k: np.array(x, dtype=kinds.get(k, np.float64)) for k, x in fields.items()})
    sim_time = np.array([1.5, 4.5])
    batched = v.state_info(batch, sim_time)
    assert tuple(batched) == v.INFO_KEYS
    assert batched["containers"].shape == (2, 4) and batched["step"].dtype == np.int64
    lines = v.line_infos(batched)
    for k, line in enumerate(lines):
        one = v.state_info(SimpleNamespace(**{f: x[k] for f, x in fields.items()}), float(sim_time[k]))
        assert one == line
        assert type(one["containers"]) is tuple and type(one["seed"]) is int and type(one["step"]) is int


def test_speed_index_of_takes_the_ten_speeds_only():
    # The cases of src/sim/speed.rs's own tests: the Rust library accepts exactly these.
    for i, speed in enumerate(v.SPEEDS):
        assert v.speed_index_of(speed) == i
    assert v.speed_index_of(0.1 * 3) == 2
    for bad in (float("nan"), float("inf"), -0.1, 0.0, 0.05, 0.55, 1.1, 1.0001, 7.0):
        assert v.speed_index_of(bad) is None, bad
