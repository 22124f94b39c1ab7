"""Batched DQN: S independent seeds of Stable-Baselines3's DQN trained at once in one process, on
S x L lines stepped in one call (``lines.BatchedLines``: native lines by default, or with
``backend="ros"`` the lines of one node, a round trip a step), each seed held to SB3 step for
step.

    engine = BatchedDQN([42, 43, 44], setup="B", variant="advanced", gamma=0.95)  # the paper's DQN
    engine.learn(100_000)
    paths = engine.save("models")  # dqn_B_advanced_seed42.zip ...: DQN.load opens each

Seed s is the run ``DQN("MlpPolicy", env, seed=s, **hyperparameters).learn(n)`` on the VecEnv of
``sorting-line-train --backend native`` (L lines, line k seeded s + k): its initial weights are
that model's (built with seed=s, so torch's default init of SB3's QNetwork); its np.random global
generator is a ``RandomState(s)`` of its own, drawn by the same calls in the same order (the
epsilon-greedy coin of ``DQN.predict``, the replay indices of ``ReplayBuffer.sample``); its action
space is seeded s as SB3 seeds it; it has its own replay buffer, Adam moments and gradient clip.
The seeds share only the arithmetic: their networks are stacked over a leading seed axis and
evaluated and updated in JAX (``q_learning``: each loss written once for one seed, vmapped over
the seeds and jitted, so each seed's gradient, clip and Adam step are its own). Every piece below
names the SB3 code it mirrors. The package's shared parts carry the rest: ``params`` and ``optim``
(the stacked weights, torch's Adam and clip, the optimizer state to and from SB3's), ``lines``
(the S x L lines as each seed's VecEnv), ``models`` (the spaces SB3 builds a model on);
``replay`` is DQN's own (per-seed buffers).

What costs a call: a rollout step is one jitted forward for all seeds (none when every seed
explores) and one step of the native lines; a ``train(gradient_steps)`` is one jitted call for
all its steps (the replay indices of all of them drawn first, by each seed's generator in SB3's
order); the epsilon coins of a rollout are drawn in one call per seed (``RandomState.rand(n)``
gives the n numbers n calls of ``rand()`` give).

Each seed is saved as the SB3 ``.zip`` SB3 would write (the per-seed model with the trained
weights, optimizer state and counters, ``model.save``), and ``BatchedDQN.from_models`` starts
from saved SB3 DQN files to continue training them. Options the engine does not implement fail
at construction, by name (:func:`check_hyperparameters`).
"""

from __future__ import annotations

import copy
import inspect
import random
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np
import torch
from stable_baselines3 import DQN
from stable_baselines3.common.buffers import ReplayBuffer
from torch import nn

from ...envs.env import action_space, observation_space
from ...line.vocabulary import check_setup, check_variant
from . import optim
from .checks import available_memory, check_seeds
from .lines import BatchedLines, check_backend
from .models import SeedModel, check_model_file, new_models, spaces_vec_env
from .params import specs_of, stack, torch_tree, write_back
from .q_learning import QLearning
from .replay import BatchedReplayBuffer, ReplaySamples

#: DQN's constructor arguments and SB3's defaults (DQN.__init__).
SB3_DEFAULTS = {
    name: p.default
    for name, p in inspect.signature(DQN.__init__).parameters.items()
    if p.default is not inspect.Parameter.empty
}
#: Arguments the engine sets itself: the seeds are the engine's, the device is the CPU.
ENGINE_OWNED = ("policy", "env", "seed", "_init_setup_model")
#: Keys of policy_kwargs the engine implements (DQNPolicy.__init__), and of Adam's optimizer_kwargs
#: (elementwise, so one Adam over the stacked weights is each seed's own Adam).
POLICY_KEYS = ("net_arch", "activation_fn", "optimizer_class", "optimizer_kwargs", "normalize_images")
ADAM_KEYS = ("betas", "eps", "weight_decay", "amsgrad")
#: Elementwise activations: applied to the stacked activations they act on each seed alone.
ACTIVATIONS = (nn.ReLU, nn.Tanh, nn.ELU, nn.LeakyReLU, nn.SiLU, nn.GELU)


def _refuse(key: str, value: Any, allowed: str) -> ValueError:
    return ValueError(f"{key} = {value!r} is not implemented by the batched DQN engine: allowed {allowed}")


def check_hyperparameters(kwargs: dict[str, Any]) -> dict[str, Any]:
    """SB3's DQN defaults updated by ``kwargs``, or a ValueError naming the first key or value the
    engine does not implement (or that is not DQN's)."""
    for key in kwargs:
        if key in ENGINE_OWNED:
            raise ValueError(f"{key} is set by the batched engine (the seeds are its `seeds` argument)")
        if key not in SB3_DEFAULTS:
            raise ValueError(f"{key}: not a hyperparameter of DQN (allowed: {', '.join(sorted(SB3_DEFAULTS))})")
    p = {k: v for k, v in SB3_DEFAULTS.items() if k not in ENGINE_OWNED} | kwargs
    fixed = {"optimize_memory_usage": False, "n_steps": 1, "tensorboard_log": None, "verbose": 0}
    for key, value in fixed.items():
        if p[key] != value:
            raise _refuse(key, p[key], f"{value!r} (SB3's default)")
    if p["replay_buffer_class"] not in (None, ReplayBuffer):
        raise _refuse("replay_buffer_class", p["replay_buffer_class"], "None or ReplayBuffer")
    extra = set(p["replay_buffer_kwargs"] or {}) - {"handle_timeout_termination"}
    if extra:
        raise _refuse("replay_buffer_kwargs", p["replay_buffer_kwargs"], "only handle_timeout_termination")
    if p["device"] not in ("auto", "cpu"):
        raise _refuse("device", p["device"], "'auto' or 'cpu' (the engine runs on the CPU)")
    train_freq = p["train_freq"]
    if isinstance(train_freq, tuple | list):
        if len(train_freq) != 2 or train_freq[1] != "step":
            raise _refuse("train_freq", train_freq, "an integer or (n, 'step'): the seeds step together")
        train_freq = train_freq[0]
    integers = {"train_freq": (train_freq, 1), "gradient_steps": (p["gradient_steps"], -1)}
    integers |= {k: (p[k], low) for k, low in (("buffer_size", 1), ("learning_starts", 0), ("batch_size", 1))}
    integers |= {k: (p[k], 1) for k in ("target_update_interval", "stats_window_size")}
    for key, (value, low) in integers.items():
        if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < low:
            raise ValueError(f"{key} = {value!r} is not valid: allowed an integer >= {low}")
    for key in ("tau", "gamma", "exploration_fraction", "exploration_initial_eps", "exploration_final_eps"):
        if not isinstance(p[key], int | float) or not 0.0 <= p[key] <= 1.0:
            raise ValueError(f"{key} = {p[key]!r} is not valid: allowed a number in [0, 1]")
    if not isinstance(p["max_grad_norm"], int | float) or not p["max_grad_norm"] > 0:
        raise ValueError(f"max_grad_norm = {p['max_grad_norm']!r} is not valid: allowed a number > 0")
    lr = p["learning_rate"]
    if not callable(lr) and (not isinstance(lr, int | float) or not lr > 0):
        raise ValueError(f"learning_rate = {lr!r} is not valid: allowed a number > 0 or a schedule")
    _check_policy_kwargs(p["policy_kwargs"] or {})
    return p | {"train_freq": int(train_freq)}


def _check_policy_kwargs(kw: dict[str, Any]) -> None:
    extra = sorted(set(kw) - set(POLICY_KEYS))
    if extra:
        raise _refuse(f"policy_kwargs[{extra[0]!r}]", kw[extra[0]], f"only the keys {', '.join(POLICY_KEYS)}")
    arch = kw.get("net_arch", [64, 64])
    if not isinstance(arch, list) or not all(isinstance(n, int) and n > 0 for n in arch):
        raise _refuse("policy_kwargs['net_arch']", arch, "a list of layer widths such as [64, 64]")
    if kw.get("activation_fn", nn.ReLU) not in ACTIVATIONS:
        allowed = ", ".join(a.__name__ for a in ACTIVATIONS)
        raise _refuse("policy_kwargs['activation_fn']", kw["activation_fn"], f"one of nn.{allowed}")
    if kw.get("optimizer_class", torch.optim.Adam) is not torch.optim.Adam:
        raise _refuse("policy_kwargs['optimizer_class']", kw["optimizer_class"], "torch.optim.Adam (SB3's)")
    extra = sorted(set(kw.get("optimizer_kwargs") or {}) - set(ADAM_KEYS))
    if extra:
        raise _refuse(f"optimizer_kwargs[{extra[0]!r}]", kw["optimizer_kwargs"][extra[0]], ", ".join(ADAM_KEYS))


def spaces_env(variant: str, n_envs: int):
    """A VecEnv of the line's spaces (and no line) for SB3 to build or load a seed's model on."""
    return spaces_vec_env(observation_space(variant), action_space(variant), n_envs)


def load_models(paths: Sequence[str | Path], seeds: Sequence[int | None], variant: str, n_envs: int) -> list[SeedModel]:
    """SB3's ``DQN.load(path, env, seed=s)`` for each path (without ``seed`` where none is given:
    SB3's load reseeds with the saved seed then), refused with the path named when a file is not a
    DQN model of this line's spaces; numpy's state right after each load, the process's generators
    left as they were.

    Not ``models.load_models`` (the on-policy loader): DQN's random actions come from the model's
    action space, which SB3's load seeds with the seed it is given (set_random_seed), and its
    epsilon coin from the np.random state that seeding leaves; that loader loads without a seed and
    starts the generators from fresh ones, and requires a seed per model."""
    loaded = []
    saved = random.getstate(), np.random.get_state(), torch.get_rng_state()
    try:
        for path, seed in zip(paths, seeds, strict=True):
            check_model_file(path, "dqn", (observation_space(variant), action_space(variant)))
            extra = {} if seed is None else {"seed": seed}
            model = DQN.load(path, env=spaces_env(variant, n_envs), device="cpu", **extra)
            loaded.append(SeedModel(model, torch.get_rng_state(), np.random.get_state()))
    finally:
        random.setstate(saved[0])
        np.random.set_state(saved[1])
        torch.set_rng_state(saved[2])
    return loaded


class BatchedDQN:
    """S seeds of SB3's DQN on ``n_envs`` lines each (see the module docstring; ``backend`` and
    ``namespace`` as ``lines.BatchedLines`` takes them). ``hyperparameters`` are DQN's constructor
    arguments (SB3's defaults for the rest); the seeds share them. The counters are SB3's names,
    one value for all seeds: they step together."""

    def __init__(
        self,
        seeds: Sequence[int],
        *,
        setup: str = "A",
        variant: str = "basic",
        n_envs: int = 1,
        episode_steps: int = 250,
        backend: str = "native",
        namespace: str | Sequence[str] | None = None,
        **hyperparameters: Any,
    ):
        seeds = check_seeds(seeds)
        self._configure(setup, variant, n_envs, episode_steps, check_hyperparameters(hyperparameters))
        self._where(backend, namespace, len(seeds))
        sb3_kwargs = {k: v for k, v in hyperparameters.items() if k != "device"} | {"device": "cpu"}
        spaces = (observation_space(variant), action_space(variant))
        self._adopt(seeds, new_models("dqn", seeds, sb3_kwargs, spaces, n_envs))

    @classmethod
    def from_models(
        cls,
        paths: Sequence[str | Path],
        seeds: Sequence[int] | None = None,
        *,
        setup: str = "A",
        variant: str = "basic",
        n_envs: int = 1,
        episode_steps: int = 250,
        backend: str = "native",
        namespace: str | Sequence[str] | None = None,
    ) -> BatchedDQN:
        """Continues SB3 DQN models (``.zip``, one per seed) as SB3's ``DQN.load(path, env,
        seed=s).learn(...)`` would: their weights, Adam state, ``_n_calls``/``_n_updates`` and
        hyperparameters (which must agree), an empty replay buffer (SB3 saves none), the lines and
        generators seeded by ``seeds`` (default: each model's saved seed, as SB3's load does)."""
        given: Sequence[int | None] = [None] * len(paths) if seeds is None else check_seeds(seeds)
        if len(given) != len(paths):
            raise ValueError(f"{len(paths)} models and {len(given)} seeds: allowed one seed per model")
        loaded = load_models(paths, given, variant, n_envs)
        seeds = check_seeds([sm.model.seed if s is None else s for sm, s in zip(loaded, given, strict=True)])
        params = [loaded_hyperparameters(sm.model) for sm in loaded]
        for path, p in zip(paths, params, strict=True):
            diff = sorted(k for k in p if comparable(p[k]) != comparable(params[0][k]))
            if diff:
                raise ValueError(
                    f"{path}: hyperparameters {diff} differ from {paths[0]}'s: allowed models of one setting"
                )
        engine = cls.__new__(cls)
        train_freq = params[0]["train_freq"]  # a TrainFreq once SB3 has built the model
        loaded_params = {**params[0], "train_freq": (train_freq.frequency, train_freq.unit.value)}
        engine._configure(setup, variant, n_envs, episode_steps, check_hyperparameters(loaded_params))
        engine._where(backend, namespace, len(seeds))
        engine._adopt(seeds, loaded)
        return engine

    def _configure(self, setup: str, variant: str, n_envs: int, episode_steps: int, params: dict[str, Any]) -> None:
        check_setup(setup)
        check_variant(variant)
        for key, value in (("n_envs", n_envs), ("episode_steps", episode_steps)):
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{key} = {value!r} is not valid: allowed an integer >= 1")
        self.setup, self.variant, self.n_envs, self.episode_steps = setup, variant, n_envs, episode_steps
        self.params = params
        # SB3's attribute names, for the loop below to read as SB3's does.
        self.learning_starts, self.batch_size = params["learning_starts"], params["batch_size"]
        self.tau, self.gamma, self.max_grad_norm = params["tau"], params["gamma"], params["max_grad_norm"]
        self.train_freq, self.gradient_steps = params["train_freq"], params["gradient_steps"]
        self.target_update_interval = params["target_update_interval"]

    def _where(self, backend: str, namespace: str | Sequence[str] | None, n_seeds: int) -> None:
        """Where the lines will run, checked now: ``learn`` builds them, after the models."""
        check_backend(backend, namespace, n_seeds, self.n_envs, None)
        self.backend, self.namespace = backend, namespace

    def _adopt(self, seeds: list[int], built: list[SeedModel]) -> None:
        """Takes over the SB3 models: their weights stacked, their optimizers' state, generators and
        counters (equal across seeds: a fresh build, or models checked to agree)."""
        self.seeds, self.models = seeds, [sm.model for sm in built]
        self.np_rngs = []
        for sm in built:
            # SB3 draws its epsilon coin and its replay indices from np.random (DQN.predict,
            # BaseBuffer.sample): seed s's run gets a generator of its own in the state SB3 left it.
            rng = np.random.RandomState()
            rng.set_state(sm.numpy_state)
            self.np_rngs.append(rng)
        # set_random_seed seeded the model's action space with s: warm-up and random actions come from it.
        self.action_spaces = [copy.deepcopy(m.action_space) for m in self.models]
        policies = [m.policy for m in self.models]
        # The seeds' QNetworks (q_net.q_net, q_net_target.q_net: SB3's create_mlp) as stacked JAX
        # trees; the torch trees are where the weights go back to when the models are written.
        self._q_trees = [torch_tree({"q_net": p.q_net.q_net}) for p in policies]
        self._target_trees = [torch_tree({"q_net": p.q_net_target.q_net}) for p in policies]
        spec = specs_of(
            [{"q_net": p.q_net.q_net} for p in policies] + [{"q_net": p.q_net_target.q_net} for p in policies]
        )
        self.q_net, self.q_net_target = stack(self._q_trees), stack(self._target_trees)
        # DQNPolicy's optimizer (Adam over q_net.parameters()), its state and step count per seed.
        settings = [optim.settings_of(p.optimizer) for p in policies]
        if any(st != settings[0] for st in settings):
            raise ValueError(f"the models' optimizers differ ({settings[0]} vs others): allowed one setting")
        self.optimizer_settings, self._learning_rate = settings[0], settings[0].lr
        self.optimizer_state, self._optimizer_steps = optim.state_from_torch(
            settings[0], [p.optimizer for p in policies], self._q_trees
        )
        self.q_learning = QLearning(spec["q_net"], settings[0], self.gamma, self.max_grad_norm)
        first = self.models[0]
        counters = ("num_timesteps", "_total_timesteps", "_n_calls", "_n_updates")
        if any(getattr(m, c) != getattr(first, c) for m in self.models for c in counters):
            raise ValueError("the models have trained different numbers of steps: allowed models trained alike")
        self.lr_schedule, self.exploration_schedule = first.lr_schedule, first.exploration_schedule
        self._n_calls, self._n_updates = first._n_calls, first._n_updates
        self.exploration_rate, self._current_progress_remaining = first.exploration_rate, 1.0
        self.num_timesteps, self._total_timesteps = first.num_timesteps, first._total_timesteps
        self._num_timesteps_at_start = first.num_timesteps
        self._episode_num = np.zeros(len(seeds), dtype=np.int64)
        self._last_obs: np.ndarray | None = None
        self._last_original_obs: np.ndarray | None = None
        self.lines: BatchedLines | None = None
        self.replay: BatchedReplayBuffer | None = None

    @property
    def n_seeds(self) -> int:
        return len(self.seeds)

    # ---- the training loop: OffPolicyAlgorithm.learn / collect_rollouts, for all seeds at once ----

    def learn(
        self,
        total_timesteps: int,
        callback: Callable[[BatchedDQN], bool | None] | None = None,
        reset_num_timesteps: bool = True,
    ) -> BatchedDQN:
        """Trains every seed for ``total_timesteps`` steps of its L lines, as SB3's ``learn``.
        ``reset_num_timesteps=False`` continues the last ``learn`` (its lines, counters and
        buffers), as SB3's does. ``callback(engine)`` runs after each rollout; False stops."""
        if not isinstance(total_timesteps, int) or isinstance(total_timesteps, bool) or total_timesteps < 1:
            raise ValueError(f"total_timesteps = {total_timesteps!r} is not valid: allowed an integer >= 1")
        if reset_num_timesteps and self.lines is not None:
            # SB3 would reset its VecEnv again, which then draws its line seeds from the lines'
            # generators rather than from the seeds: not mirrored, so refused rather than different.
            raise ValueError(
                "learn(reset_num_timesteps=True) a second time is not implemented by the batched DQN engine: "
                "allowed learn(..., reset_num_timesteps=False), which continues the training as SB3's does"
            )
        total_timesteps = self._setup_learn(total_timesteps, reset_num_timesteps)
        # OffPolicyAlgorithm.learn: rollouts of train_freq vector steps, then gradient steps once
        # past learning_starts (gradient_steps -1: as many as transitions collected, per seed).
        while self.num_timesteps < total_timesteps:
            steps = self._steps_after_rollout()
            drawn = self._collect_rollout(steps)
            if steps > 0:
                self.train(steps, self.batch_size, drawn)
            if callback is not None and callback(self) is False:
                break
        return self

    def _steps_after_rollout(self) -> int:
        """The gradient steps that follow the coming rollout (0: none): collect_rollouts always
        takes its train_freq vector steps, so whether OffPolicyAlgorithm.learn then trains is
        known before it starts."""
        after = self.num_timesteps + self.train_freq * self.n_envs
        if not after > self.learning_starts:  # (after > 0 always)
            return 0
        return self.gradient_steps if self.gradient_steps >= 0 else self.train_freq * self.n_envs

    def _setup_learn(self, total_timesteps: int, reset_num_timesteps: bool) -> int:
        """BaseAlgorithm._setup_learn: the counters from 0 (or the total counted on from them), the
        lines reset where there is no last observation (line k of seed s from seed s + k,
        VecEnv.seed); OffPolicyAlgorithm._setup_model's replay buffer. Returns the total."""
        if reset_num_timesteps:
            self.num_timesteps = 0
            self._episode_num[:] = 0
        else:
            total_timesteps += self.num_timesteps
        self._total_timesteps, self._num_timesteps_at_start = total_timesteps, self.num_timesteps
        if self.lines is None:
            self.lines = BatchedLines(
                self.seeds,
                self.n_envs,
                setup=self.setup,
                variant=self.variant,
                episode_steps=self.episode_steps,
                stats_window=self.params["stats_window_size"],
                backend=self.backend,
                namespace=self.namespace,
            )
        if self._last_obs is None:
            self._last_obs = self.lines.reset()
        if self.replay is None:
            handle = (self.params["replay_buffer_kwargs"] or {}).get("handle_timeout_termination", True)
            self.replay = new_replay(
                self.n_seeds, self.params["buffer_size"], self._last_obs.shape[-1], self.n_envs, handle, total_timesteps
            )
        return total_timesteps

    def _collect_rollout(self, gradient_steps: int = 0) -> np.ndarray | None:
        """OffPolicyAlgorithm.collect_rollouts with TrainFreq(train_freq, STEP). Returns the replay
        indices of the ``gradient_steps`` that follow it (``BatchedReplayBuffer.draw``), or None."""
        assert self.lines is not None and self.replay is not None and self._last_obs is not None
        # DQN.predict's coin is one np.random.rand() per seed and step past the warm-up; a rollout's
        # coins come first in each seed's generator (its replay indices after them), so one call
        # per seed draws them all (rand(n) gives the numbers of n calls of rand()).
        starts = self.num_timesteps + self.n_envs * np.arange(self.train_freq)
        n_coins = int((starts >= self.learning_starts).sum())
        coins = np.stack([rng.rand(n_coins) for rng in self.np_rngs]) if n_coins else None
        # Then the replay indices of the train() after the rollout, drawn now: the draws depend on
        # nothing the rollout does (the bound is the buffer's after train_freq adds; nothing else
        # draws from these generators in between), and drawing them here overlaps the previous
        # gradient step, which JAX still runs while the first predict below waits for its weights.
        drawn = None
        if gradient_steps > 0:
            bound = self.replay.upper_bound(self.train_freq)
            drawn = self.replay.draw(gradient_steps, self.batch_size, self.np_rngs, bound)
        for k in range(self.train_freq):
            if self.num_timesteps < self.learning_starts:
                # OffPolicyAlgorithm._sample_action, warm-up: action_space.sample() per line.
                actions = np.array([[space.sample() for _ in range(self.n_envs)] for space in self.action_spaces])
            else:
                assert coins is not None
                actions = self._sample_actions(coins[:, k - (self.train_freq - n_coins)])
            step = self.lines.step(actions)
            self.num_timesteps += self.n_envs
            # _store_transition: next_obs is the terminal observation where an episode ended
            # (the step's own observation); every end is a time limit here (TimeLimit.truncated).
            self.replay.add(self._last_obs, step.terminal_obs, actions, step.rewards, step.dones, step.truncated)
            self._last_original_obs, self._last_obs = self._last_obs, step.obs
            # BaseAlgorithm._update_current_progress_remaining
            self._current_progress_remaining = 1.0 - float(self.num_timesteps) / float(self._total_timesteps)
            self._on_step()
            self._episode_num += step.dones.sum(axis=1)
        return drawn

    def _sample_actions(self, coins: np.ndarray) -> np.ndarray:
        """(S, L) actions past the warm-up: DQN.predict(deterministic=False), ``coins`` (S,) the
        seeds' draws of its ``np.random.rand()``."""
        assert self._last_obs is not None
        # DQN.predict draws ONE number per call (per seed here, from that seed's np.random) and
        # takes random actions for all L lines of the call, or greedy ones for all of them.
        explore = coins < self.exploration_rate
        if explore.all():
            actions = np.empty((self.n_seeds, self.n_envs), dtype=np.int64)
        else:
            actions = self.predict(self._last_obs).astype(np.int64)
        for s in np.flatnonzero(explore):
            actions[s] = [self.action_spaces[s].sample() for _ in range(self.n_envs)]
        return actions

    def _on_step(self) -> None:
        """DQN._on_step: the target network every max(target_update_interval // n_envs, 1) vector
        steps (polyak_update, tau), and the exploration rate from its LinearSchedule."""
        self._n_calls += 1
        if self._n_calls % max(self.target_update_interval // self.n_envs, 1) == 0:
            self.q_net_target = self.q_learning.polyak(self.q_net, self.q_net_target, self.tau)
            # (SB3 also copies batch-norm running stats here; the MLP has none.)
        self.exploration_rate = self.exploration_schedule(self._current_progress_remaining)

    # ---- the update: DQN.train ----

    def train(self, gradient_steps: int, batch_size: int, drawn: np.ndarray | None = None) -> jax.Array:
        """DQN.train: the learning rate from its schedule, then ``gradient_steps`` steps, each on a
        fresh batch of each seed's own buffer (at the indices ``drawn`` for them, else drawn now).
        Returns the seeds' mean losses (S,), computed once the steps are: ``np.asarray`` waits."""
        assert self.replay is not None
        # BaseAlgorithm._update_learning_rate: the optimizer's lr for all the steps of this call.
        self._learning_rate = self.lr_schedule(self._current_progress_remaining)
        # replay_buffer.sample once per gradient step, in that order: all drawn before the steps
        # (nothing else draws from the seeds' generators, nor writes the buffers, in between).
        if drawn is None:
            batches = self.replay.sample(gradient_steps, batch_size, self.np_rngs)
        else:
            batches = self.replay.gather(drawn)
        losses = self._gradient_steps(batches)
        self._n_updates += gradient_steps
        return losses.mean(axis=1)  # (a JAX array: learn() does not wait for it)

    def gradient_step(self, batch: ReplaySamples) -> np.ndarray:
        """One DQN gradient step of every seed on its batch (arrays or tensors with a leading seed
        axis, as SB3's ReplayBufferSamples: actions, dones, rewards (S, B, 1) or (S, B)), at the
        optimizer's current learning rate: DQN.train's loop body. Returns each seed's loss (S,)."""
        arrays = [np.asarray(a) for a in batch]
        arrays = [a[..., 0] if a.ndim == 3 and k not in (0, 2) else a for k, a in enumerate(arrays)]
        return np.asarray(self._gradient_steps(ReplaySamples(*(a[:, None] for a in arrays)))[:, 0])

    def _gradient_steps(self, batches: ReplaySamples) -> jax.Array:
        """The steps of ``batches`` (S, G, B, ...) at ``self._learning_rate``, dispatched (JAX runs
        them while the caller goes on: the next rollout's first predict waits for the weights);
        the losses (S, G)."""
        n = batches.actions.shape[1]
        coefs = optim.coefficients(self.optimizer_settings, self._learning_rate, self._optimizer_steps, n, self.n_seeds)
        self.q_net, self.optimizer_state, losses = self.q_learning.train(
            self.q_net, self.optimizer_state, self.q_net_target, batches, coefs
        )
        self._optimizer_steps += n
        return losses

    def predict(self, observations: np.ndarray) -> np.ndarray:
        """Greedy actions (S, N) for observations (S, N, obs_dim): each seed's
        ``predict(obs, deterministic=True)`` (QNetwork._predict: argmax of the Q-values)."""
        obs = np.asarray(observations, dtype=np.float32)
        if obs.ndim != 3 or obs.shape[0] != self.n_seeds:
            raise ValueError(f"observations of shape {obs.shape}: allowed (seeds={self.n_seeds}, N, obs_dim)")
        return self.q_learning.act(self.q_net, obs)

    # ---- saving: each seed as the SB3 model SB3 would have written ----

    def sb3_models(self) -> list[DQN]:
        """The seeds' SB3 models with the engine's state written into them: weights of q_net and
        q_net_target, Adam's state, and what SB3's learn leaves on a model (counters, schedules'
        progress, last observations, episode statistics), so that ``save`` writes SB3's zip."""
        write_back(self.q_net, self._q_trees)
        write_back(self.q_net_target, self._target_trees)
        optim.state_to_torch(
            self.optimizer_settings,
            self.optimizer_state,
            self._optimizer_steps,
            self._learning_rate,
            [m.policy.optimizer for m in self.models],
            self._q_trees,
        )
        for s, model in enumerate(self.models):
            model.num_timesteps, model._total_timesteps = self.num_timesteps, self._total_timesteps
            model._num_timesteps_at_start = self._num_timesteps_at_start
            model._n_calls, model._n_updates = self._n_calls, self._n_updates
            model._episode_num = int(self._episode_num[s])
            model.exploration_rate = self.exploration_rate
            model._current_progress_remaining = self._current_progress_remaining
            if self._last_obs is not None and self._last_original_obs is not None:
                model._last_obs = self._last_obs[s].copy()
                # _store_transition keeps the observation acted on last; _setup_learn's episode starts
                # (all True) are left as they are by an off-policy rollout.
                model._last_original_obs = self._last_original_obs[s].copy()
                model._last_episode_starts = np.ones(self.n_envs, dtype=bool)
            if self.lines is not None:
                model.ep_info_buffer = deque(self.lines.episodes[s], maxlen=model._stats_window_size)
                model.ep_success_buffer = deque(maxlen=model._stats_window_size)
        return self.models

    def save(self, out: str | Path, stem: str = "dqn_{setup}_{variant}_seed{seed}") -> list[Path]:
        """Writes each seed's SB3 zip into ``out`` (``stem`` names it, sorting-line-train's names
        by default); returns the paths in seed order."""
        (out := Path(out)).mkdir(parents=True, exist_ok=True)
        paths = []
        for seed, model in zip(self.seeds, self.sb3_models(), strict=True):
            path = out / (stem.format(setup=self.setup, variant=self.variant, seed=seed) + ".zip")
            model.save(path)
            paths.append(path)
        return paths

    def close(self) -> None:
        if self.lines is not None:
            self.lines.close()
            self.lines = None


#: The hyperparameters a loaded model holds as attributes of those names (BaseAlgorithm, DQN).
_LOADED_KEYS = (
    "learning_rate",
    "buffer_size",
    "learning_starts",
    "batch_size",
    "tau",
    "gamma",
    "train_freq",
    "gradient_steps",
    "replay_buffer_kwargs",
    "optimize_memory_usage",
    "n_steps",
    "target_update_interval",
    "exploration_fraction",
    "exploration_initial_eps",
    "exploration_final_eps",
    "max_grad_norm",
    "policy_kwargs",
)


def loaded_hyperparameters(model: DQN) -> dict[str, Any]:
    """A loaded model's hyperparameters, as DQN's constructor arguments."""
    return {k: getattr(model, k) for k in _LOADED_KEYS} | {"stats_window_size": model._stats_window_size}


def comparable(value: Any) -> Any:
    """A value two models' hyperparameters can be compared by: a schedule by its repr where it has
    one of its own (SB3's schedules do), a function by its code; anything else as it is."""
    if callable(value) and not isinstance(value, type):
        if type(value).__repr__ is not object.__repr__ and not inspect.isfunction(value):
            return repr(value)
        code = getattr(value, "__code__", None)
        return code.co_code if code is not None else id(value)
    return value


def new_replay(
    seeds: int, buffer_size: int, obs_dim: int, n_envs: int, handle_timeouts: bool, total_timesteps: int
) -> BatchedReplayBuffer:
    """The seeds' replay buffers, or a MemoryError saying what they would take: the rows a run of
    ``total_timesteps`` writes (up to buffer_size) for every seed, against the memory available now
    (np.zeros leaves the rows never written untouched, as in SB3)."""
    rows = min(max(buffer_size // n_envs, 1), -(-total_timesteps // n_envs) + 1)
    need = seeds * rows * n_envs * BatchedReplayBuffer.bytes_per_transition(obs_dim)
    have = available_memory()
    message = (
        f"the replay buffers of {seeds} seeds x {n_envs} lines (buffer_size {buffer_size}) for {total_timesteps} "
        f"steps take {need / 1e9:.2f} GB, and {'?' if have is None else f'{have / 1e9:.2f}'} GB are available: "
        f"train fewer seeds at once (about {max(1, (have or need) * seeds // max(need, 1))}) or a smaller buffer_size"
    )
    if have is not None and need > have:
        raise MemoryError(message)
    try:
        return BatchedReplayBuffer(seeds, buffer_size, obs_dim, n_envs, handle_timeouts)
    except MemoryError:  # the whole buffer's address space, which SB3 reserves too
        raise MemoryError(message) from None
