"""`sorting-line-export`: a trained SB3 model (PPO, A2C, DQN, sb3-contrib's MaskablePPO) as an ONNX
policy that a controller runs with onnxruntime alone (no torch, no SB3).

    sorting-line-export models/ppo_B_advanced_seed42.zip --out policy.onnx
    sorting-line-export model.zip --out policy.onnx --setup B --variant advanced   # no training record

The graph is the greedy policy: ``observation`` (float32 [batch, 1|2]) -> ``action`` (int64
[batch], the Gymnasium action index), with ``action_mask`` (bool [batch, n]) as a second input
for MaskablePPO (masked actions get SB3's -1e8 logit). It is SB3's own deterministic decision,
traced from the policy modules by torch.onnx (the TorchScript exporter) and checked here with
onnxruntime against ``policy.predict(deterministic=True)`` on observations drawn over the
observation space; a policy that does not export exactly is refused, naming the disagreement.

The metadata (``line.policy_card``: Gymnasium id, setup, variant, observation layout, action
decoding, algorithm, hyperparameters, training steps, seed, exporter) comes from the training
record beside the model (``<stem>.json``, which `sorting-line-train` writes) and the zip itself;
``--setup``/``--variant``/``--evolution``/``--seed``/``--steps`` give or override it.

Exit codes: 0 written, 2 bad input (not a model, an unsupported policy, a missing record without
``--setup``, a missing package), 1 the export disagreed with SB3.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from ..agents.learned_policy import TRAIN_HINT, PolicyFileError, Sb3Parts, load_learned_policy, read_sb3_zip, sb3_card
from ..line.policy_card import PolicyCard, PolicyCardError
from ..line.vocabulary import MODE_COUNT, SETUPS, VARIANTS

#: ONNX operator set of the written graph (onnxruntime runs 7..23).
OPSET = 17
#: The logit sb3-contrib gives a masked action (``MaskableCategorical``'s HUGE_NEG).
MASKED_LOGIT = -1e8
#: Observations the exporter checks its graph on before it writes it.
SELF_CHECK_SAMPLES = 2000


def exporter_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    import torch

    try:
        ours = version("sorting_line_gym")
    except PackageNotFoundError:  # run from a source tree that is not installed
        ours = "(not installed)"
    return f"sorting_line_gym {ours} (sorting-line-export, torch.onnx {torch.__version__})"


def greedy_module(parts: Sb3Parts):
    """The policy's greedy decision as a torch module: SB3's own layers, then argmax."""
    import torch

    policy, masked = parts.policy, parts.algorithm == "maskable_ppo"

    class Greedy(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.policy = policy

        def logits(self, obs):
            if parts.algorithm == "dqn":
                return self.policy.q_net(obs)  # Q-values: the greedy action is their argmax
            features = self.policy.extract_features(obs, self.policy.pi_features_extractor)
            return self.policy.action_net(self.policy.mlp_extractor.forward_actor(features))

        def forward(self, obs, mask=None):
            logits = self.logits(obs)
            if parts.algorithm == "dqn":
                return torch.argmax(logits, dim=1)
            if mask is not None:
                logits = torch.where(mask, logits, torch.full_like(logits, MASKED_LOGIT))
            # SB3's mode of its Categorical: the argmax of the probabilities, computed as torch's
            # distribution does (normalised logits, softmax). Near-equal logits (an untrained net)
            # round to equal probabilities, and the first of them wins, not the largest logit.
            normalised = logits - torch.logsumexp(logits, dim=1, keepdim=True)
            return torch.argmax(torch.softmax(normalised, dim=1), dim=1)

    module = Greedy().eval()
    return module, masked


def export_onnx(parts: Sb3Parts, card: PolicyCard, out: Path) -> None:
    """Writes the greedy policy of ``parts`` with ``card`` as its metadata to ``out``."""
    import onnx
    import torch

    module, masked = greedy_module(parts)
    obs = torch.zeros((1, parts.obs_dim), dtype=torch.float32)
    args = (obs, torch.ones((1, parts.n_actions), dtype=torch.bool)) if masked else (obs,)
    names = ["observation", "action_mask"][: len(args)]
    out.parent.mkdir(parents=True, exist_ok=True)
    with torch.no_grad(), warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of the dynamo one, which needs onnxscript
        # and more: for SB3's MLPs both write the same graph.
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            module,
            args,
            str(out),
            input_names=names,
            output_names=["action"],
            dynamic_axes={**{n: {0: "batch"} for n in names}, "action": {0: "batch"}},
            opset_version=OPSET,
            dynamo=False,
        )
    model = onnx.load(str(out))
    card.masked, card.exporter = masked, exporter_version()
    del model.metadata_props[:]
    for key, value in card.to_metadata().items():
        model.metadata_props.add(key=key, value=value)
    model.producer_name = "sorting-line-export"
    onnx.checker.check_model(model)
    onnx.save(model, str(out))


def sample_inputs(obs_space, n_actions: int, count: int, seed: int, masked: bool):
    """``count`` observations drawn uniformly over ``obs_space`` and, if ``masked``, random masks
    with at least one allowed action (half of them the evolving line's mode-0-only mask)."""
    rng = np.random.default_rng(seed)
    obs = rng.uniform(obs_space.low, obs_space.high, size=(count, *obs_space.shape)).astype(np.float32)
    if not masked:
        return obs, None
    masks = rng.random((count, n_actions)) < 0.5
    masks[::2] = np.arange(n_actions) % MODE_COUNT == 0
    masks[np.arange(count), rng.integers(0, n_actions, count)] = True
    return obs, masks


def disagreements(path: Path, parts: Sb3Parts, count: int, seed: int = 0) -> tuple[int, str]:
    """How many of ``count`` drawn observations the ONNX file at ``path`` decides otherwise than
    SB3's ``predict(deterministic=True)``, and the first such case."""
    policy = load_learned_policy(path)
    obs, masks = sample_inputs(parts.data["observation_space"], parts.n_actions, count, seed, policy.masked)
    kwargs = {"action_masks": masks} if policy.masked else {}
    expected, _ = parts.policy.predict(obs, deterministic=True, **kwargs)
    got = policy.decide_batch(obs, masks)
    wrong = np.flatnonzero(got != expected)
    first = (
        f"observation {obs[wrong[0]].tolist()}: ONNX {got[wrong[0]]}, SB3 {expected[wrong[0]]}" if wrong.size else ""
    )
    return int(wrong.size), first


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sorting-line-export", description=__doc__.split("\n\n")[0])
    p.add_argument("model", type=Path, help="the SB3 model zip (PPO, A2C, DQN or MaskablePPO)")
    p.add_argument("--out", type=Path, required=True, help="the ONNX file to write")
    p.add_argument("--setup", choices=list(SETUPS), help="the setup trained on (default: the training record's)")
    p.add_argument("--variant", choices=VARIANTS, help="the variant trained on (default: the record's, or the shapes')")
    p.add_argument("--evolution", help="the evolution schedule trained on (evolving line; default: none)")
    p.add_argument("--seed", type=int, help="the training seed (default: the record's or the model's)")
    p.add_argument("--steps", type=int, help="the training steps (default: the record's or the model's)")
    return p


def card_for(args, parts: Sb3Parts) -> PolicyCard:
    """The card from the training record beside the model, the zip and the flags."""
    from ..agents.learned_policy import variant_of_shapes

    base = None
    if args.setup is not None:
        variant = args.variant or variant_of_shapes(parts.obs_dim, parts.n_actions)
        base = PolicyCard(setup=args.setup, variant=variant, algorithm=parts.algorithm)
    card = sb3_card(args.model, parts, base)
    if card is None:
        raise PolicyFileError(
            f"{args.model}: no training record beside it ({args.model.with_suffix('.json').name}): "
            "give the line it was trained on with --setup (and --variant, --evolution)"
        )
    for name, flag in (("variant", args.variant), ("evolution", args.evolution), ("seed", args.seed)):
        if flag is not None:
            setattr(card, name, flag)
    if args.steps is not None:
        card.training_steps = args.steps
    expected = variant_of_shapes(parts.obs_dim, parts.n_actions)
    if card.variant != expected:
        raise PolicyFileError(f"{args.model}: variant {card.variant} does not fit its spaces, which are {expected}'s")
    return card


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        parts = read_sb3_zip(args.model)
        card = card_for(args, parts)
        PolicyCard(**{k: v for k, v in vars(card).items()})  # checks the flags' values once more
        try:
            import onnx  # noqa: F401
            import torch  # noqa: F401
        except ImportError as e:
            raise PolicyFileError(f"exporting needs {e.name}: {TRAIN_HINT}") from None
        export_onnx(parts, card, args.out)
        wrong, first = disagreements(args.out, parts, SELF_CHECK_SAMPLES)
    except (PolicyFileError, PolicyCardError) as e:
        print(f"sorting-line-export: {e}", file=sys.stderr)
        return 2
    if wrong:
        args.out.unlink(missing_ok=True)
        print(
            f"sorting-line-export: the exported policy disagrees with SB3 on {wrong} of {SELF_CHECK_SAMPLES} "
            f"observations (e.g. {first}); nothing written",
            file=sys.stderr,
        )
        return 1
    print(f"wrote {args.out}: {card.describe()}; agrees with SB3 on {SELF_CHECK_SAMPLES} drawn observations")
    return 0


if __name__ == "__main__":
    sys.exit(main())
