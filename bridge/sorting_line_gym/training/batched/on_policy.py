"""The batched on-policy trainer: S seeds of PPO, A2C or MaskablePPO trained at once on S x L
lines (native by default, or a node's with ``backend="ros"``: ``lines.BatchedLines``), each seed
as SB3's ``OnPolicyAlgorithm.learn`` (stable_baselines3/common/on_policy_algorithm.py) would
train it with ``seed=s`` and ``n_envs=L``.

    trainer = OnPolicyTrainer("ppo", [42, 43, 44], setup="B", variant="advanced",
                              params={"gamma": 0.85, "learning_rate": 7e-4, "ent_coef": 0.03})
    trainer.learn(100_000)               # 100k steps per seed
    trainer.save(["ppo_42.zip", ...])    # SB3 zips: PPO.load opens them

A seed is a run of its own: SB3's initial weights for that seed (``models.new_models``), its own
action-sampling generator (torch) and minibatch generator (numpy), optimizer state, gradient
clip, episode bookkeeping and lines (``lines.BatchedLines``); all seeds share the step count, so
one learning-rate and clip-range schedule (SB3's own, of seed 0's model) serves them all.

The arithmetic runs in JAX (``params``, ``optim``, ``actor_critic``, ``ppo``, ``a2c``): the S
networks live as stacked arrays, a rollout step is one compiled forward of all S x L lines, an
update one compiled call. The SB3 models hold the weights again after :meth:`sync_models`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np
import torch

from ...envs.env import action_space, observation_space
from . import checks, host, optim, params
from .a2c import A2CSettings, a2c_update
from .actor_critic import JittedPolicy, check_policy, compiled, exponential_noise, networks
from .lines import BatchedLines
from .models import finish_model, load_models, new_models
from .ppo import PPOSettings, minibatch_orders, ppo_update
from .rollout import RolloutBuffer, bootstrap_truncated

#: Steps of exponential draws taken from each seed's generator at once (their order is the
#: generator's either way: actor_critic.exponential_noise); bounds the draws' memory.
NOISE_CHUNK = 64

#: progress(trainer): called after each update (steps per seed: trainer.num_timesteps).
Progress = Callable[["OnPolicyTrainer"], None]


class OnPolicyTrainer:
    """S seeds of one on-policy algorithm (see the module docstring). ``models``: SB3 zips, one per
    seed, to continue training from instead of new models. ``backend`` and ``namespace``: where the
    lines run (``lines.BatchedLines``: native by default; ``"ros"``, a node of S x L lines)."""

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
        backend: str = "native",
        namespace: str | Sequence[str] | None = None,
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
            stats_window=int(params.get("stats_window_size", 100)), backend=backend, namespace=namespace,
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
        for m in self.models:
            check_policy(m.policy)
        nets = [networks(m.policy) for m in self.models]
        self.specs = params.specs_of(nets)
        self.compiled = compiled(tuple(sorted(self.specs.items())))
        #: Each seed's live torch parameters, as ``params`` trees (what sync_models writes into).
        self.trees = [params.torch_tree(n) for n in nets]
        self.params = params.stack(self.trees)
        self.optimizers = [m.policy.optimizer for m in self.models]
        self.opt_settings = optim.settings_of(self.template.policy.optimizer)
        for opt in self.optimizers[1:]:
            if optim.settings_of(opt) != self.opt_settings:
                raise ValueError(f"the models' optimizers differ: {optim.settings_of(opt)} vs {self.opt_settings}")
        self.opt_state, self.opt_steps = optim.state_from_torch(self.opt_settings, self.optimizers, self.trees)
        self.lr = self.opt_settings.lr
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
        policy = self._rollout_policy()
        buffer.reset()
        obs = self._last_obs
        truncations: list[tuple[int, np.ndarray, np.ndarray]] = []
        noise = np.empty(0)
        while not buffer.full:
            k = buffer.pos % NOISE_CHUNK
            if k == 0:  # Categorical.sample's draws of the next steps, from each seed's generator
                steps = min(NOISE_CHUNK, buffer.n_steps - buffer.pos)
                noise = exponential_noise(self.generators, (steps, lines.n_lines, lines.n_actions))
            masks = lines.action_masks() if self.masked else None  # sb3-contrib: get_action_masks(env)
            actions, values, log_probs = policy.act(obs, noise[:, k], masks)
            actions = actions.astype(np.int64)
            step = lines.step(actions)
            self.num_timesteps += lines.n_lines  # env.num_envs per seed
            if step.truncated.any():  # timeout: bootstrap from the terminal observation (SB3 issue #633)
                truncations.append((buffer.pos, step.truncated, step.terminal_obs))
            buffer.add(obs, actions, step.rewards, self._last_episode_starts, values, log_probs, masks)
            obs = step.obs
            self._last_episode_starts = step.dones
        self._last_obs = obs
        # The values of the truncated episodes' terminal observations and of the last observation,
        # in one call (the policy did not change during the rollout, so when they are computed does not matter);
        # padded to a power of two of blocks, so that few shapes are ever compiled.
        blocks = [t[2] for t in truncations] + [obs]
        blocks += [np.zeros_like(obs)] * ((1 << (len(blocks) - 1).bit_length()) - len(blocks))
        values = policy.values(np.concatenate(blocks, axis=1))
        values = values.reshape(len(self.seeds), len(blocks), -1)
        for i, (pos, truncated, _) in enumerate(truncations):
            bootstrap_truncated(buffer.rewards[pos], truncated, values[:, i], gamma)
        # The last observation's block comes right after the truncations' (the padding follows it).
        last_values = values[:, len(truncations)]
        buffer.compute_returns_and_advantage(last_values, self._last_episode_starts, gamma, self.template.gae_lambda)

    def _rollout_policy(self) -> host.HostPolicy | JittedPolicy:
        """The policy of this rollout's steps (its weights do not change during it): on the host
        where the networks allow it (host.py: one row per seed is cheaper there), else jitted."""
        if host.supported(*self.specs.values()):
            return host.HostPolicy(self.specs, self.params)
        return JittedPolicy(self.compiled, self.params)

    def train(self) -> None:
        """PPO.train, MaskablePPO.train or A2C.train on the filled buffer, for every seed."""
        t, p = self.template, self.progress_remaining
        # BaseAlgorithm._update_learning_rate
        self.lr = t.lr_schedule(p)
        data = self.buffer.flat()
        n_seeds = len(self.seeds)
        if self.algo == "a2c":
            coef = optim.coefficients(self.opt_settings, self.lr, self.opt_steps, 1, n_seeds)
            self.params, self.opt_state = a2c_update(
                self.specs, self.opt_settings, self.params, self.opt_state, coef, data,
                A2CSettings(t.normalize_advantage, t.ent_coef, t.vf_coef, t.max_grad_norm),
            )  # fmt: skip
            self.opt_steps += 1
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
        steps = t.n_epochs * -(-data.size // t.batch_size)  # minibatches: the last one possibly shorter
        coef = optim.coefficients(self.opt_settings, self.lr, self.opt_steps, steps, n_seeds)
        orders = minibatch_orders(self.np_rngs, t.n_epochs, data.size)
        self.params, self.opt_state = ppo_update(self.specs, self.opt_settings, self.params, self.opt_state, coef,
                                                 data, settings, orders)  # fmt: skip
        self.opt_steps += steps
        self.n_updates += t.n_epochs

    # --- what a run gives -----------------------------------------------------------------------------------------

    def predict(self, obs: np.ndarray, masks: np.ndarray | None = None) -> np.ndarray:
        """(S, B) actions of each seed's ``predict(obs, deterministic=True)`` for ``obs`` (S, B, obs_dim)."""
        obs = np.asarray(obs, dtype=np.float32)
        return np.asarray(
            self.compiled["predict"](self.params, obs, None if masks is None else np.asarray(masks, bool))
        )

    def weights(self) -> list[tuple[np.ndarray, list[torch.Tensor]]]:
        """Each stacked array (S, ...) with the S torch parameters it stands for (slice s: seed s's),
        in the trees' order: what the tests compare with SB3's weights."""
        arrays = params.torch_layout(self.params)
        per_seed = [jax.tree_util.tree_leaves(tree, is_leaf=torch.is_tensor) for tree in self.trees]
        return [(a, [leaves[i] for leaves in per_seed]) for i, a in enumerate(arrays)]

    def sync_models(self) -> list[Any]:
        """Each seed's SB3 model with the trained weights, optimizer state and counters written in."""
        params.write_back(self.params, self.trees)
        optim.state_to_torch(self.opt_settings, self.opt_state, self.opt_steps, self.lr, self.optimizers, self.trees)
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
