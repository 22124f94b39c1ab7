"""A trained policy as an agent: an ONNX file written by `sorting-line-export` (run by onnxruntime;
torch is never imported) or a saved Stable-Baselines3 model (``.zip``, where SB3 is installed).

Both give the greedy decision for one observation, built as the env builds it
(``vocabulary.observations``), with the action mask of the line's hardware
(``vocabulary.action_mask``) where the policy takes one (MaskablePPO). :func:`load_learned_policy`
opens either and refuses, with a :class:`PolicyFileError` naming why, what cannot be a policy for
the line: not a model, an SB3 policy we cannot run or export, an ONNX file without our metadata
(usable only when told to ignore the mismatch and its shapes fit), or a missing runtime (naming
the install command).

The SB3 side is read policy-only (``load_from_zip_file``: the policy class, its spaces and
weights), so that PPO, A2C, DQN and MaskablePPO load alike and the exporter (``training.export``)
exports exactly the module that decides here.
"""

from __future__ import annotations

import json
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..line.policy_card import PolicyCard, PolicyCardError, card_from_training_json
from ..line.vocabulary import ACTION_COUNTS, action_mask, decode_action, observations

#: Where onnxruntime comes from (the project's pinned core set).
INSTALL_HINT = "pip install -r launch_scripts/requirements-bridge.txt (or: bash launch_scripts/setup.sh)"
#: Where SB3, sb3-contrib and torch come from: the training stack, which a core install leaves out.
TRAIN_HINT = "bash launch_scripts/setup.sh --train (or: pip install -r launch_scripts/requirements-train.txt)"


def missing_training_stack() -> list[str]:
    """The packages of the training stack that this install lacks (a core one lacks them all)."""
    import importlib.util

    return [m for m in ("torch", "stable_baselines3") if importlib.util.find_spec(m) is None]


#: Scalar settings of an SB3 model that a card lists as its hyperparameters.
HYPERPARAMETERS = (
    "learning_rate",
    "gamma",
    "gae_lambda",
    "ent_coef",
    "vf_coef",
    "max_grad_norm",
    "n_steps",
    "batch_size",
    "n_epochs",
    "buffer_size",
    "learning_starts",
    "tau",
    "target_update_interval",
    "exploration_final_eps",
    "exploration_fraction",
)


class PolicyFileError(ValueError):
    """A file that cannot serve as the line's policy; the message says why (exit code 2)."""


def variant_of_shapes(obs_dim: int, n_actions: int) -> str:
    """The line variant whose observation and action spaces have these sizes, or PolicyFileError."""
    for variant, n in ACTION_COUNTS.items():
        if n == n_actions and obs_dim == (2 if variant == "advanced" else 1):
            return variant
    raise PolicyFileError(
        f"its observation has {obs_dim} value(s) and its action space {n_actions} actions: no line has those "
        f"(basic: 1 and {ACTION_COUNTS['basic']}; advanced and evolving: 2 and {ACTION_COUNTS['advanced']})"
    )


@dataclass
class LearnedPolicy:
    """A loaded policy: ``decide(obs, mask)`` -> the greedy action index."""

    path: str
    card: PolicyCard | None
    obs_dim: int
    n_actions: int
    masked: bool
    runtime: str  # "onnxruntime" or "stable-baselines3"
    _decide: Any = field(repr=False, default=None)

    @property
    def variant(self) -> str:
        return variant_of_shapes(self.obs_dim, self.n_actions)

    def decide(self, obs: np.ndarray, mask: np.ndarray | None) -> int:
        """The greedy action for one observation (and mask, if the policy takes one)."""
        masks = None if mask is None else np.asarray(mask, dtype=bool).reshape(1, -1)
        return int(self.decide_batch(np.asarray(obs, dtype=np.float32).reshape(1, self.obs_dim), masks)[0])

    def decide_batch(self, obs: np.ndarray, masks: np.ndarray | None) -> np.ndarray:
        """The greedy actions for a batch of observations [n, obs_dim] (and masks [n, n_actions])."""
        if self.masked and masks is None:
            masks = np.ones((len(obs), self.n_actions), dtype=bool)
        return np.asarray(self._decide(np.asarray(obs, dtype=np.float32), masks)).reshape(-1)

    def act(self, obs: np.ndarray, mask: np.ndarray | None) -> tuple[int, int]:
        """(speed index, mode) of the greedy action."""
        return decode_action(self.variant, self.decide(obs, mask))

    def describe(self) -> str:
        what = self.card.describe() if self.card else "a policy without sorting_line metadata"
        return f"{what}, {Path(self.path).name} on {self.runtime}"


def load_learned_policy(path: str | Path, card: PolicyCard | None = None) -> LearnedPolicy:
    """An ONNX file (``.onnx``) or an SB3 model (a zip); ``card`` stands in for a zip's missing
    training record (an ONNX file's card is its metadata)."""
    path = Path(path)
    if not path.is_file():
        raise PolicyFileError(f"{path}: no such file")
    if zipfile.is_zipfile(path):
        return _load_sb3(path, card)
    return _load_onnx(path)


# -- ONNX ----------------------------------------------------------------------------------------


def _load_onnx(path: Path) -> LearnedPolicy:
    try:
        import onnxruntime
    except ImportError:
        raise PolicyFileError(f"{path}: running an ONNX policy needs onnxruntime: {INSTALL_HINT}") from None
    options = onnxruntime.SessionOptions()
    # A 64x64 MLP: one thread decides fastest and leaves the cores to the node.
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    options.log_severity_level = 3
    try:
        session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except Exception as e:  # noqa: BLE001 - onnxruntime raises its own exception types per failure
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise PolicyFileError(f"{path}: not an ONNX model onnxruntime can load ({first})") from None
    inputs, outputs = session.get_inputs(), session.get_outputs()
    obs_dim = inputs[0].shape[-1] if inputs and len(inputs[0].shape) == 2 else None
    if not isinstance(obs_dim, int) or len(inputs) not in (1, 2) or len(outputs) != 1:
        shapes = [(i.name, i.shape) for i in inputs]
        raise PolicyFileError(
            f"{path}: its inputs {shapes} are not a policy's (allowed: observation [batch, 1 or 2] and optionally "
            "action_mask [batch, n])"
        )
    masked = len(inputs) == 2
    try:
        card = PolicyCard.from_metadata(dict(session.get_modelmeta().custom_metadata_map))
    except PolicyCardError as e:
        card = None
        if "no sorting_line metadata" not in str(e):
            raise PolicyFileError(f"{path}: {e}") from None
    n_actions = ACTION_COUNTS[card.variant] if card else (inputs[1].shape[-1] if masked else None)
    if n_actions is None or not isinstance(n_actions, int):
        # Without metadata nor a mask input the action count shows only in what it answers.
        probe = session.run(None, {inputs[0].name: np.zeros((1, obs_dim), np.float32)})[0]
        n_actions = ACTION_COUNTS["advanced" if obs_dim == 2 else "basic"] if probe.size == 1 else -1
    policy = LearnedPolicy(str(path), card, obs_dim, n_actions, masked, "onnxruntime")
    policy.variant  # noqa: B018 - raises PolicyFileError for shapes that fit no line
    names = [i.name for i in inputs]

    def decide(obs: np.ndarray, masks: np.ndarray | None):
        feed = {names[0]: obs, **({names[1]: masks} if masked else {})}
        return session.run(None, feed)[0]

    policy._decide = decide
    return policy


# -- Stable-Baselines3 -------------------------------------------------------------------------


@dataclass
class Sb3Parts:
    """What an SB3 zip holds that a runtime and the exporter need."""

    policy: Any  # the torch policy module, in eval mode
    algorithm: str
    data: dict
    obs_dim: int
    n_actions: int


def read_sb3_zip(path: str | Path) -> Sb3Parts:
    """The policy of an SB3 model zip, rebuilt from its class, spaces and weights (no env)."""
    path = Path(path)
    if not path.is_file():
        raise PolicyFileError(f"{path}: no such file")
    try:
        from gymnasium import spaces
        from stable_baselines3.common.policies import ActorCriticPolicy
        from stable_baselines3.common.save_util import load_from_zip_file
        from stable_baselines3.dqn.policies import DQNPolicy
    except ImportError:
        raise PolicyFileError(
            f"{path}: a Stable-Baselines3 model (.zip) needs stable-baselines3 and torch, the training stack, "
            f"not installed here: {TRAIN_HINT}; or export it where they are (sorting-line-export MODEL.zip --out "
            "POLICY.onnx) and run the .onnx, which needs only onnxruntime"
        ) from None
    try:
        data, params, _ = load_from_zip_file(path, device="cpu", print_system_info=False)
    except (ValueError, KeyError, OSError, zipfile.BadZipFile, json.JSONDecodeError) as e:
        raise PolicyFileError(f"{path}: not a Stable-Baselines3 model ({e})") from None
    if not data or not params or "policy" not in params:
        raise PolicyFileError(f"{path}: not a Stable-Baselines3 model (no policy data or weights)")
    cls, obs_space, act_space = data.get("policy_class"), data.get("observation_space"), data.get("action_space")
    if not isinstance(cls, type):
        raise PolicyFileError(
            f"{path}: its policy class cannot be loaded here ({cls!r}; sb3-contrib's MaskablePPO needs sb3-contrib: "
            f"{TRAIN_HINT})"
        )
    kinds = [c.__name__ for c in cls.__mro__]
    if not (issubclass(cls, (ActorCriticPolicy, DQNPolicy)) or "MaskableActorCriticPolicy" in kinds):
        raise PolicyFileError(
            f"{path}: its policy {cls.__name__} is not supported (allowed: the MlpPolicy of PPO, A2C, DQN, MaskablePPO)"
        )
    if not isinstance(act_space, spaces.Discrete) or not isinstance(obs_space, spaces.Box) or len(obs_space.shape) != 1:
        raise PolicyFileError(
            f"{path}: it acts in {act_space} on {obs_space}; a line's policy acts in Discrete(n) on a flat Box"
        )
    variant_of_shapes(obs_space.shape[0], int(act_space.n))
    policy = cls(obs_space, act_space, lambda _progress: 0.0, **(data.get("policy_kwargs") or {}))
    try:
        policy.load_state_dict(params["policy"])
    except RuntimeError as e:
        raise PolicyFileError(f"{path}: its weights do not fit its policy ({str(e).splitlines()[0]})") from None
    policy.set_training_mode(False)
    return Sb3Parts(policy, _algorithm(cls, data), data, obs_space.shape[0], int(act_space.n))


def _algorithm(cls: type, data: dict) -> str:
    names = [c.__name__ for c in cls.__mro__]
    if "MaskableActorCriticPolicy" in names:
        return "maskable_ppo"
    if "DQNPolicy" in names:
        return "dqn"
    return "ppo" if "clip_range" in data else "a2c"


def sb3_card(path: Path, parts: Sb3Parts, card: PolicyCard | None) -> PolicyCard | None:
    """The card of a zip: ``card`` if given, else from the training record beside it (``<stem>.json``)
    if there is one, completed from the zip (algorithm, seed, steps, hyperparameters)."""
    record = path.with_suffix(".json")
    if card is None and record.is_file():
        try:
            card = card_from_training_json(record, algorithm=parts.algorithm)
        except PolicyCardError as e:
            raise PolicyFileError(str(e)) from None
    if card is None:
        return None
    card.algorithm = parts.algorithm
    card.masked = parts.algorithm == "maskable_ppo"
    if card.seed is None and isinstance(parts.data.get("seed"), int):
        card.seed = parts.data["seed"]
    if card.training_steps is None and isinstance(parts.data.get("num_timesteps"), int):
        card.training_steps = parts.data["num_timesteps"]
    if not card.hyperparameters:
        card.hyperparameters = {
            k: parts.data[k] for k in HYPERPARAMETERS if isinstance(parts.data.get(k), (int, float, str))
        }
    return card


def _load_sb3(path: Path, card: PolicyCard | None) -> LearnedPolicy:
    parts = read_sb3_zip(path)  # first: without SB3 (and so torch) it says what to install
    import torch

    card = sb3_card(path, parts, card)
    masked = parts.algorithm == "maskable_ppo"

    def decide(obs: np.ndarray, masks: np.ndarray | None):
        with torch.no_grad():
            kwargs = {"action_masks": masks} if masked else {}
            action, _ = parts.policy.predict(obs, deterministic=True, **kwargs)
        return action

    return LearnedPolicy(str(path), card, parts.obs_dim, parts.n_actions, masked, "stable-baselines3", decide)


class LearnedAgent:
    """A learned policy behind the agents' interface (``agents.policies``): ``act`` builds the
    observation as the env does (``vocabulary.observations``; category
    ``vocabulary.CATEGORY_UNKNOWN_CODE`` while the line has no ratio sensor) and masks it as
    ``action_masks()`` does for the line's hardware (``sort_modes``: set by the controller as the
    evolving line's events say)."""

    def __init__(self, policy: LearnedPolicy):
        self.policy, self.variant = policy, policy.variant
        self.name = f"policy {Path(policy.path).name}"
        self.sort_modes = True

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset: a greedy policy has no state."""

    def observation(self, quantity: float, category: int) -> np.ndarray:
        return observations(self.variant, quantity, category)

    def act(self, quantity: float, category: int, current_speed_index: int) -> tuple[int, int]:
        if not math.isfinite(quantity):
            raise ValueError(f"the input reading is {quantity}, not a number the policy can take")
        mask = action_mask(self.variant, self.sort_modes) if self.policy.masked else None
        return self.policy.act(self.observation(quantity, category), mask)

    def predict(self, obs, current_speed_index: int) -> int:
        mask = action_mask(self.variant, self.sort_modes) if self.policy.masked else None
        return self.policy.decide(np.asarray(obs, dtype=np.float32), mask)
