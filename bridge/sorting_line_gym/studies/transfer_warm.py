"""What two of the transfer study's strategies do to an agent before it trains on the changed line
(``transfer_cells`` runs them; docs/evolving.md says why these values):

- **shrink-and-perturb** (``shrink_perturb``): the continued agent's weights at the change mixed
  with a fresh initialisation's;
- **new, cloned from the oracle** (``clone_oracle``): a new agent's policy first fitted to the
  exact oracle's actions on the changed line (``oracle_demonstrations``).

Both work on SB3 models in torch; the batched engine writes its weights into its seeds' SB3
models, applies the same function there and reads them back (``in_batched``), so the two engines
give the same agents. Neither draws from the global random generators: an agent's own training
draws what it would have drawn without them.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

import numpy as np

#: Shrink-and-perturb (Ash & Adams, "On Warm-Starting Neural Network Training", NeurIPS 2020):
#: at the change every parameter theta becomes SHRINK * theta + PERTURB * theta_fresh, theta_fresh
#: that parameter of a fresh initialisation of the same policy (the paper's noise: "a randomly
#: initialised model as the noise source", so each layer's noise has its own init's scale). 0.4 and
#: 0.1 are the defaults of the authors' own code (github.com/JordanAsh/warm_start, run.py's --shrink
#: and --perturb); the paper sweeps both. Unlike that code, which starts a new optimizer, the agent's
#: Adam state goes on, as the continued agent's does (docs/evolving.md).
SHRINK, PERTURB = 0.4, 0.1
#: The fresh initialisation of seed s's perturbation is seeded FRESH_SEED + s: its own, not the
#: agent's initial weights (seeded s), and the same on every run of the cell.
FRESH_SEED = 1_000_000
#: Behaviour cloning of the oracle (``clone_oracle``): its episodes on the changed line from seeds
#: CLONE_SEED... (training seeds: below the held-out 10000...), the same demonstrations for every
#: training seed; cross-entropy of the policy's action distribution on the oracle's actions,
#: CLONE_EPOCHS passes in minibatches of CLONE_BATCH, with Adam at CLONE_LR (its own optimiser: the
#: agent's RL optimiser starts fresh, as a new agent's). Chosen, not tuned: 20 episodes are 1000
#: steps, a hundredth of the paper's training budget.
CLONE_SEED, CLONE_EPISODES, CLONE_EPOCHS, CLONE_BATCH, CLONE_LR = 0, 20, 10, 100, 1e-3


def fresh_policy(model, seed: int):
    """A fresh initialisation of ``model``'s policy (same class, spaces and settings), its weights
    drawn from torch seeded ``seed``; the global generators are left as they were."""
    import torch

    saved = torch.get_rng_state(), np.random.get_state(), random.getstate()
    try:
        torch.manual_seed(seed)
        return model.policy_class(model.observation_space, model.action_space, model.lr_schedule,
                                  **model.policy_kwargs)  # fmt: skip
    finally:
        torch.set_rng_state(saved[0])
        np.random.set_state(saved[1])
        random.setstate(saved[2])


def shrink_perturb(model, seed: int) -> None:
    """Shrink-and-perturb ``model``'s policy in place: theta <- SHRINK * theta + PERTURB * theta_fresh,
    theta_fresh from ``fresh_policy(model, FRESH_SEED + seed)``. The optimiser's state carries on,
    as the continued agent's does: only the weights differ from it."""
    import torch

    fresh = dict(fresh_policy(model, FRESH_SEED + seed).named_parameters())
    with torch.no_grad():
        for name, theta in model.policy.named_parameters():
            theta.mul_(SHRINK).add_(fresh[name], alpha=PERTURB)


def oracle_demonstrations(line: dict[str, Any], env, episodes: int = CLONE_EPISODES) -> tuple[np.ndarray, np.ndarray]:
    """(observations, actions) of the exact oracle's ``episodes`` (seeds CLONE_SEED...) on the
    library's fixed ``line``, replayed on ``env`` (the changed line, whose dynamics are that line's)
    for what the agent reads there. Raises if a replayed episode's reward is not the oracle's (then
    ``env`` is not the line the oracle solved)."""
    import sorting_line_gym._native as _native

    observations, actions = [], []
    for i in range(episodes):
        reward, best = _native.oracle(line, CLONE_SEED + i)
        obs, _ = env.reset(seed=CLONE_SEED + i)
        total = 0.0
        for action in best:
            observations.append(np.asarray(obs, dtype=np.float32))
            actions.append(int(action))
            obs, r, terminated, truncated, _ = env.step(int(action))
            total += float(r)
            if terminated or truncated:
                break
        if not np.isclose(total, reward, rtol=0, atol=1e-6):
            raise ValueError(
                f"the oracle's episode {CLONE_SEED + i} of the line {line} replayed gives {total}, not its {reward}: "
                "the line it was replayed on is another"
            )
    return np.stack(observations), np.array(actions, dtype=np.int64)


def clone_oracle(model, seed: int, demonstrations: tuple[np.ndarray, np.ndarray]) -> list[float]:
    """Behaviour cloning of ``model``'s policy on ``demonstrations`` (``oracle_demonstrations``), in
    place (CLONE_* above), the minibatch order from a generator seeded ``seed``. Returns each
    epoch's mean loss (the negative log-likelihood of the oracle's actions)."""
    import torch

    obs, actions = (torch.as_tensor(a) for a in demonstrations)
    policy = model.policy
    optimizer = torch.optim.Adam(policy.parameters(), lr=CLONE_LR)
    generator = torch.Generator().manual_seed(seed)
    losses = []
    policy.set_training_mode(True)
    for _ in range(CLONE_EPOCHS):
        order, total = torch.randperm(len(actions), generator=generator), 0.0
        for start in range(0, len(actions), CLONE_BATCH):
            batch = order[start : start + CLONE_BATCH]
            loss = -policy.get_distribution(obs[batch]).log_prob(actions[batch]).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(batch)
        losses.append(total / len(actions))
    policy.set_training_mode(False)
    return losses


def in_batched(trainer, change: Callable[[Any, int], Any]) -> list[Any]:
    """``change(model, seed)`` for every seed of the batched ``trainer``: its weights written into its
    SB3 models, changed there, and read back; its optimiser state, generators and lines go on as
    they were. Returns what each call returned."""
    from ..training.batched import params

    found = [change(model, int(seed)) for seed, model in zip(trainer.seeds, trainer.sync_models(), strict=True)]
    trainer.params = params.stack(trainer.trees)
    return found
