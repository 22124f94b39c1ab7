"""The batched on-policy trainer: S seeds of PPO, A2C or MaskablePPO trained at once on S x L
native lines, each seed as SB3's ``OnPolicyAlgorithm.learn`` (stable_baselines3/common/
on_policy_algorithm.py) would train it with ``seed=s`` and ``n_envs=L``.

    trainer = OnPolicyTrainer("ppo", [42, 43, 44], setup="B", variant="advanced",
                              params={"gamma": 0.85, "learning_rate": 7e-4, "ent_coef": 0.03})
    trainer.learn(100_000)               # 100k steps per seed
    trainer.save(["ppo_42.zip", ...])    # SB3 zips: PPO.load opens them

A seed is a run of its own: SB3's initial weights for that seed (``models.new_models``), its own
action-sampling generator (torch) and minibatch generator (numpy), optimizer state, gradient
clip, episode bookkeeping and lines (``lines.BatchedLines``); all seeds share the step count, so
one learning-rate and clip-range schedule (SB3's own, of seed 0's model) serves them all.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ...envs.env import action_space, observation_space
from . import checks
from .a2c import A2CSettings, a2c_update
from .actor_critic import StackedActorCritic, per_seed_modules
from .lines import BatchedLines
from .models import finish_model, load_models, new_models
from .ppo import PPOSettings, minibatch_orders, ppo_update
from .rollout import RolloutBuffer, bootstrap_truncated
from .stacked import optimizer_state_from_seeds, optimizer_state_to_seeds, parameter_pairs, stacked_optimizer

#: progress(trainer): called after each update (steps per seed: trainer.num_timesteps).
Progress = Callable[["OnPolicyTrainer"], None]


class OnPolicyTrainer:
    """S seeds of one on-policy algorithm (see the module docstring). ``models``: SB3 zips, one per
    seed, to continue training from instead of new models."""

    def __init__(
        self,
        algo: str,
        seeds: Sequence[int],
        *,
        setup: str,
        variant: str,
        params: Mapping[str, Any] | None = None,
        lines_per_seed: int = 1,
        episode_steps: int = 250,
        evolution: str | None = None,
        models: Sequence[str | Path] | None = None,
    ) -> None:
        self.algo = checks.check_algo(algo)
        self.seeds = checks.check_seeds(seeds)
        if models is not None and params:
            raise ValueError(
                f"params {sorted(params)} with models: a loaded model keeps its own hyperparameters (as SB3's "
                "load does); allowed no params when continuing models"
            )
        params = checks.check_params(algo, params or {})
        if not isinstance(lines_per_seed, int) or lines_per_seed < 1:
            raise ValueError(f"lines_per_seed = {lines_per_seed!r} is not valid: allowed an integer >= 1")
        if models is not None and len(models) != len(self.seeds):
            raise ValueError(f"{len(models)} models for {len(self.seeds)} seeds: allowed one model per seed")
        n_steps = int(params.get("n_steps", 2048 if algo != "a2c" else 5))
        obs_dim = observation_space("advanced" if evolution else variant).shape[0]  # type: ignore[index]
        n_actions = int(action_space("advanced" if evolution else variant).n)
        checks.check_memory(len(self.seeds), lines_per_seed, n_steps, obs_dim, n_actions)
        self.lines = BatchedLines(
            self.seeds, lines_per_seed, setup=setup, variant=variant, episode_steps=episode_steps, evolution=evolution,
            stats_window=int(params.get("stats_window_size", 100)),
        )  # fmt: skip
        try:
            spaces = (self.lines.observation_space, self.lines.action_space)
            if models is None:
                built = new_models(algo, self.seeds, params, spaces, lines_per_seed)
            else:
                built = load_models(algo, models, self.seeds, spaces, lines_per_seed)
            self._setup(built)
        except BaseException:
            self.lines.close()
            raise

    def _setup(self, built: list) -> None:
        self.models = [b.model for b in built]
        self.template = self.models[0]  # its schedules and settings are every seed's (one config)
        self.policy = StackedActorCritic([m.policy for m in self.models])
        self.pairs = parameter_pairs(self.policy, [per_seed_modules(m.policy) for m in self.models])
        self.optimizer = stacked_optimizer(self.template.policy.optimizer, self.policy.parameters())
        optimizer_state_from_seeds(self.optimizer, self.pairs, [m.policy.optimizer for m in self.models])
        self.generators = [torch.Generator().set_state(b.torch_state) for b in built]
        self.np_rngs = []
        for b in built:
            rng = np.random.RandomState()
            rng.set_state(b.numpy_state)
            self.np_rngs.append(rng)
        t = self.template
        self.masked = self.algo == "maskable_ppo"
        self.buffer = RolloutBuffer(t.n_steps, len(self.seeds), self.lines.n_lines, self.lines.obs_dim,
                                    self.lines.n_actions, masked=self.masked)  # fmt: skip
        self.num_timesteps = int(t.num_timesteps)
        self.n_updates = int(t._n_updates)
        self.total_timesteps = 0
        self.progress_remaining = 1.0
        self._last_obs: np.ndarray | None = None
        self._last_episode_starts = np.ones((len(self.seeds), self.lines.n_lines), dtype=bool)
        self.started = time.perf_counter()

    # --- OnPolicyAlgorithm.learn --------------------------------------------------------------------------------

    def learn(self, total_timesteps: int, progress: Progress | None = None, reset_num_timesteps: bool = True):
        """Trains every seed ``total_timesteps`` steps (whole rollouts, as SB3: until at least that many)."""
        if not isinstance(total_timesteps, int) or total_timesteps < 1:
            raise ValueError(f"total_timesteps = {total_timesteps!r} is not valid: allowed an integer >= 1")
        # BaseAlgorithm._setup_learn
        if reset_num_timesteps:
            self.num_timesteps = 0
            for episodes in self.lines.episodes:  # a new ep_info_buffer, as SB3's
                episodes.clear()
        else:
            total_timesteps += self.num_timesteps
        self.total_timesteps = total_timesteps
        if reset_num_timesteps or self._last_obs is None:
            self._last_obs = self.lines.reset()
            self._last_episode_starts = np.ones((len(self.seeds), self.lines.n_lines), dtype=bool)
        self.started = time.perf_counter()
        while self.num_timesteps < total_timesteps:
            self.collect_rollout()
            # BaseAlgorithm._update_current_progress_remaining
            self.progress_remaining = 1.0 - float(self.num_timesteps) / float(total_timesteps)
            self.train()
            if progress is not None:
                progress(self)
        return self

    def collect_rollout(self) -> None:
        """OnPolicyAlgorithm.collect_rollouts for all seeds: n_steps steps of every line."""
        assert self._last_obs is not None
        buffer, lines, gamma = self.buffer, self.lines, self.template.gamma
        buffer.reset()
        obs = self._last_obs
        while not buffer.full:
            masks = lines.action_masks() if self.masked else None  # sb3-contrib: get_action_masks(env)
            obs_t = torch.from_numpy(obs)
            mask_t = None if masks is None else torch.from_numpy(masks)
            actions, values, log_probs = self.policy.act(obs_t, self.generators, mask_t)
            actions_np = actions.numpy()
            step = lines.step(actions_np)
            self.num_timesteps += lines.n_lines  # env.num_envs per seed
            rewards = step.rewards
            if step.truncated.any():  # timeout: bootstrap from the terminal observation (SB3 issue #633)
                with torch.no_grad():
                    terminal_values = self.policy.predict_values(torch.from_numpy(step.terminal_obs)).numpy()
                bootstrap_truncated(rewards, step.truncated, terminal_values, gamma)
            buffer.add(obs, actions_np, rewards, self._last_episode_starts, values.numpy(), log_probs.numpy(), masks)
            obs = step.obs
            self._last_episode_starts = step.dones
        self._last_obs = obs
        with torch.no_grad():
            last_values = self.policy.predict_values(torch.from_numpy(obs)).numpy()
        buffer.compute_returns_and_advantage(last_values, self._last_episode_starts, gamma, self.template.gae_lambda)

    def train(self) -> None:
        """PPO.train, MaskablePPO.train or A2C.train on the filled buffer, for every seed."""
        t, p = self.template, self.progress_remaining
        # BaseAlgorithm._update_learning_rate
        for group in self.optimizer.param_groups:
            group["lr"] = t.lr_schedule(p)
        data = self.buffer.flat()
        if self.algo == "a2c":
            a2c_update(self.policy, self.optimizer, data, A2CSettings(t.normalize_advantage, t.ent_coef, t.vf_coef,
                                                                      t.max_grad_norm))  # fmt: skip
            self.n_updates += 1
            return
        settings = PPOSettings(
            n_epochs=t.n_epochs,
            batch_size=t.batch_size,
            clip_range=t.clip_range(p),
            clip_range_vf=None if t.clip_range_vf is None else t.clip_range_vf(p),
            normalize_advantage=t.normalize_advantage,
            ent_coef=t.ent_coef,
            vf_coef=t.vf_coef,
            max_grad_norm=t.max_grad_norm,
            maskable=self.masked,
        )
        ppo_update(self.policy, self.optimizer, data, settings, minibatch_orders(self.np_rngs, t.n_epochs, data.size))
        self.n_updates += t.n_epochs

    # --- what a run gives -----------------------------------------------------------------------------------------

    def predict(self, obs: np.ndarray, masks: np.ndarray | None = None) -> np.ndarray:
        """(S, B) actions of each seed's ``predict(obs, deterministic=True)`` for ``obs`` (S, B, obs_dim)."""
        mask_t = None if masks is None else torch.as_tensor(masks, dtype=torch.bool)
        return self.policy.predict(torch.as_tensor(obs, dtype=torch.float32), mask_t).numpy()

    def sync_models(self) -> list[Any]:
        """Each seed's SB3 model with the trained weights, optimizer state and counters written in."""
        with torch.no_grad():
            for p, per_seed in self.pairs:
                for s, q in enumerate(per_seed):
                    q.copy_(p[s])
        optimizer_state_to_seeds(self.optimizer, self.pairs, [m.policy.optimizer for m in self.models])
        for s, model in enumerate(self.models):
            last_obs = None if self._last_obs is None else self._last_obs[s].copy()
            finish_model(
                model,
                {
                    "num_timesteps": self.num_timesteps,
                    "_total_timesteps": self.total_timesteps,
                    "_n_updates": self.n_updates,
                    "_current_progress_remaining": self.progress_remaining,
                    "_episode_num": 0,
                    "ep_info_buffer": list(self.lines.episodes[s]),
                    "_last_obs": last_obs,
                    "_last_episode_starts": self._last_episode_starts[s].copy(),
                },
            )
        return self.models

    def save(self, paths: Sequence[str | Path]) -> list[Path]:
        """Writes seed s's model to ``paths[s]`` as SB3's ``model.save`` does."""
        if len(paths) != len(self.seeds):
            raise ValueError(f"{len(paths)} paths for {len(self.seeds)} seeds: allowed one path per seed")
        written = []
        for model, path in zip(self.sync_models(), paths, strict=True):
            model.save(path)
            written.append(Path(path) if str(path).endswith(".zip") else Path(f"{path}.zip"))
        return written

    def steps_per_second(self) -> float:
        """Steps per second of all seeds together since learn() started."""
        elapsed = max(time.perf_counter() - self.started, 1e-9)
        return self.num_timesteps * len(self.seeds) / elapsed

    def close(self) -> None:
        self.lines.close()
