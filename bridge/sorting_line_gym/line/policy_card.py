"""What a deployed policy says about itself: the metadata `sorting-line-export` writes into an ONNX
file's ``metadata_props`` and every runtime reads back (the controller, ``agents.learned_policy``).

A card names the line the policy was trained for (Gymnasium id, setup, variant, evolution
schedule), how to build its input (observation layout, the value of an unknown category, whether
it takes an action mask) and how to read its output (action decoding), and where it came from
(algorithm, hyperparameters, training steps, seed, exporter). Keys are ``sorting_line.<field>``;
structured values are JSON. Nothing here loads ONNX, torch or ROS: a card is plain data.

``sorting-line-train`` writes the training half of a card into the JSON beside each model
(``<stem>.json``: algo, setup, variant, seed, n_timesteps, hyperparams), which
:func:`card_from_training_json` reads.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from .vocabulary import (
    ACTION_COUNTS,
    CATEGORY_UNKNOWN_OBSERVATION,
    ENV_IDS,
    MODE_COUNT,
    MODES,
    SPEEDS,
    check_setup,
    check_variant,
)

#: Prefix of every metadata key we write; a file without ``sorting_line.format`` is not ours.
PREFIX = "sorting_line."
#: Version of the card's layout (bumped when a field changes meaning).
FORMAT = 1
#: Gymnasium id of the evolving line (an advanced line whose hardware changes).
EVOLVING_ID = "SortingLineEvolving-v0"
#: The package whose ids these are (``gymnasium.make("sorting_line_gym:<id>")``).
ID_PACKAGE = "sorting_line_gym"
#: Algorithms the exporter knows, by the name the card gives them, with their display names.
ALGORITHMS = {"ppo": "PPO", "a2c": "A2C", "dqn": "DQN", "maskable_ppo": "MaskablePPO"}


class PolicyCardError(ValueError):
    """A card that is missing, incomplete or inconsistent (the message says which field)."""


def observation_layout(variant: str) -> dict[str, Any]:
    """The observation a policy of ``variant`` takes, as the env builds it (``vocabulary.observations``)."""
    if check_variant(variant) == "advanced":
        return {
            "shape": [2],
            "dtype": "float32",
            "fields": ["input sensor reading 0..1", "ratio category 0 mixed, 1 A-rich, 2 B-rich"],
            "category_unknown": CATEGORY_UNKNOWN_OBSERVATION,
        }
    return {"shape": [1], "dtype": "float32", "fields": ["input sensor reading 0..1"]}


def action_decoding(variant: str) -> dict[str, Any]:
    """How an action index becomes commands (``vocabulary.decode_actions``)."""
    decoding = {"n": ACTION_COUNTS[check_variant(variant)], "speeds": list(SPEEDS)}
    if variant == "advanced":
        rules = {"speed_index": f"action // {MODE_COUNT}", "mode": f"action % {MODE_COUNT}"}
        return {**decoding, **rules, "modes": dict(MODES)}
    return {**decoding, "speed_index": "action", "mode": "always 0"}


@dataclass
class PolicyCard:
    """One policy's metadata (see the module's docstring)."""

    setup: str
    variant: str
    algorithm: str
    seed: int | None = None
    training_steps: int | None = None
    hyperparameters: dict[str, Any] = field(default_factory=dict)
    evolution: str = ""  # the schedule trained on (evolving line), "" for a fixed line
    masked: bool = False  # the ONNX graph takes an action mask as its second input
    exporter: str = ""
    format: int = FORMAT

    def __post_init__(self):
        try:
            check_setup(self.setup)
            check_variant(self.variant)
        except ValueError as e:
            raise PolicyCardError(str(e)) from None
        if self.algorithm not in ALGORITHMS:
            raise PolicyCardError(f"algorithm = {self.algorithm!r} is not valid: allowed {', '.join(ALGORITHMS)}")

    @property
    def env_id(self) -> str:
        return f"{ID_PACKAGE}:{EVOLVING_ID if self.evolution else ENV_IDS[self.variant]}"

    def describe(self) -> str:
        line = f"setup {self.setup} {self.variant}" + (f" (evolving: {self.evolution})" if self.evolution else "")
        origin = ", ".join(
            part
            for part in (
                f"seed {self.seed}" if self.seed is not None else "",
                f"{self.training_steps} steps" if self.training_steps is not None else "",
            )
            if part
        )
        return f"{ALGORITHMS[self.algorithm]} for {line}" + (f" ({origin})" if origin else "")

    def to_metadata(self) -> dict[str, str]:
        """The ``metadata_props`` of the ONNX file: strings, structures as JSON."""
        values = asdict(self)
        values.update(
            env_id=self.env_id,
            observation=observation_layout(self.variant),
            action=action_decoding(self.variant),
            inputs=["observation", "action_mask"] if self.masked else ["observation"],
        )
        return {PREFIX + k: v if isinstance(v, str) else json.dumps(v, sort_keys=True) for k, v in values.items()}

    @classmethod
    def from_metadata(cls, props: dict[str, str]) -> PolicyCard:
        """The card of an ONNX file's ``metadata_props``; PolicyCardError if it has none or a bad one."""
        if PREFIX + "format" not in props:
            raise PolicyCardError("it has no sorting_line metadata (not written by sorting-line-export)")
        values: dict[str, Any] = {}
        for f in fields(cls):
            text = props.get(PREFIX + f.name)
            if text is None:
                continue
            try:
                values[f.name] = text if f.type == "str" else json.loads(text)
            except json.JSONDecodeError:
                raise PolicyCardError(f"metadata {PREFIX}{f.name} = {text!r} is not valid JSON") from None
        if values.get("format") != FORMAT:
            raise PolicyCardError(f"metadata format {values.get('format')!r} is not valid: allowed {FORMAT}")
        for name in ("setup", "variant", "algorithm"):
            if name not in values:
                raise PolicyCardError(f"metadata {PREFIX}{name} is missing")
        return cls(**values)


def card_from_training_json(path: str | Path, algorithm: str | None = None) -> PolicyCard:
    """The card of a model trained by `sorting-line-train`, from the JSON beside it."""
    try:
        run = json.loads(Path(path).read_text())
        return PolicyCard(
            setup=run["setup"],
            variant=run["variant"],
            algorithm=algorithm or run["algo"],
            seed=run.get("seed"),
            training_steps=run.get("n_timesteps"),
            hyperparameters=run.get("hyperparams", {}),
            evolution=run.get("evolution", "") or "",
        )
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as e:
        raise PolicyCardError(
            f"{path}: not a training record of sorting-line-train ({type(e).__name__}: {e})"
        ) from None
