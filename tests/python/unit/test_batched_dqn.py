"""The batched trainer's DQN (training/batched/dqn.py) held to SB3's DQN step for step, for every
seed of a batch of several seeds:

- one gradient step and its target update, from the same weights and the same replay batch, give
  SB3's q_net and q_net_target to 1e-5 relative (SB3's own ``train(gradient_steps, batch_size)``
  is the reference, its replay buffer's ``sample`` handing it the engine's batch), with the
  gradient clip biting for one seed and not for another;
- a short training on native lines (warm-up, the epsilon-greedy schedule, train_freq and
  gradient_steps, target updates every target_update_interval // n_envs calls, truncated episodes
  bootstrapped from their final observation, a replay buffer that wraps, a second ``learn`` with
  reset_num_timesteps=False) equals SB3's ``learn`` calls with the same seed: the same transitions
  in the replay buffer, the same exploration rate and target updates at each step, the same weights;
- a saved seed loads with DQN.load, whose ``predict(deterministic=True)`` gives the engine's
  actions, and continues in the engine as in SB3 (``DQN.load(...).learn``);
- a bad hyperparameter, seed or model file fails at construction, naming it; so does a second
  ``learn`` that would reset the lines (not mirrored).

Native lines in this process: no node, no DDS. About 25 s on a busy machine.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from support.training_stack import MISSING

if MISSING:
    pytest.skip(f"needs the training stack (setup.sh --train); missing {', '.join(MISSING)}", allow_module_level=True)

import jax  # noqa: E402
import torch  # noqa: E402
from stable_baselines3 import DQN, PPO  # noqa: E402
from stable_baselines3.common.buffers import ReplayBufferSamples  # noqa: E402
from stable_baselines3.common.logger import Logger  # noqa: E402

from sorting_line_gym.training.batched.dqn import BatchedDQN, spaces_env  # noqa: E402
from sorting_line_gym.training.batched.replay import BatchedReplayBuffer, ReplaySamples  # noqa: E402
from sorting_line_gym.training.train import make_training_env  # noqa: E402

SEEDS = [3, 4, 11]
LINE = dict(setup="B", variant="advanced")
#: A short run that passes through every part of the loop: warm-up, the exploration schedule,
#: two gradient steps per rollout of 2 vector steps, target updates every 60 // 2 calls, 50-step
#: episodes (truncated), and a buffer of 150 rows x 2 lines that wraps.
SHORT = dict(
    gamma=0.95,
    learning_starts=40,
    train_freq=2,
    gradient_steps=2,
    target_update_interval=60,
    exploration_fraction=0.4,
    buffer_size=300,
    batch_size=16,
    learning_rate=1e-3,
)
LINES, EPISODE, STEPS = 2, 50, 600


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def relative_error(ours: dict[str, torch.Tensor], theirs: dict[str, torch.Tensor]) -> float:
    assert ours.keys() == theirs.keys()
    return max(float((ours[k] - theirs[k]).abs().max() / theirs[k].abs().max().clamp_min(1e-12)) for k in ours)


def quiet(model: DQN) -> DQN:
    """``train()`` outside ``learn()`` records to a logger; one that writes nowhere."""
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def engine_nets(engine: BatchedDQN, s: int) -> tuple[dict, dict]:
    policy = engine.sb3_models()[s].policy
    return policy.q_net.state_dict(), policy.q_net_target.state_dict()


def batches(n_seeds: int, batch_size: int, rng: np.random.Generator) -> tuple[list, list]:
    """Two replay batches of every seed with terminal and non-terminal transitions, stacked over the
    seeds (the engine's) and per seed (SB3's). Seed 0's rewards are large (its gradient norm is
    clipped), the last seed's tiny (not clipped)."""
    out = []
    for _ in range(2):
        scale = np.geomspace(50.0, 0.01, n_seeds)[:, None, None]
        out.append(
            [
                torch.from_numpy(rng.uniform(0, 2, (n_seeds, batch_size, 2)).astype(np.float32)),
                torch.from_numpy(rng.integers(0, 30, (n_seeds, batch_size, 1))),
                torch.from_numpy(rng.uniform(0, 2, (n_seeds, batch_size, 2)).astype(np.float32)),
                torch.from_numpy((rng.random((n_seeds, batch_size, 1)) < 0.3).astype(np.float32)),
                torch.from_numpy((rng.normal(size=(n_seeds, batch_size, 1)) * scale).astype(np.float32)),
            ]
        )
    return [[ReplayBufferSamples(*(t[s] for t in b)) for b in out] for s in range(n_seeds)], out


def test_gradient_steps_and_target_update_equal_sb3_for_every_seed():
    # max_grad_norm 0.3: the gradient norms of the first two seeds are ~0.4-0.55 (clipped), the last one's ~0.1.
    params = dict(tau=0.5, target_update_interval=1, max_grad_norm=0.3, learning_rate=3e-3, gamma=0.9)
    engine = BatchedDQN(SEEDS, **LINE, **params)
    per_seed, stacked = batches(len(SEEDS), 32, np.random.default_rng(0))
    references = []
    for s, seed in enumerate(SEEDS):
        reference = quiet(DQN("MlpPolicy", spaces_env("advanced", 1), seed=seed, device="cpu", **params))
        ours = engine_nets(engine, s)
        assert relative_error(ours[0], reference.policy.q_net.state_dict()) == 0.0, "not SB3's initial weights"
        feed = iter(per_seed[s])
        reference.replay_buffer.sample = lambda batch_size, env=None, feed=feed: next(feed)  # type: ignore[method-assign]
        reference.train(gradient_steps=2, batch_size=32)
        reference._on_step()  # target_update_interval 1: a polyak update with tau 0.5
        references.append(reference)
    for batch in stacked:
        engine.gradient_step(ReplaySamples(*batch))
    engine._on_step()
    for s, reference in enumerate(references):
        q_net, q_net_target = engine_nets(engine, s)
        assert relative_error(q_net, reference.policy.q_net.state_dict()) < 1e-5, f"seed {SEEDS[s]}: q_net"
        assert relative_error(q_net_target, reference.policy.q_net_target.state_dict()) < 1e-5, f"seed {SEEDS[s]}"
        assert engine.exploration_rate == reference.exploration_rate


def traced(algorithm, target_parameters, n_seeds: int = 1) -> list[tuple[int, float, list[bool]]]:
    """Wraps ``algorithm._on_step`` to record, at each vector step, the timesteps, the exploration
    rate it sets and, per seed, whether the target network changed (the engine's parameters have a
    leading seed axis of ``n_seeds``; SB3's are one seed's)."""
    original, trace = algorithm._on_step, []

    def on_step():
        before = [p.detach().clone() for p in target_parameters()]
        original()
        after = list(target_parameters())
        if n_seeds == 1 and not isinstance(algorithm, BatchedDQN):
            before, after = [b[None] for b in before], [a[None] for a in after]
        changed = torch.stack([(b != a).flatten(1).any(1) for b, a in zip(before, after, strict=True)]).any(0)
        trace.append((algorithm.num_timesteps, algorithm.exploration_rate, changed.tolist()))

    algorithm._on_step = on_step
    return trace


@pytest.fixture(scope="module")
def short_runs(tmp_path_factory):
    """The engine's short training of two seeds and SB3's of each, on the same native lines."""
    seeds = SEEDS[:2]  # one compiled chunk of seeds: the code every seed runs in any batch (seed_axis.py)
    engine = BatchedDQN(seeds, **LINE, n_envs=LINES, episode_steps=EPISODE, **SHORT)
    engine_trace = traced(
        engine, lambda: [torch.from_numpy(np.array(a)) for a in jax.tree.leaves(engine.q_net_target)], len(seeds)
    )
    # Two learn() calls, the second continuing the first (reset_num_timesteps=False), on both sides.
    engine.learn(STEPS - 200).learn(200, reset_num_timesteps=False)
    references = []
    for seed in seeds:
        env = make_training_env(LINE["setup"], LINE["variant"], LINES, EPISODE, backend="native")
        model = DQN("MlpPolicy", env, seed=seed, device="cpu", **SHORT)
        trace = traced(model, model.q_net_target.parameters)
        references.append((model.learn(STEPS - 200).learn(200, reset_num_timesteps=False), trace))
        env.close()
    paths = engine.save(tmp_path_factory.mktemp("models"))
    yield engine, engine_trace, references, paths
    engine.close()


def test_a_short_training_equals_sb3_learn(short_runs):
    engine, engine_trace, references, _ = short_runs
    for s, (model, trace) in enumerate(references):
        ours = [(t, rate) for t, rate, _ in engine_trace]
        assert ours == [(t, rate) for t, rate, _ in trace], f"seed {engine.seeds[s]}: exploration schedule"
        updates = [t for t, _, changed in trace if changed[0]]
        assert updates == [t for t, _, changed in engine_trace if changed[s]], f"seed {engine.seeds[s]}: targets"
        assert updates[:2] == [60, 120], "the target updates every 60 // 2 calls once training has started"
        buffer, ours_buffer = model.replay_buffer, engine.replay
        assert buffer.full and ours_buffer.full and buffer.pos == ours_buffer.pos
        for name in ("observations", "next_observations", "rewards", "dones", "timeouts"):
            assert np.array_equal(getattr(buffer, name), ours_buffer.of_seed(name, s)), name
        actions = ours_buffer.of_seed("actions", s)
        assert np.array_equal(buffer.actions[..., 0], actions), "actions (the epsilon-greedy draws)"
        assert buffer.timeouts.sum() > 0 and buffer.dones.sum() == buffer.timeouts.sum(), "truncations"
        q_net, q_net_target = engine_nets(engine, s)
        assert relative_error(q_net, model.policy.q_net.state_dict()) < 1e-5
        assert relative_error(q_net_target, model.policy.q_net_target.state_dict()) < 1e-5
        assert (engine._n_calls, engine._n_updates) == (model._n_calls, model._n_updates)
        assert engine._episode_num[s] == model._episode_num


def test_a_saved_seed_loads_in_sb3_and_continues_in_the_engine(short_runs):
    engine, _, references, paths = short_runs
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 21), [0.0, 1.0, 2.0]), axis=-1).reshape(-1, 2).astype(np.float32)
    greedy = engine.predict(np.stack([grid] * engine.n_seeds))
    for s, path in enumerate(paths):
        model, (sb3, _) = DQN.load(path, device="cpu"), references[s]
        assert np.array_equal(model.predict(grid, deterministic=True)[0], greedy[s]), path
        # What SB3's learn leaves on the model and saves with it: the same as SB3's run.
        for key in ("num_timesteps", "_total_timesteps", "_n_calls", "_n_updates", "_episode_num", "exploration_rate"):
            assert getattr(model, key) == getattr(sb3, key), key
        for key in ("_last_obs", "_last_original_obs", "_last_episode_starts"):
            assert np.array_equal(getattr(model, key), getattr(sb3, key)), key
        assert [(e["r"], e["l"]) for e in model.ep_info_buffer] == [(e["r"], e["l"]) for e in sb3.ep_info_buffer]
    # Continuing: SB3's DQN.load(path, env).learn(n) against the engine's from_models(...).learn(n).
    more = 160
    continued = BatchedDQN.from_models(paths, **LINE, n_envs=LINES, episode_steps=EPISODE).learn(more)
    for s, path in enumerate(paths):
        env = make_training_env(LINE["setup"], LINE["variant"], LINES, EPISODE, backend="native")
        model = DQN.load(path, env=env, device="cpu").learn(more)
        env.close()
        q_net, q_net_target = engine_nets(continued, s)
        assert relative_error(q_net, model.policy.q_net.state_dict()) < 1e-5, path
        assert relative_error(q_net_target, model.policy.q_net_target.state_dict()) < 1e-5, path
    continued.close()


@pytest.mark.parametrize("n_envs, train_freq, gradient_steps", [(1, 4, 1), (8, 1, 2)])
def test_the_papers_settings_are_implemented(n_envs, train_freq, gradient_steps):
    """hyperparams/dqn.yml, for one line and mapped to 8 (hyperparams.for_lines)."""
    from sorting_line_gym.training import hyperparams

    own, kwargs = hyperparams.split(hyperparams.load("dqn", "advanced", overrides=[f"n_envs={n_envs}"]))
    engine = BatchedDQN([1, 2], **LINE, n_envs=own["n_envs"], episode_steps=own["episode_steps"], **kwargs)
    assert (engine.gamma, engine.train_freq, engine.gradient_steps) == (0.95, train_freq, gradient_steps)


@pytest.mark.parametrize(
    "keywords, named",
    [
        (dict(n_steps=3), "n_steps"),
        (dict(optimize_memory_usage=True), "optimize_memory_usage"),
        (dict(train_freq=(1, "episode")), "train_freq"),
        (dict(tensorboard_log="runs"), "tensorboard_log"),
        (dict(policy_kwargs=dict(net_arch=[64], dueling=True)), "dueling"),
        (dict(policy_kwargs=dict(optimizer_class=torch.optim.SGD)), "optimizer_class"),
        (dict(gamma=1.5), "gamma"),
        (dict(batch_size=0), "batch_size"),
        (dict(seed=1), "seed"),
        (dict(clip_range=0.2), "clip_range"),
    ],
)
def test_a_bad_hyperparameter_fails_at_construction(keywords, named):
    with pytest.raises(ValueError, match=named):
        BatchedDQN([1], **LINE, **keywords)


def test_a_second_learn_that_resets_is_refused(short_runs):
    with pytest.raises(ValueError, match="reset_num_timesteps=False"):
        short_runs[0].learn(10)


def test_replay_buffers_beyond_memory_fail_saying_what_they_take(monkeypatch):
    from sorting_line_gym.training.batched import dqn

    monkeypatch.setattr(dqn, "available_memory", lambda: 10**6)
    engine = BatchedDQN([1, 2], **LINE, n_envs=2)
    with pytest.raises(MemoryError, match=r"2 seeds x 2 lines .* 100000 steps take 0.0[0-9] GB, and 0.00 GB"):
        engine.learn(100_000)
    engine.close()


def test_bad_seeds_and_model_files_fail_naming_them(tmp_path):
    for seeds, named in (([1, 1], "more than once"), ([-1], "-1"), ([], "one or more")):
        with pytest.raises(ValueError, match=named):
            BatchedDQN(seeds, **LINE)
    ppo = tmp_path / "ppo.zip"
    PPO("MlpPolicy", spaces_env("advanced", 1), n_steps=8, batch_size=8, device="cpu").save(ppo)
    with pytest.raises(ValueError, match="a ppo model"):
        BatchedDQN.from_models([ppo], **LINE)
    basic = tmp_path / "basic.zip"
    DQN("MlpPolicy", spaces_env("basic", 1), device="cpu", buffer_size=10).save(basic)
    with pytest.raises(ValueError, match="observation space"):
        BatchedDQN.from_models([basic], **LINE)


def test_the_bound_drawn_ahead_is_the_bound_after_the_adds():
    # The trainer draws a cycle's replay indices before its rollout adds train_freq rows
    # (BatchedDQN._collect_rollout): the bound it draws against must be the one SB3 samples with
    # after those adds, before, at and past the buffer's wrap.
    buffer = BatchedReplayBuffer(2, 10, 2, 1, True)
    zeros = np.zeros((2, 1))
    for _ in range(25):
        ahead = {adds: buffer.upper_bound(adds) for adds in range(1, 5)}
        for adds in range(1, 5):
            later = copy.deepcopy(buffer)
            for _ in range(adds):
                later.add(np.zeros((2, 1, 2)), np.zeros((2, 1, 2)), zeros, zeros, zeros, zeros)
            assert ahead[adds] == later.upper_bound() == (10 if later.full else later.pos), (buffer.pos, adds)
        buffer.add(np.zeros((2, 1, 2)), np.zeros((2, 1, 2)), zeros, zeros, zeros, zeros)
