"""What Python still states about the line, against the Rust library's own exports (the extension
``sorting_line_gym._native``, native/src/vocabulary.rs): the vocabulary re-exports them, and the few
places that say a line fact in Python's own words (a docstring, a range in a help text, the
decoding a policy card writes, the fields the ROS backend reads an info from) say what the
library says. No ROS, no node: well under a second.

tests/python/unit/test_vocabulary.py holds the same exports to the CLI's ``sorting_line vocabulary``.
"""

from __future__ import annotations

import csv
import io
import math
import re
import subprocess
from dataclasses import fields
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from sorting_line_gym import _native
from sorting_line_gym.agents import policies
from sorting_line_gym.envs import env as env_module
from sorting_line_gym.envs import evolving as evolving_module
from sorting_line_gym.line import vocabulary as v
from sorting_line_gym.line.options import LineOptions
from sorting_line_gym.line.policy_card import action_decoding
from sorting_line_gym.reports import plots
from sorting_line_gym.reports import results_csv as results_csv_module
from sorting_line_gym.reports.benchmark_summary import HELDOUT_EPISODES, HELDOUT_SEED
from sorting_line_gym.studies import benchmark as benchmark_module
from sorting_line_gym.studies import curves as curves_module
from sorting_line_gym.studies import engine_check as engine_check_module
from sorting_line_gym.studies import evaluate as evaluate_module
from sorting_line_gym.training import hyperparams as hyperparams_module
from sorting_line_gym.training import trained_agent
from support import ros_harness as h

ROOT = Path(__file__).resolve().parents[3]

#: Each re-export of the vocabulary, by the name the extension gives it.
REEXPORTED = (
    "VARIANTS",
    "INPUTS",
    "SPEEDS",
    "SPEED_TOLERANCE",
    "MODE_COUNT",
    "CATEGORY_UNKNOWN_CODE",
    "CATEGORY_UNKNOWN_OBSERVATION",
    "START_SPEED_INDEX",
    "START_ACCURACY",
    "START_OCCUPANCY",
    "THRESHOLD",
    "BELOW_THRESHOLD_REWARD",
    "EPISODE_STEPS",
    "MAX_EPISODE_STEPS",
    "EVAL_FIRST_SEED",
    "EVAL_EPISODES",
    "NODE_LINES",
    "INFO_KEYS",
    "INFO_FIELDS",
)
#: The read-only mappings among them.
REEXPORTED_MAPPINGS = (
    "SETUPS",
    "MODES",
    "MODE_LABELS",
    "CATEGORIES",
    "ACTION_COUNTS",
    "SETTING_RANGES",
    "START_CONTENTS",
)


@pytest.mark.parametrize("name", REEXPORTED)
def test_the_vocabulary_re_exports_the_library(name):
    assert getattr(v, name) == getattr(_native, name)


@pytest.mark.parametrize("name", REEXPORTED_MAPPINGS)
def test_the_vocabularys_mappings_are_the_librarys_read_only(name):
    mine = getattr(v, name)
    assert {k: dict(x) if name == "SETUPS" else x for k, x in mine.items()} == getattr(_native, name)
    with pytest.raises(TypeError):
        mine["new"] = None  # shared by every module: nobody may change it


def test_what_python_derives_follows_from_the_library():
    assert v.SPEED_COUNT == len(v.SPEEDS) and v.START_SPEED == v.SPEEDS[v.START_SPEED_INDEX]
    assert set(v.MODE_LABELS) == set(v.MODES.values()) == set(v.CATEGORIES.values())
    assert all(v.MODE_LABELS[number].startswith(name) for name, number in v.MODES.items())
    assert v.ACTION_COUNTS == {"basic": v.SPEED_COUNT, "advanced": v.SPEED_COUNT * v.MODE_COUNT}
    assert set(v.ENV_IDS) == set(v.VARIANTS)
    assert v.INFO_KEYS == tuple(key for key, _, _ in v.INFO_FIELDS)
    assert policies.LEVELS == 101 and policies.level is _native.level


@pytest.mark.parametrize("variant", v.VARIANTS)
def test_the_codec_decodes_as_the_library_masks(variant):
    actions = np.arange(v.ACTION_COUNTS[variant])
    speeds, modes = v.decode_actions(variant, actions)
    # The library's mask without sort modes keeps exactly the actions of mode 0.
    np.testing.assert_array_equal(v.action_mask(variant, sort_modes=False), modes == 0)
    assert v.action_mask(variant).all() and v.action_mask(variant).shape == actions.shape
    # A policy card tells other languages how to decode (line/policy_card.py): the same decoding.
    text = action_decoding(variant)
    assert text["n"] == len(actions) and text["speeds"] == list(v.SPEEDS)
    if variant == "advanced":
        rules = {name: compile(text[name], name, "eval") for name in ("speed_index", "mode")}
        assert [eval(rules["speed_index"], {"action": int(a)}) for a in actions] == speeds.tolist()
        assert [eval(rules["mode"], {"action": int(a)}) for a in actions] == modes.tolist()
        assert text["modes"] == dict(v.MODES)
    else:
        assert text["speed_index"] == "action" and (modes == 0).all()


def test_observations_are_the_librarys_for_one_line_and_a_batch():
    one = v.observations("advanced", 0.25, v.CATEGORY_UNKNOWN_CODE)
    assert one.dtype == np.float32 and one.tolist() == [0.25, v.CATEGORY_UNKNOWN_OBSERVATION]
    batch = v.observations("advanced", np.array([0.5, 1.0]), np.array([2, 0], dtype=np.uint8))
    assert batch.shape == (2, 2) and batch.tolist() == [[0.5, 2.0], [1.0, 0.0]]
    assert v.observations("basic", np.float64(0.3), 9).tolist() == [np.float32(0.3)]
    with pytest.raises(ValueError, match="'fancy' is not a valid Variant: allowed basic, advanced"):
        v.observations("fancy", 0.5, 0)


def test_the_info_fields_are_line_state_fields_of_the_message():
    text = (ROOT / "msg" / "msg" / "LineState.msg").read_text()
    message = {m.group(2): m.group(1) for m in re.finditer(r"^(\w+)\s+(\w+)", text, re.M)}
    for key, kind, names in v.INFO_FIELDS:
        assert kind in {"float", "int", "containers", "seed", "time"}, key
        assert (kind == "time") == (not names), key
        for name in names:
            assert name in message, f"info key {key!r} reads LineState.{name}, which the message lacks"
        assert kind != "float" or message[names[0]] == "float64", key


def test_the_ros_backends_info_and_the_native_lines_agree():
    """state_info (the ROS backend's, fed by INFO_FIELDS) on a state holding the native line's
    values gives the native line's info, key for key and type for type."""
    line = _native.NativeLine(dict(v.SETUPS["D"], variant="advanced", threshold=v.THRESHOLD, max_steps=v.EPISODE_STEPS))
    line.reset(7)
    for action in (4, 17, 29):
        info = line.step(action)[4]
    state = {}
    for key, _, names in v.INFO_FIELDS:
        values = info[key] if len(names) > 1 else (info[key],) * len(names)
        state.update(zip(names, values, strict=True))
    mine = v.state_info(SimpleNamespace(**state), info["sim_time"])
    assert list(mine) == list(info) and mine == info
    assert all(type(mine[k]) is type(info[k]) for k in info), {k: type(x) for k, x in info.items()}


def test_the_setting_ranges_are_the_librarys_checks():
    """LineOptions accepts a setting exactly where the library's line does, at both ends."""
    base = dict(v.SETUPS["A"], variant="basic", threshold=v.THRESHOLD, max_steps=v.EPISODE_STEPS)
    for name, (low, high, high_allowed) in v.SETTING_RANGES.items():
        for value in (low, math.nextafter(low, -math.inf), high, math.nextafter(high, math.inf)):
            try:
                _native.NativeLine({**base, name: value})
                library = True
            except ValueError:
                library = False
            try:
                LineOptions(**{name: value})
                python = True
            except ValueError:
                python = False
            assert python == library, f"{name} = {value!r}: LineOptions says {python}, the library {library}"
        assert high_allowed == (name != "threshold")
        meaning = next(f.metadata["meaning"] for f in fields(LineOptions) if f.name == name)
        assert f"({low} {'..=' if high_allowed else '..<'} {high})" in meaning, meaning


def test_the_env_docstring_says_the_librarys_line():
    doc = env_module.__doc__
    contents = v.START_CONTENTS
    start = ", ".join(f"{place} {a}/{b}" for place, (a, b) in contents.items())
    assert f"Fixed line contents ({start}, speed {v.START_SPEED})" in doc
    for variant, env_id in v.ENV_IDS.items():
        assert f"`{env_id}`: `Discrete({v.ACTION_COUNTS[variant]})`" in doc
    assert f"below the threshold ({v.THRESHOLD})" in doc and f"TimeLimit\nof {v.EPISODE_STEPS} steps" in doc
    listed = re.sub(r"\(.*?\)", "", doc.split("## Info\n", 1)[1], flags=re.S)  # without the explanations
    assert tuple(k.strip().rstrip(".") for k in listed.split(",")) == v.INFO_KEYS


def _prose(doc: str | None) -> str:
    """A docstring with its line breaks and indentation as single spaces."""
    assert doc
    return " ".join(doc.split())


def _training_episode_steps() -> int:
    """The training episode length of the packaged hyperparameters: one for every algorithm and line."""
    hyperparams = ROOT / "bridge" / "sorting_line_gym" / "training" / "hyperparams"
    entries = [entry for path in hyperparams.glob("*.yml") for entry in yaml.safe_load(path.read_text()).values()]
    lengths = {entry["episode_steps"] for entry in entries}
    assert len(entries) >= 6 and len(lengths) == 1, lengths
    return lengths.pop()


def _setups_where(key: str) -> str:
    return ", ".join(name for name, setup in v.SETUPS.items() if setup[key])


@pytest.mark.parametrize("module", [env_module, evolving_module], ids=["env", "evolving"])
def test_the_env_docstrings_actions_are_the_librarys(module):
    """The action encoding and the modes' labels the docstrings state, evaluated: the codec's."""
    doc = _prose(module.__doc__)
    assert f"`Discrete({v.ACTION_COUNTS['advanced']})`" in doc
    rule = re.search(r"`(speed_index \* \d+ \+ mode)`", doc)
    assert rule, doc
    for speed_index in range(v.SPEED_COUNT):
        for mode in v.MODES.values():
            action = eval(rule.group(1), {"speed_index": speed_index, "mode": mode})
            assert action == v.encode_actions("advanced", speed_index, mode), rule.group(1)
    labels = ", ".join(f"{number} {label}" for number, label in sorted(v.MODE_LABELS.items()))
    assert f"mode {labels}" in doc


def test_the_env_docstrings_spaces_and_reward_are_the_librarys():
    """The numbers of env.py's docstring beyond its start contents, episode and info (above): the
    speed of an index, the observation spaces, the setups with noise and a penalty, and the reward
    formula, evaluated on a grid against the library's reward; and the training episode length
    against the packaged hyperparameters."""
    doc = _prose(env_module.__doc__)
    speed = re.search(r"the belt speed index i \(speed (.+?)\)\.", doc)
    assert speed, doc
    speeds = [eval(speed.group(1), {"i": i}) for i in range(v.SPEED_COUNT)]
    assert [v.speed_index_of(s) for s in speeds] == list(range(v.SPEED_COUNT))
    for variant in v.VARIANTS:
        box = env_module.observation_space(variant)
        stated = f"`Box({box.low.min():g}, {box.high.max():g}, {box.shape}, {box.dtype})`"
        assert f"{variant}: {stated}" in doc
    assert f"ratio category ({', '.join(map(str, sorted(v.CATEGORIES.values())))})" in doc
    assert f"relative noise in setups {_setups_where('obs_noise')};" in doc
    penalties = {s["action_penalty"] for s in v.SETUPS.values() if s["action_penalty"]}
    assert len(penalties) == 1 and f"the penalty ({penalties.pop()} in setups {_setups_where('action_penalty')})" in doc
    below = re.search(r"below the threshold \(([\d.]+)\): (-?[\d.]+)\. Otherwise (.+?), where", doc)
    assert below, doc
    assert float(below.group(1)) == v.THRESHOLD and float(below.group(2)) == v.BELOW_THRESHOLD_REWARD
    formula = below.group(3)
    for speed_index, speed_value in enumerate(v.SPEEDS):
        for penalty in (0.0, 0.5):
            for accuracy in np.linspace(v.THRESHOLD, 1.0, 7):
                stated = eval(formula, {"accuracy": accuracy, "speed": speed_value, "penalty": penalty})
                assert math.isclose(stated, v.reward(accuracy, speed_index, penalty=penalty), abs_tol=1e-12), formula
            assert v.reward(math.nextafter(v.THRESHOLD, 0), speed_index, penalty=penalty) == v.BELOW_THRESHOLD_REWARD
    training = re.search(r"`max_episode_steps=(\d+)` for training", doc)
    assert training and int(training.group(1)) == _training_episode_steps(), doc


def test_the_evolving_docstring_says_the_librarys_mask_and_unknown_category():
    doc = _prose(evolving_module.__doc__)
    mode0 = int(v.action_mask("advanced", sort_modes=False).sum())
    assert mode0 == v.SPEED_COUNT and "allows the ten actions with mode 0" in doc
    assert f"reads **{v.CATEGORY_UNKNOWN_OBSERVATION}**" in doc


@pytest.mark.parametrize(
    ("module", "stated"),
    [
        (evaluate_module, [f"seed {v.EVAL_FIRST_SEED} + i ({v.EVAL_EPISODES} episodes, {v.EPISODE_STEPS} steps each)"]),
        (
            benchmark_module,
            [
                f"``sorting-line-eval``'s protocol ({v.EPISODE_STEPS} steps, deterministic)",
                f"the paper's {v.EVAL_EPISODES} seeds {v.EVAL_SEEDS}",
                f"``--heldout-episodes`` ({HELDOUT_EPISODES}) held-out seeds from ``--heldout-seed`` ({HELDOUT_SEED})",
                f"every setup ({min(v.SETUPS)}-{max(v.SETUPS)}) and variant ({', '.join(v.VARIANTS)})",
            ],
        ),
        (curves_module, [f"seed ``seed + i`` for episode i, {v.EPISODE_STEPS} steps"]),
        (
            results_csv_module,
            [
                f"the held-out seeds, {HELDOUT_SEED}..{HELDOUT_SEED + HELDOUT_EPISODES - 1} by default",
                f"summed reward ({v.EPISODE_STEPS} steps, deterministic policy",
            ],
        ),
        (
            engine_check_module,
            [
                f"scored on {HELDOUT_EPISODES} held-out seeds (from {HELDOUT_SEED})",
                f"training seeds {engine_check_module.DEFAULT_SEEDS[0]}..{engine_check_module.DEFAULT_SEEDS[-1]}",
            ],
        ),
    ],
    ids=["evaluate", "benchmark", "curves", "results_csv", "engine_check"],
)
def test_the_studies_docstrings_say_the_protocol(module, stated):
    """The episode length and the seeds the studies' docstrings state are the ones they run."""
    doc = _prose(module.__doc__)
    for text in stated:
        assert text in doc, text


def test_make_agents_docstring_says_the_ranges():
    doc = _prose(trained_agent.make_agent.__doc__)
    assert f"(K = 0..{v.SPEED_COUNT - 1}, M = 0..{v.MODE_COUNT - 1})" in doc


def test_the_agents_and_hyperparameters_docstrings_say_the_librarys_line():
    """policies.py's and hyperparams.py's numbers: the action encoding, the categories, the start
    speed, the decision tables' cells, the constant and random agents' ranges, the episode lengths."""
    doc = _prose(policies.__doc__)
    assert f"advanced: speed index * {v.MODE_COUNT} + mode" in doc
    assert all(f"{number} {name}" in doc for name, number in v.CATEGORIES.items())
    assert f":data:`START_SPEED_INDEX` (speed {v.START_SPEED})" in doc
    table = policies.load_policy("A", "advanced")
    assert len(table["rba"]) == len(table["rba_hold"]) == table["levels"] * len(v.CATEGORIES)
    assert all(len(cell) == v.SPEED_COUNT for cell in table["rba_hold"])
    doc = _prose(policies.load_policy.__doc__)
    assert f"``level * {len(v.CATEGORIES)} + category``" in doc and f"current speed 0..{v.SPEED_COUNT - 1}" in doc
    assert f"mode ``mode`` (0..{v.MODE_COUNT - 1})" in _prose(policies.ConstantAgent.__doc__)
    assert f"({v.SPEED_COUNT} speeds; x {v.MODE_COUNT} modes on the advanced line)" in _prose(
        policies.RandomAgent.__doc__
    )
    stated = f"the paper trains on {_training_episode_steps()}, evaluates on {v.EPISODE_STEPS}"
    assert stated in _prose(hyperparams_module.__doc__)


def test_the_dashboard_starts_with_the_librarys_contents():
    history = env_module._History
    assert (history.START_INPUT, history.START_BELT, history.START_MACHINE) == tuple(v.START_CONTENTS.values())
    assert v.START_OCCUPANCY == sum(v.START_CONTENTS["belt"]) / 100


@pytest.mark.parametrize("variant", v.VARIANTS)
def test_the_plots_table_is_the_clis(variant):
    """reports.plots reads ``sorting_line table`` in-process: the same rows, text for text."""
    argv = [str(h.node_binary()), "table", "--variant", variant]
    r = subprocess.run(argv, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert plots.read_table(variant) == list(csv.DictReader(io.StringIO(r.stdout)))
    with pytest.raises(ValueError, match="threshold = 1 is out of range: allowed 0.0 ..< 1.0"):
        _native.table(variant, 1.0)
    with pytest.raises(ValueError, match="variant = 'fancy' is not valid: allowed basic, advanced"):
        plots.read_table("fancy")


@pytest.mark.parametrize("variant", v.VARIANTS)
def test_the_plots_reward_is_the_tables_where_the_accuracy_is_sure(variant):
    """Where the table's accuracy clears the threshold for sure (or surely not), its expected
    reward is the step reward of its expected accuracy: reward_of (the library's reward) gives it,
    to the table's six decimals."""
    rows = plots.read_table(variant)
    sure = [r for r in rows if r["p_above_threshold"] in ("1.000000", "0.000000")]
    assert {r["p_above_threshold"] for r in sure} == {"1.000000", "0.000000"}
    assert len({r["speed"] for r in sure}) == v.SPEED_COUNT
    accuracy = np.array([float(r["expected_accuracy"]) for r in sure])
    got = np.array([plots.reward_of(a, float(r["speed"])) for a, r in zip(accuracy, sure, strict=True)])
    expected = np.array([float(r["expected_reward"]) for r in sure])
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-6)


def test_the_reward_checks_its_inputs():
    np.testing.assert_array_equal(v.reward([0.69, 0.7, 1.0], 9), [-0.1, 0.5, 1.0])
    assert v.reward(0.85, 4, penalty=0.5).shape == () and v.reward(np.zeros((2, 3)), 0).shape == (2, 3)
    assert plots.reward_of(np.array([1.0]), v.SPEEDS[-1]).tolist() == [1.0]
    for call, message in [
        (lambda: v.reward(0.8, 10), "speed_index = 10 is out of range: allowed 0 ..= 9"),
        (lambda: v.reward(0.8, -1), "speed_index = -1 is out of range: allowed 0 ..= 9"),
        (lambda: v.reward([0.8, 1.5], 0), "accuracy = 1.5 is out of range: allowed 0.0 ..= 1.0"),
        (lambda: v.reward(math.nan, 0), "accuracy = NaN is out of range: allowed 0.0 ..= 1.0"),
        (lambda: v.reward(0.8, 0, threshold=1.0), "threshold = 1 is out of range: allowed 0.0 ..< 1.0"),
        (lambda: v.reward(0.8, 0, penalty=-0.5), r"action_penalty = -0.5 is out of range: allowed 0.0 ..= 10.0"),
        (lambda: plots.reward_of(np.array([0.8]), 0.55), "speed = 0.55 is not a belt speed: allowed 0.1, 0.2,"),
    ]:
        with pytest.raises(ValueError, match=re.escape(message)):
            call()


def test_the_native_agent_names_the_librarys_ranges():
    settings = dict(v.SETUPS["A"], variant="advanced", threshold=v.THRESHOLD, max_steps=v.EPISODE_STEPS)
    agent = _native.Agent("rba", settings)
    assert 0 <= agent.act(0.5, 2, v.SPEED_COUNT - 1) < v.ACTION_COUNTS["advanced"]
    codes = ", ".join(map(str, sorted(v.CATEGORIES.values())))
    with pytest.raises(ValueError, match=re.escape(f"category = 3 is out of range: allowed {codes}")):
        agent.act(0.5, 3, 0)
    last = v.SPEED_COUNT - 1
    with pytest.raises(ValueError, match=re.escape(f"current_speed_index = 10 is out of range: allowed 0 ..= {last}")):
        agent.act(0.5, 0, v.SPEED_COUNT)
