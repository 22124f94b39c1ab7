"""Training hyperparameters: the paper's defaults, kept in RL Zoo style YAML files.

``hyperparams/<algo>.yml`` (shipped with the package) holds one entry per Gymnasium id, as RL Zoo
does; ``--hyperparams FILE`` replaces it with a file of the same shape and ``--hp key=value``
overrides single keys (the value is read as YAML: ``--hp gamma=0.9 --hp policy_kwargs="{net_arch:
[32, 32]}"``). Four keys are ours, not the algorithm's:

- ``n_timesteps``: training budget in environment steps;
- ``policy``: SB3 policy name (``MlpPolicy``);
- ``n_envs``: lines trained on at once (1: one env; N > 1: N lines of one node, one round trip each);
- ``episode_steps``: length of a training episode (the paper trains on 250, evaluates on 50).

Everything else is handed to the algorithm's constructor; ``load`` refuses, by name, a key the
constructor does not take.

Several lines (``n_envs`` = N > 1) change what one update sees unless the rollout keys follow, so
``load`` maps the paper's one-line settings to N lines (:func:`for_lines`), for each algorithm's
rollout keys the file and the overrides leave at SB3's default, by one of two named mappings
(:data:`MAPPINGS`). Both keep the minibatch size and, for PPO and DQN, the gradient steps per
transition (:func:`gradient_steps_per_transition`); they differ in what one update sees:

- ``same-rollout`` (the default): each update sees as many transitions as on one line. PPO keeps
  its 2048-step rollout as N x ``n_steps`` (same samples, minibatches and epochs per update); DQN
  keeps one gradient step per 4 transitions (``train_freq`` counts vector steps of N transitions,
  so ``train_freq`` x N / 4 gradient steps; ``target_update_interval`` SB3 already divides by N);
  A2C keeps its update as close to 5 transitions as N allows (``n_steps`` = max(1, 5 // N): from 5
  lines on, N transitions and 1-step returns per update). Each line then contributes a short
  stretch of experience to an update (256 steps of PPO on 8 lines, about one training episode).
- ``same-line-rollout``: each line's stretch per update stays the one-line rollout. PPO collects
  N x 2048 steps per update (its epochs over 64-sample minibatches unchanged: the same gradient
  steps per transition, N times fewer policy refreshes); DQN trains every 4 vector steps (4 N
  transitions) with N gradient steps; A2C updates on N x 5 transitions (one gradient step per
  update, as on one line: N times fewer, larger updates).

N must be a power of two (up to 2048) so these are whole numbers.
"""

from __future__ import annotations

import importlib.resources
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import yaml

from ..line.vocabulary import ENV_IDS, check_variant  # ENV_IDS: the keys of the hyperparameter files

#: The algorithms sorting-line-train knows, by their command-line name.
ALGOS = ("ppo", "dqn", "a2c")
#: Keys of a hyperparameter entry that are not constructor arguments of the algorithm.
OWN_KEYS = ("n_timesteps", "policy", "n_envs", "episode_steps")
#: SB3's defaults of the keys that set how much one update sees, for one line (the paper's).
ONE_LINE_ROLLOUT = {"ppo": {"n_steps": 2048}, "dqn": {"train_freq": 4, "gradient_steps": 1}, "a2c": {"n_steps": 5}}
#: The named one-line to N-line mappings (module docstring), the default first.
MAPPINGS = ("same-rollout", "same-line-rollout")
DEFAULT_MAPPING = MAPPINGS[0]


def algorithm_class(algo: str):
    """The Stable-Baselines3 class of ``algo`` (imported on demand: SB3 is heavy)."""
    import stable_baselines3

    check_algo(algo)
    return getattr(stable_baselines3, algo.upper())


def check_algo(algo: str) -> str:
    if algo not in ALGOS:
        raise ValueError(f"algorithm {algo!r} is not valid: allowed {', '.join(ALGOS)}")
    return algo


def parse_override(text: str) -> tuple[str, Any]:
    """``key=value`` with the value read as YAML (numbers, lists, dicts, strings)."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ValueError(f"hyperparameter override {text!r} is not valid: expected key=value")
    try:
        return key.strip(), yaml.safe_load(value)
    except yaml.YAMLError as e:
        raise ValueError(f"hyperparameter override {text!r}: the value is not valid YAML ({e})") from None


def load(
    algo: str,
    variant: str,
    path: str | Path | None = None,
    overrides: Iterable[str] = (),
    mapping: str = DEFAULT_MAPPING,
) -> dict[str, Any]:
    """The hyperparameters of ``algo`` for the line ``variant``: the entry for its Gymnasium id in
    ``path`` (default: the packaged file), then ``overrides`` applied, then mapped to ``n_envs``
    lines by ``mapping``."""
    check_algo(algo)
    env_id = ENV_IDS[check_variant(variant)]
    if path is None:
        source = f"sorting_line_gym/hyperparams/{algo}.yml"
        text = importlib.resources.files(__package__).joinpath("hyperparams", f"{algo}.yml").read_text()
    else:
        source = str(path)
        try:
            text = Path(path).read_text()
        except OSError as e:
            raise ValueError(f"hyperparameter file {source}: cannot read it ({e.strerror})") from None
    try:
        entries = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ValueError(f"hyperparameter file {source} is not valid YAML: {e}") from None
    if not isinstance(entries, dict) or env_id not in entries or not isinstance(entries[env_id], dict):
        found = ", ".join(map(str, entries)) if isinstance(entries, dict) else "nothing"
        raise ValueError(f"hyperparameter file {source} has no entry for {env_id} (it has: {found})")
    params = dict(entries[env_id])
    overridden = set()
    for text_ in overrides:
        key, value = parse_override(text_)
        params[key] = value
        overridden.add(key)
    _check_own_keys(params, source)
    _check_constructor_keys(algo, params, lambda key: "an override" if key in overridden else source)
    return for_lines(algo, params, mapping)


def check_mapping(mapping: str) -> str:
    if mapping not in MAPPINGS:
        raise ValueError(f"lines mapping {mapping!r} is not valid: allowed {', '.join(MAPPINGS)}")
    return mapping


def mapped_rollout(algo: str, n: int, mapping: str = DEFAULT_MAPPING) -> dict[str, int]:
    """The rollout keys of ``algo`` on ``n`` lines under ``mapping`` (the arithmetic of the module
    docstring), from the one-line values in :data:`ONE_LINE_ROLLOUT`."""
    one = ONE_LINE_ROLLOUT[check_algo(algo)]
    if check_mapping(mapping) == "same-line-rollout":
        if algo == "dqn":
            return {"train_freq": one["train_freq"], "gradient_steps": one["gradient_steps"] * n}
        return dict(one)
    if algo == "ppo":
        return {"n_steps": one["n_steps"] // n}
    if algo == "a2c":
        return {"n_steps": max(1, one["n_steps"] // n)}
    per_gradient_step = one["train_freq"] // one["gradient_steps"]
    train_freq = max(1, per_gradient_step // n)
    return {"train_freq": train_freq, "gradient_steps": train_freq * n // per_gradient_step}


def for_lines(algo: str, params: dict[str, Any], mapping: str = DEFAULT_MAPPING) -> dict[str, Any]:
    """``params`` with the rollout keys mapped from one line to ``params["n_envs"]`` lines by
    ``mapping`` (see the module docstring), unless one of them is given explicitly. One line:
    unchanged."""
    n = params["n_envs"]
    check_mapping(mapping)
    if n == 1:
        return params
    if n & (n - 1) or n > 2048:
        raise ValueError(
            f"n_envs = {n} is not valid for the one-line to N-line mapping: allowed a power of two, 1 .. 2048"
        )
    if any(key in params for key in ONE_LINE_ROLLOUT[algo]):
        return params
    return {**params, **mapped_rollout(algo, n, mapping)}


def gradient_steps_per_transition(algo: str, params: dict[str, Any]) -> float:
    """Gradient steps per environment transition with ``params`` (rollout keys at SB3's default
    when absent): PPO ``n_epochs`` x minibatches per rollout / rollout, DQN ``gradient_steps`` /
    (``train_freq`` x N), A2C one per rollout of ``n_steps`` x N."""
    n = params["n_envs"]
    rollout = {**ONE_LINE_ROLLOUT[algo], **{k: params[k] for k in ONE_LINE_ROLLOUT[algo] if k in params}}
    if algo == "ppo":
        samples = rollout["n_steps"] * n
        return params.get("n_epochs", 10) * -(-samples // params.get("batch_size", 64)) / samples
    if algo == "dqn":
        return rollout["gradient_steps"] / (rollout["train_freq"] * n)
    return 1 / (rollout["n_steps"] * n)


def _check_own_keys(params: dict[str, Any], source: str) -> None:
    for key, low in (("n_timesteps", 1), ("n_envs", 1), ("episode_steps", 1)):
        value = params.get(key)
        if not isinstance(value, int) or isinstance(value, bool) or value < low:
            raise ValueError(f"{key} = {value!r} (from {source}) is not valid: allowed an integer >= {low}")
    if not isinstance(params.get("policy"), str):
        raise ValueError(
            f"policy = {params.get('policy')!r} (from {source})"
            f" is not valid: allowed an SB3 policy name such as MlpPolicy"
        )


def split(params: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(our keys, the algorithm's constructor keyword arguments)."""
    own = {k: params[k] for k in OWN_KEYS}
    return own, {k: v for k, v in params.items() if k not in OWN_KEYS}


def _check_constructor_keys(algo: str, params: dict[str, Any], source_of: Callable[[str], str]) -> None:
    """Fails, naming the key, when ``params`` has a key that is neither ours nor an argument of the
    algorithm's constructor: at load time, before a node is started for nothing."""
    import inspect

    accepted = set(inspect.signature(algorithm_class(algo).__init__).parameters) - {"self", "policy", "env"}
    unknown = sorted(set(split(params)[1]) - accepted)
    if unknown:
        raise ValueError(
            f"{', '.join(f'{k} (from {source_of(k)})' for k in unknown)}"
            f": not a hyperparameter of {algo.upper()} (allowed: "
            f"{', '.join(OWN_KEYS)}, and {algo.upper()}'s arguments: {', '.join(sorted(accepted))})"
        )
