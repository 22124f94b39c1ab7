"""The batched trainer's PPO, A2C and MaskablePPO (training/batched) held to SB3 step for step,
for every seed of a batch of several seeds:

- one update (PPO: all epochs and minibatches, in an order both draw from the same generator
  states; A2C: its one step) from the same weights and the same transitions gives SB3's weights
  to 1e-5 relative: SB3's own ``train()`` on its filled buffer is the reference;
- the returns and advantages of a rollout with terminations and truncations are SB3's;
- action masks act as MaskablePPO's (the update with masks, sampling, deterministic prediction);
- a whole short training on native lines (rollouts with truncated episodes, their bootstrap,
  two updates) equals SB3's ``learn`` with the same seed: the same episodes, the same weights;
- each seed saved loads with PPO.load / A2C.load, whose ``predict(deterministic=True)`` gives the
  trainer's actions, and loads back into the trainer;
- bad input fails at construction, naming the value.

Native lines in this process: no node, no DDS. About 30 s on a busy machine.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
jax = pytest.importorskip("jax")
pytest.importorskip("sb3_contrib")

from stable_baselines3.common.logger import Logger  # noqa: E402

from sorting_line_gym.training.batched.actor_critic import evaluate_actions, exponential_noise  # noqa: E402
from sorting_line_gym.training.batched.on_policy import OnPolicyTrainer  # noqa: E402
from sorting_line_gym.training.train import make_training_env  # noqa: E402

SEEDS = [3, 4, 11]
LINES = 2
#: The paper's PPO settings, on short rollouts whose 2 x 40 samples leave a short last minibatch.
PPO = dict(n_steps=40, batch_size=24, n_epochs=3, gamma=0.85, learning_rate=7e-4, ent_coef=0.03)
A2C = dict(gamma=0.9, learning_rate=5e-4, ent_coef=0.06)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def trainer(algo: str, params: dict, seeds=SEEDS, lines: int = LINES, **kwargs) -> OnPolicyTrainer:
    return OnPolicyTrainer(algo, seeds, setup="B", variant="advanced", params=params, lines_per_seed=lines, **kwargs)


def fill(tr: OnPolicyTrainer, rng: np.random.Generator, masked: bool = False) -> None:
    """The same random transitions into the trainer's buffer and every seed's SB3 buffer, with
    SB3's values and log-probabilities of them; episodes start anywhere (terminations and
    truncations alike), and SB3's buffer computes its returns and advantages."""
    S, L, n = len(tr.seeds), tr.lines.n_lines, tr.template.n_steps
    tr.buffer.reset()
    for m in tr.models:
        m.rollout_buffer.reset()
    for t in range(n):
        obs = np.stack([rng.random((S, L)), rng.integers(0, 3, (S, L))], axis=-1).astype(np.float32)
        masks = rng.random((S, L, 30)) < 0.4 if masked else None
        if masks is not None:
            masks[..., 0] = True
        actions = np.stack([[rng.choice(np.flatnonzero(masks[s, j]) if masked else 30) for j in range(L)]
                            for s in range(S)]).astype(np.int64)  # fmt: skip
        rewards = (rng.normal(size=(S, L)) * 3).astype(np.float32)
        starts = (rng.random((S, L)) < 0.15) | (t == 0)
        values, log_probs = np.zeros((S, L), np.float32), np.zeros((S, L), np.float32)
        for s, m in enumerate(tr.models):
            extra = {"action_masks": masks[s]} if masked else {}
            with torch.no_grad():
                v, lp, _ = m.policy.evaluate_actions(torch.as_tensor(obs[s]), torch.as_tensor(actions[s]), **extra)
            m.rollout_buffer.add(obs[s], actions[s], rewards[s], starts[s], v, lp, **extra)
            values[s], log_probs[s] = v.numpy().flatten(), lp.numpy()
        tr.buffer.add(obs, actions, rewards, starts, values, log_probs, masks)
    last_values = rng.normal(size=(S, L)).astype(np.float32)
    dones = rng.random((S, L)) < 0.5
    for s, m in enumerate(tr.models):
        m.rollout_buffer.compute_returns_and_advantage(torch.as_tensor(last_values[s]), dones[s])
    tr.buffer.compute_returns_and_advantage(last_values, dones, tr.template.gamma, tr.template.gae_lambda)


def assert_weights_equal_sb3(tr: OnPolicyTrainer, rtol: float = 1e-5) -> None:
    """Every stacked weight's slice s equals seed s's SB3 weight, to ``rtol`` of the tensor's scale."""
    for p, per_seed in tr.weights():
        for s, q in enumerate(per_seed):
            scale = q.detach().abs().max().item()
            assert np.abs(p[s] - q.detach().numpy()).max() <= rtol * scale, (s, tuple(q.shape))


def sb3_train(tr: OnPolicyTrainer, progress: float, numpy_seeds: list[int]) -> None:
    """SB3's own train() of each seed's model, its minibatches shuffled from ``np.random.seed(k)``;
    the trainer's update with each seed's generator in that state."""
    for m, k in zip(tr.models, numpy_seeds, strict=True):
        m.set_logger(Logger(None, []))
        m._current_progress_remaining = progress
        np.random.seed(k)
        m.train()
    tr.np_rngs = [np.random.RandomState(k) for k in numpy_seeds]
    tr.progress_remaining = progress
    tr.train()


@pytest.mark.parametrize(
    "algo, params",
    [
        ("ppo", PPO),
        ("ppo", {**PPO, "clip_range": lambda p: 0.3 * p, "clip_range_vf": 0.1, "learning_rate": lambda p: 1e-3 * p}),
        ("ppo", {**PPO, "policy_kwargs": {"net_arch": {"pi": [32], "vf": [16, 16]}, "activation_fn": torch.nn.ReLU}}),
        ("maskable_ppo", PPO),
        ("a2c", A2C),
        ("a2c", {**A2C, "normalize_advantage": True, "n_steps": 8}),
    ],
    ids=["ppo", "ppo-schedules-clip-vf", "ppo-net-arch-relu", "maskable-ppo", "a2c", "a2c-normalized"],
)
def test_one_update_equals_sb3s_for_every_seed(algo, params):
    tr = trainer(algo, params)
    try:
        rng = np.random.default_rng(7)
        fill(tr, rng, masked=algo == "maskable_ppo")
        for s, m in enumerate(tr.models):  # returns and advantages: SB3's, exactly
            np.testing.assert_array_equal(tr.buffer.advantages[:, s], m.rollout_buffer.advantages)
            np.testing.assert_array_equal(tr.buffer.returns[:, s], m.rollout_buffer.returns)
        before = [p.copy() for p, _ in tr.weights()]
        sb3_train(tr, 0.6, [100 + s for s in range(len(SEEDS))])
        assert_weights_equal_sb3(tr)
        assert tr.n_updates == tr.models[0]._n_updates
        # The weights moved, every seed's: the comparison is not of untouched initial weights.
        assert all(max(np.abs(p[s] - b[s]).max() for (p, _), b in zip(tr.weights(), before, strict=True)) > 1e-4
                   for s in range(len(SEEDS)))  # fmt: skip
    finally:
        tr.close()


def test_returns_and_advantages_of_terminations_and_truncations_equal_sb3s():
    """Episodes cut anywhere (episode_starts) and at the rollout's end (dones), gae_lambda < 1 and 1."""
    for params in (PPO, {**A2C, "n_steps": 16}):
        tr = trainer("ppo" if "batch_size" in params else "a2c", params)
        try:
            fill(tr, np.random.default_rng(1))
            for s, m in enumerate(tr.models):
                np.testing.assert_array_equal(tr.buffer.advantages[:, s], m.rollout_buffer.advantages)
                np.testing.assert_array_equal(tr.buffer.returns[:, s], m.rollout_buffer.returns)
        finally:
            tr.close()


def test_masks_act_as_maskable_ppos():
    """With the evolving line's kind of masks: sampling never picks a masked action, the
    log-probabilities and entropies are MaskablePPO's, and the deterministic action is its predict's."""
    tr = trainer("maskable_ppo", PPO)
    try:
        rng = np.random.default_rng(3)
        S, B = len(SEEDS), 64
        obs = np.stack([rng.random((S, B)), rng.integers(0, 3, (S, B))], axis=-1).astype(np.float32)
        masks = rng.random((S, B, 30)) < 0.3
        masks[..., 3] = True
        noise = exponential_noise(tr.generators, (B, 30))  # Categorical.sample's draws, from each seed's generator
        actions, _, log_probs = (np.asarray(a) for a in tr.compiled["act"](tr.params, obs, noise, masks))
        assert np.take_along_axis(masks, actions[..., None], axis=-1).all()
        chosen = tr.predict(obs, masks)
        _, _, mine = jax.vmap(lambda p, o, a, k: evaluate_actions(tr.specs, p, o, a, k))(tr.params, obs, actions, masks)
        for s, m in enumerate(tr.models):
            with torch.no_grad():
                _, lp, ent = m.policy.evaluate_actions(torch.as_tensor(obs[s]), torch.as_tensor(actions[s]),
                                                       action_masks=masks[s])  # fmt: skip
            torch.testing.assert_close(torch.as_tensor(log_probs[s]), lp, rtol=1e-5, atol=1e-6)
            torch.testing.assert_close(torch.as_tensor(np.asarray(mine[s])), ent, rtol=1e-5, atol=1e-6)
            np.testing.assert_array_equal(chosen[s], m.predict(obs[s], action_masks=masks[s], deterministic=True)[0])
    finally:
        tr.close()


@pytest.mark.parametrize("episode_steps", [20, 15], ids=["rollouts-end-episodes", "rollouts-end-mid-episode"])
@pytest.mark.parametrize("algo, params", [("ppo", PPO), ("a2c", A2C)], ids=["ppo", "a2c"])
def test_a_short_training_equals_sb3s_learn(algo, params, episode_steps, tmp_path):
    """Two rollouts on native lines with short episodes (truncated: SB3 bootstraps them from the
    terminal observation) and their updates: each seed equals SB3 trained with that seed on one
    line of the same backend, episode for episode; saved, it loads in SB3 and predicts the
    trainer's actions, and it loads back into the trainer. With 15-step episodes a PPO rollout of
    40 steps holds two truncations and ends inside an episode, so its last values (the bootstrap
    of GAE) count: 20-step episodes end with the rollout, where they do not."""
    total = 2 * params.get("n_steps", 5) * (4 if algo == "a2c" else 1)
    tr = trainer(algo, params, lines=1, episode_steps=episode_steps)
    try:
        tr.learn(total)
        paths = tr.save([tmp_path / f"{algo}_seed{s}" for s in SEEDS])
        episodes = [[e["r"] for e in tr.lines.episodes[s]] for s in range(len(SEEDS))]
        obs = np.stack([np.random.default_rng(0).random(50), np.arange(50) % 3], axis=-1).astype(np.float32)
        engine_actions = tr.predict(np.broadcast_to(obs, (len(SEEDS), *obs.shape)))
    finally:
        tr.close()
    cls = type(tr.template)
    for s, seed in enumerate(SEEDS):
        env = make_training_env("B", "advanced", 1, episode_steps, backend="native")
        try:
            reference = cls("MlpPolicy", env, seed=seed, device="cpu", **params).learn(total)
        finally:
            env.close()
        assert [float(e["r"]) for e in reference.ep_info_buffer] == pytest.approx(episodes[s], rel=1e-6)
        saved = cls.load(paths[s], device="cpu")
        assert saved.num_timesteps == reference.num_timesteps and saved._n_updates == reference._n_updates
        for (name, ref), mine in zip(
            reference.policy.state_dict().items(), saved.policy.state_dict().values(), strict=True
        ):
            assert (ref - mine).abs().max().item() <= 1e-4 * ref.abs().max().item(), name
        np.testing.assert_array_equal(saved.predict(obs, deterministic=True)[0], engine_actions[s])
    again = trainer(algo, {}, lines=1, models=paths)
    try:
        for (p, _), (q, _) in zip(again.weights(), tr.weights(), strict=True):
            np.testing.assert_array_equal(p, q)
        assert again.num_timesteps == total
        # The optimizer's moments and step, as saved
        assert sorted(again.opt_state) == sorted(tr.opt_state) and again.opt_steps == tr.opt_steps > 0
        for key in again.opt_state:
            for ours, theirs in zip(jax.tree_util.tree_leaves(again.opt_state[key]),
                                    jax.tree_util.tree_leaves(tr.opt_state[key]), strict=True):  # fmt: skip
                np.testing.assert_array_equal(np.asarray(ours), np.asarray(theirs))
    finally:
        again.close()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"algo": "ddpg"}, "algorithm 'ddpg' is not valid for the batched trainer: allowed ppo, a2c, maskable_ppo"),
        ({"seeds": [1, 2, 1]}, r"seeds \[1\] are given more than once"),
        ({"seeds": [-1]}, "seed -1 is not valid: allowed integers 0 <= seed < 2"),
        ({"seeds": []}, "seeds = \\[\\]: allowed one or more"),
        ({"params": {"target_kl": 0.01}}, "target_kl = 0.01: the batched trainer implements only target_kl = None"),
        ({"params": {"use_sde": True}}, "use_sde = True: the batched trainer implements only use_sde = False"),
        ({"params": {"gamma_": 0.9}}, "gamma_ is not a hyperparameter of PPO"),
        ({"params": {"seed": 3}}, "seed is not a hyperparameter of the batched trainer"),
        ({"params": {"policy_kwargs": {"squash_output": True}}}, "policy_kwargs squash_output: not implemented"),
        ({"params": {"policy_kwargs": {"optimizer_class": torch.optim.LBFGS}}}, "optimizer LBFGS is not supported"),
        ({"lines": 0}, "lines_per_seed = 0 is not valid"),
        ({"seeds": list(range(4096)), "lines": 4096}, r"4096 seeds x 4096 lines .* would need about .* GiB"),
    ],
)
def test_bad_input_fails_at_construction_naming_it(kwargs, message):
    args = {"algo": "ppo", "seeds": [1, 2], "params": {}, "lines": 1, **kwargs}
    with pytest.raises(ValueError, match=message):
        trainer(args["algo"], args["params"], seeds=args["seeds"], lines=args["lines"])


def test_a_model_of_another_algorithm_or_line_is_refused(tmp_path):
    tr = trainer("a2c", A2C, seeds=[5], lines=1)
    try:
        (path,) = tr.save([tmp_path / "a2c_seed5.zip"])
    finally:
        tr.close()
    with pytest.raises(ValueError, match="a2c_seed5.zip: a a2c model; allowed here: ppo models"):
        trainer("ppo", {}, seeds=[5], lines=1, models=[path])
    with pytest.raises(ValueError, match="a2c_seed5.zip: a model of observation space Box.*allowed here: Box"):
        OnPolicyTrainer("a2c", [5], setup="B", variant="basic", models=[path])
    with pytest.raises(ValueError, match=r"params \['gamma'\] with models: a loaded model keeps its own"):
        trainer("a2c", {"gamma": 0.5}, seeds=[5], lines=1, models=[path])
    other = trainer("a2c", {**A2C, "ent_coef": 0.0}, seeds=[6], lines=1)
    try:
        (different,) = other.save([tmp_path / "a2c_seed6.zip"])
    finally:
        other.close()
    with pytest.raises(ValueError, match="a2c_seed6.zip: ent_coef = 0.0 where .*a2c_seed5.zip has 0.06"):
        trainer("a2c", {}, seeds=[5, 6], lines=1, models=[path, different])


@pytest.mark.parametrize("algo", ["a2c", "dqn"])
def test_sorting_line_train_engine_batched_writes_each_seeds_model(algo, tmp_path, capsys):
    """`sorting-line-train --engine batched --seeds ...`: one SB3 zip and record per seed, named as
    --engine sb3 names them (DQN through BatchedDQN); flags the batched engine lacks are refused
    (exit 2), not ignored."""
    from sorting_line_gym.training import hyperparams
    from sorting_line_gym.training.train import main

    argv = ["--algo", algo, "--setup", "D", "--engine", "batched", "--seeds", "7", "8", "--timesteps", "40"]
    assert main([*argv, "--out", str(tmp_path), "--no-progress"]) == 0
    for seed in (7, 8):
        model = hyperparams.algorithm_class(algo).load(tmp_path / f"{algo}_D_basic_seed{seed}.zip", device="cpu")
        assert model.num_timesteps == 40 and model.seed == seed
        assert (tmp_path / f"{algo}_D_basic_seed{seed}.json").is_file()
    if algo == "dqn":
        return
    for extra, message in (
        # Refused before any node starts (no rclpy: this is the unit tier): too many lines for one node.
        (["--backend", "ros", "--n-envs", "64"], "2 seeds x 64 lines = 128 lines on 1 node(s)"),
        (["--hp", "use_sde=true"], "use_sde = True: the batched trainer implements only use_sde = False"),
        (["--seed", "3"], "--seed and --seeds: allowed one of them"),
    ):
        assert main([*argv, "--out", str(tmp_path / "no"), *extra]) == 2
        assert message in capsys.readouterr().err


def test_maskable_ppo_on_the_evolving_line_equals_sb3s():
    """The evolving line's masks (mode 0 only before its upgrade) in the rollouts: each seed equals
    sb3-contrib's MaskablePPO trained with that seed on the native evolving line, episode for episode."""
    import gymnasium
    from sb3_contrib import MaskablePPO
    from stable_baselines3.common.monitor import Monitor

    import sorting_line_gym  # noqa: F401 - registers the ids
    from sorting_line_gym.envs.evolving import schedule_file

    schedule, params, seeds = str(schedule_file("upgrade")), dict(n_steps=100, batch_size=50, n_epochs=2), [5, 6]
    tr = OnPolicyTrainer("maskable_ppo", seeds, setup="B", variant="advanced", params=params, episode_steps=50,
                         evolution=schedule)  # fmt: skip
    try:
        tr.learn(300)
        models = tr.sync_models()
        for s, seed in enumerate(seeds):
            env = gymnasium.make("sorting_line_gym:SortingLineEvolving-v0", evolution=schedule, setup="B",
                                 max_episode_steps=50, backend="native")  # fmt: skip
            reference = MaskablePPO("MlpPolicy", Monitor(env), seed=seed, device="cpu", **params).learn(300)
            env.close()
            ours = [e["r"] for e in tr.lines.episodes[s]]
            # Monitor sums a return in float64 and rounds it to 6 decimals (VecMonitor, above: float32 as here).
            assert [float(e["r"]) for e in reference.ep_info_buffer] == pytest.approx(ours, rel=1e-6, abs=1e-6)
            for name, ref in reference.policy.state_dict().items():
                mine = models[s].policy.state_dict()[name]
                assert (ref - mine).abs().max().item() <= 1e-4 * ref.abs().max().item(), name
    finally:
        tr.close()
