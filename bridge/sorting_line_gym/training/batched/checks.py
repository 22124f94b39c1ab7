"""What the batched trainer accepts, checked before anything is built or trained: the algorithm,
the seeds, each SB3 hyperparameter (implemented, or only at SB3's default, or refused by name:
never silently ignored), and whether S x L lines fit in memory.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

#: The algorithms of the batched trainer, by their command-line name (line/policy_card.py's names).
ON_POLICY = ("ppo", "a2c", "maskable_ppo")
#: numpy's legacy seeding (which SB3's set_random_seed uses) takes seeds below 2**32.
SEED_LIMIT = 2**32

#: Constructor arguments the trainer implements, with any value SB3 accepts.
COMMON = (
    "learning_rate",
    "n_steps",
    "gamma",
    "gae_lambda",
    "ent_coef",
    "vf_coef",
    "max_grad_norm",
    "stats_window_size",
)
IMPLEMENTED = {
    "ppo": (*COMMON, "batch_size", "n_epochs", "clip_range", "clip_range_vf", "normalize_advantage"),
    "maskable_ppo": (*COMMON, "batch_size", "n_epochs", "clip_range", "clip_range_vf", "normalize_advantage"),
    "a2c": (*COMMON, "normalize_advantage", "rms_prop_eps", "use_rms_prop"),
}
#: Arguments the trainer has only at one value (SB3's default, or what it does anyway).
ONLY_VALUE: dict[str, Any] = {
    "use_sde": False,
    "sde_sample_freq": -1,
    "target_kl": None,
    "rollout_buffer_class": None,
    "rollout_buffer_kwargs": None,
    "tensorboard_log": None,
    "verbose": 0,
    "device": "cpu",
}
#: policy_kwargs keys the trainer implements (the policy SB3 builds from them is then checked:
#: actor_critic.check_policy, optim.settings_of).
POLICY_KWARGS = ("net_arch", "activation_fn", "ortho_init", "optimizer_class", "optimizer_kwargs")


def check_algo(algo: str) -> str:
    if algo not in ON_POLICY:
        raise ValueError(f"algorithm {algo!r} is not valid for the batched trainer: allowed {', '.join(ON_POLICY)}")
    return algo


def check_seeds(seeds: Sequence[int]) -> list[int]:
    """Seeds as a list: at least one, each an integer 0 <= s < 2**32, no two equal."""
    seeds = list(seeds)
    if not seeds:
        raise ValueError("seeds = []: allowed one or more seeds (one training each)")
    for s in seeds:
        if not isinstance(s, int) or isinstance(s, bool) or not 0 <= s < SEED_LIMIT:
            raise ValueError(f"seed {s!r} is not valid: allowed integers 0 <= seed < 2**32")
    repeated = sorted({s for s in seeds if seeds.count(s) > 1})
    if repeated:
        raise ValueError(f"seeds {repeated} are given more than once: allowed distinct seeds (each its own run)")
    return seeds


def algorithm_class(algo: str) -> type:
    """The SB3 (or sb3-contrib) class of ``algo``: an on-policy algorithm, or ``"dqn"`` (the batched
    DQN builds its seeds' models with ``models.new_models`` too)."""
    if algo == "dqn":
        from stable_baselines3 import DQN

        return DQN
    if check_algo(algo) == "maskable_ppo":
        from sb3_contrib import MaskablePPO

        return MaskablePPO
    import stable_baselines3

    return getattr(stable_baselines3, algo.upper())


def check_params(algo: str, params: Mapping[str, Any]) -> dict[str, Any]:
    """``params`` (SB3 constructor keyword arguments), refused by name where the trainer does not
    implement a key or a value; returns them with ``device="cpu"`` (the trainer runs on the CPU)."""
    import inspect

    cls = algorithm_class(algo)
    accepted = set(inspect.signature(cls.__init__).parameters) - {"self", "policy", "env", "_init_setup_model"}
    implemented = set(IMPLEMENTED[algo]) | set(ONLY_VALUE) | {"policy_kwargs"}
    name = cls.__name__
    for key, value in params.items():
        if key == "seed":
            raise ValueError("seed is not a hyperparameter of the batched trainer: give the seeds (one run each)")
        if key not in accepted:
            raise ValueError(f"{key} is not a hyperparameter of {name} (allowed: {', '.join(sorted(accepted))})")
        if key not in implemented:
            raise ValueError(
                f"{key} = {value!r}: an option of {name} the batched trainer does not implement "
                f"(implemented: {', '.join(sorted(implemented))}); use --engine sb3 for it"
            )
        if key in ONLY_VALUE and value != ONLY_VALUE[key] and not (key == "device" and value == "auto"):
            raise ValueError(
                f"{key} = {value!r}: the batched trainer implements only {key} = {ONLY_VALUE[key]!r}; "
                "use --engine sb3 for another value"
            )
    for key in params.get("policy_kwargs") or {}:
        if key not in POLICY_KWARGS:
            raise ValueError(
                f"policy_kwargs {key}: not implemented by the batched trainer (implemented: {', '.join(POLICY_KWARGS)})"
            )
    return {**params, "device": "cpu"}


def check_policy_name(policy: str) -> str:
    if policy != "MlpPolicy":
        raise ValueError(f"policy = {policy!r}: the batched trainer has MlpPolicy")
    return policy


def bytes_needed(n_seeds: int, n_lines: int, n_steps: int, obs_dim: int, n_actions: int) -> int:
    """A generous estimate of what S x L lines and their rollouts take: the rollout arrays (twice:
    numpy and the flat torch copy), the lines and their outputs (LINE_BYTES each, measured), the
    activations of one forward pass over all lines (64 units, a few layers)."""
    per_sample = 4 * obs_dim + 8 + 4 * 6 + n_actions
    return n_seeds * n_lines * (2 * n_steps * per_sample + LINE_BYTES + 16 * 64 * 4)


#: Memory of one native line with its seed generator and batch outputs: 2.4 kB measured (20,000
#: advanced lines after 200 steps), with a margin.
LINE_BYTES = 8192


def check_memory(n_seeds: int, n_lines: int, n_steps: int, obs_dim: int, n_actions: int) -> None:
    """Refuses an S x L whose estimate (:func:`bytes_needed`) exceeds 80% of the available memory."""
    need = bytes_needed(n_seeds, n_lines, n_steps, obs_dim, n_actions)
    have = available_memory()
    if have is not None and need > 0.8 * have:
        raise ValueError(
            f"{n_seeds} seeds x {n_lines} lines with {n_steps}-step rollouts would need about {need / 2**30:.1f} GiB; "
            f"this machine has {have / 2**30:.1f} GiB available: allowed up to 80% of it (fewer seeds, lines or steps)"
        )


def available_memory() -> int | None:
    """MemAvailable of /proc/meminfo in bytes (None where there is none)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None
