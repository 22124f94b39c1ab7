"""The batched engine (training/batched) on the ROS backend's lines: S seeds x L lines of one real
`sorting_line node` (``--lines S*L``) instead of native lines in this process.

- A short PPO training (2 seeds x 2 lines, two rollouts with truncated episodes) on the lines of a
  node the test started (``namespace``: the engine attaches) gives bit-identical weights to the
  same training on native lines; so does a short DQN training on a node the engine starts itself:
  the backend changes the pace, not what is learned (the project's determinism across backends).
- ``sorting-line-train --engine batched --backend ros --seeds ...`` starts its node and writes
  models that ``PPO.load`` opens.
- A node of fewer lines than S x L, and S x L beyond what one node serves, fail before training,
  naming the number and what is needed.

ROS tier: run in a loopback-only network namespace (conftest). About 30 s on a busy machine.
"""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

pytest.importorskip("torch")

from sorting_line_gym.line.errors import BridgeError  # noqa: E402
from sorting_line_gym.line.options import LineOptions  # noqa: E402
from sorting_line_gym.training.batched.dqn import BatchedDQN  # noqa: E402
from sorting_line_gym.training.batched.on_policy import OnPolicyTrainer  # noqa: E402

SEEDS, LINES = [3, 4], 2
#: Short rollouts of the paper's PPO; 50-step episodes so that both rollouts end some.
PPO = dict(n_steps=32, batch_size=32, n_epochs=2, gamma=0.85, learning_rate=7e-4, ent_coef=0.03)
LINE = dict(setup="B", variant="advanced")
EPISODE_STEPS = 50

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def node_args(namespace: str, lines: int) -> list[str]:
    """`sorting_line node` flags of a node serving ``lines`` lines as the engine's LineOptions ask
    (what line.process.NodeProcess passes when a bank starts one), in ``namespace``."""
    options = LineOptions(**LINE, max_episode_steps=EPISODE_STEPS).node_options(lines)
    flags = [arg for key, value in options.items() for arg in (f"--{key.replace('_', '-')}", str(value))]
    return [*flags, "--ros-args", "-r", f"__ns:={namespace}"]


def leaves(tree) -> list[np.ndarray]:
    return [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(tree)]


def assert_bit_identical(ros, native) -> None:
    a, b = leaves(ros), leaves(native)
    assert len(a) == len(b) > 0
    for x, y in zip(a, b, strict=True):
        assert x.dtype == y.dtype and np.array_equal(x, y), "the ROS lines' training differs from the native one"


def ppo_training(**where) -> tuple[list[np.ndarray], np.ndarray]:
    trainer = OnPolicyTrainer("ppo", SEEDS, **LINE, params=PPO, lines_per_seed=LINES, episode_steps=EPISODE_STEPS,
                              **where)  # fmt: skip
    try:
        trainer.learn(2 * PPO["n_steps"] * LINES)
        return leaves(trainer.params), trainer.lines.episode_counts.copy()
    finally:
        trainer.close()


def test_ppo_on_a_nodes_lines_equals_ppo_on_native_lines(start_node, namespace):
    ns = namespace("ppo")
    start_node(*node_args(ns, len(SEEDS) * LINES))
    ros, ros_episodes = ppo_training(backend="ros", namespace=ns)
    native, native_episodes = ppo_training()
    assert ros_episodes.tolist() == native_episodes.tolist() and ros_episodes.min() > 0
    assert_bit_identical(ros, native)


def test_dqn_on_lines_of_a_node_it_starts_equals_dqn_on_native_lines():
    def trained(backend: str):
        engine = BatchedDQN(
            SEEDS, setup="D", variant="basic", n_envs=LINES, episode_steps=EPISODE_STEPS, backend=backend,
            learning_starts=40, train_freq=4, batch_size=16, buffer_size=500, target_update_interval=20,
        )  # fmt: skip
        try:
            engine.learn(200)
            assert engine.lines is not None and engine.lines.backend == backend
            return leaves(engine.q_net) + leaves(engine.q_net_target)
        finally:
            if engine.lines is not None:
                engine.lines.close()

    assert_bit_identical(trained("ros"), trained("native"))


def test_sorting_line_train_batched_on_ros_writes_models_ppo_loads(tmp_path, capsys):
    from stable_baselines3 import PPO as SB3PPO

    from sorting_line_gym.training.train import main

    def argv(seeds: list[int], out) -> list[str]:
        line = ["--algo", "ppo", "--setup", "D", "--engine", "batched", "--backend", "ros", "--n-envs", "2"]
        budget = ["--timesteps", "64", "--hp", "n_steps=32", "--hp", "batch_size=32", "--no-progress"]
        return [*line, *budget, "--seeds", *map(str, seeds), "--out", str(out)]

    assert main(argv([7, 8], tmp_path)) == 0
    assert "on ros lines" in capsys.readouterr().err
    for seed in (7, 8):
        model = SB3PPO.load(tmp_path / f"ppo_D_basic_seed{seed}.zip", device="cpu")
        assert model.num_timesteps == 64 and model.seed == seed
        action, _ = model.predict(np.zeros(model.observation_space.shape, dtype=np.float32), deterministic=True)
        assert model.action_space.contains(int(action))
        assert json.loads((tmp_path / f"ppo_D_basic_seed{seed}.json").read_text())["seed"] == seed
    # S x L beyond one node's 64 lines: refused before a node starts or a model is built.
    assert main(argv(list(range(33)), tmp_path / "no")) == 2
    err = capsys.readouterr().err
    assert "33 seeds x 2 lines = 66 lines on 1 node(s): a node serves 1 ..= 64 lines" in err, err
    assert not (tmp_path / "no").exists() or not any((tmp_path / "no").iterdir())


def test_a_node_of_fewer_lines_than_seeds_times_lines_is_refused_naming_them(start_node, namespace):
    ns = namespace("few")
    start_node(*node_args(ns, 2))
    trainer = OnPolicyTrainer("ppo", SEEDS, **LINE, params=PPO, lines_per_seed=LINES, episode_steps=EPISODE_STEPS,
                              backend="ros", namespace=ns)  # fmt: skip
    try:
        with pytest.raises(BridgeError) as refused:
            trainer.learn(64)
        assert trainer.num_timesteps == 0
    finally:
        trainer.close()
    message = str(refused.value)
    assert f"2 seeds x 2 lines need 4 lines on the node(s) {ns} (sorting_line node --lines 4 each)" in message
    assert "0 ..= 1" in message, message  # the node's own word: it serves lines 0 and 1


def test_bad_backend_input_fails_at_construction_naming_it():
    with pytest.raises(ValueError, match="namespace = '/x' with backend = 'native'"):
        OnPolicyTrainer("ppo", SEEDS, **LINE, params=PPO, namespace="/x")
    with pytest.raises(ValueError, match="backend = 'dds' is not valid"):
        BatchedDQN(SEEDS, backend="dds")
    with pytest.raises(ValueError, match="3 seeds x 2 lines = 6 lines on 4 node"):
        BatchedDQN([1, 2, 3], n_envs=2, backend="ros", namespace=["/a", "/b", "/c", "/d"])
