"""`sorting-line-export`: SB3 models (PPO, A2C, DQN, MaskablePPO) as ONNX policies.

What must hold:
- the ONNX policy decides exactly as SB3's ``predict(deterministic=True)`` on 10,000 observations
  drawn over the observation space, for each algorithm (MaskablePPO with masks: random ones and
  the evolving line's mode-0-only one). The PPO model is the committed one (tests/data/policies,
  4096 steps on the line); A2C, DQN and MaskablePPO are trained here for a few hundred steps on
  real lines (the evolving one for MaskablePPO), which keeps their networks off their initial weights;
- the metadata names the line, the layouts and where the policy came from;
- bad input fails with exit code 2 and a message, no traceback: not a model, a zip that is no SB3
  model, an SB3 model of an unsupported policy (a continuous action space), a model without a
  training record and without --setup, a missing package.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from support import ros_harness as h

POLICIES = h.ROOT / "tests" / "data" / "policies"
PPO_ZIP = POLICIES / "ppo_B_advanced_seed42.zip"
ROUND_TRIP_SAMPLES = 10_000


def export_cli(*args, env: dict | None = None) -> subprocess.CompletedProcess:
    script = Path(sys.executable).parent / "sorting-line-export"
    return subprocess.run(
        [str(script), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=180,
        env=env or dict(os.environ),
        stdin=subprocess.DEVNULL,
    )


def train_small(algo: str, out: Path) -> Path:
    """A model trained for a few hundred steps on a real line (MaskablePPO: the evolving one)."""
    import torch

    torch.set_num_threads(1)
    if algo == "maskable_ppo":
        from sb3_contrib import MaskablePPO

        from sorting_line_gym.envs.evolving import SortingLineEvolvingEnv

        env = SortingLineEvolvingEnv(evolution="upgrade", setup="B", max_episode_steps=50)
        try:
            model = MaskablePPO("MlpPolicy", env, n_steps=128, batch_size=64, n_epochs=2, seed=3)
            model.learn(total_timesteps=256)
        finally:
            env.close()
        path = out / "maskable_ppo_B_evolving.zip"
        model.save(path)
        return path
    from sorting_line_gym.training import hyperparams
    from sorting_line_gym.training.train import train

    setup, variant, hp = {
        "a2c": ("A", "basic", ["n_timesteps=300"]),
        "dqn": ("D", "basic", ["n_timesteps=300", "learning_starts=100", "train_freq=4"]),
    }[algo]
    params = hyperparams.load(algo, variant, None, hp)
    run = train(algo, setup, variant, seed=5, out=out, params=params, tensorboard=None, progress=False)
    return Path(run.model_path)


@pytest.mark.parametrize("algo", ["ppo", "a2c", "dqn", "maskable_ppo"])
def test_the_onnx_policy_decides_as_sb3_on_10000_observations(algo, tmp_path, capsys):
    from sorting_line_gym.agents.learned_policy import load_learned_policy, read_sb3_zip
    from sorting_line_gym.training.export import disagreements, main

    if algo == "ppo":
        model = tmp_path / PPO_ZIP.name
        shutil.copy(PPO_ZIP, model)
        shutil.copy(PPO_ZIP.with_suffix(".json"), model.with_suffix(".json"))
    else:
        model = train_small(algo, tmp_path)
    onnx_path = tmp_path / f"{algo}.onnx"
    flags = ["--setup", "B", "--evolution", "upgrade"] if algo == "maskable_ppo" else []
    assert main([str(model), "--out", str(onnx_path), *flags]) == 0, capsys.readouterr().err
    assert "agrees with SB3" in capsys.readouterr().out

    parts = read_sb3_zip(model)
    assert parts.algorithm == algo
    wrong, first = disagreements(onnx_path, parts, ROUND_TRIP_SAMPLES, seed=11)
    assert wrong == 0, f"{wrong} of {ROUND_TRIP_SAMPLES} decisions differ, e.g. {first}"

    policy = load_learned_policy(onnx_path)
    assert policy.runtime == "onnxruntime" and policy.masked == (algo == "maskable_ppo")
    card = policy.card
    assert card.algorithm == algo and card.exporter.startswith("sorting_line_gym ")
    if algo == "maskable_ppo":
        assert (card.setup, card.variant, card.evolution) == ("B", "advanced", "upgrade")
        assert card.env_id == "sorting_line_gym:SortingLineEvolving-v0"
        # The mask decides: with only mode 0 allowed, every action has mode 0.
        obs = np.random.default_rng(0).uniform(0, 2, (500, 2)).astype(np.float32)
        masks = np.tile(np.arange(30) % 3 == 0, (500, 1))
        assert set((policy.decide_batch(obs, masks) % 3).tolist()) == {0}
    else:
        record = json.loads(model.with_suffix(".json").read_text())
        assert (card.setup, card.variant, card.seed) == (record["setup"], record["variant"], record["seed"])
        assert card.training_steps == record["n_timesteps"] and card.hyperparameters == record["hyperparams"]


def test_the_metadata_says_what_a_runtime_needs():
    import onnx

    model = onnx.load(str(PPO_ZIP.with_suffix(".onnx")))
    props = {p.key: p.value for p in model.metadata_props}
    assert props["sorting_line.env_id"] == "sorting_line_gym:SortingLineAdvanced-v0"
    assert (props["sorting_line.setup"], props["sorting_line.variant"]) == ("B", "advanced")
    assert json.loads(props["sorting_line.observation"])["shape"] == [2]
    action = json.loads(props["sorting_line.action"])
    assert action["n"] == 30 and action["speed_index"] == "action // 3" and action["mode"] == "action % 3"
    assert props["sorting_line.algorithm"] == "ppo" and json.loads(props["sorting_line.seed"]) == 42
    assert json.loads(props["sorting_line.training_steps"]) == 4096
    assert json.loads(props["sorting_line.hyperparameters"])["gamma"] == 0.85
    assert [i.name for i in model.graph.input] == ["observation"] and [o.name for o in model.graph.output] == ["action"]


def continuous_model(path: Path) -> Path:
    """An SB3 PPO on a continuous action space: a policy no line can use."""
    import gymnasium
    from stable_baselines3 import PPO

    PPO("MlpPolicy", gymnasium.make("Pendulum-v1"), n_steps=64, batch_size=64, seed=0).save(path)
    return path


def test_bad_input_fails_with_a_message_and_exit_code_2(tmp_path, capsys):
    text = tmp_path / "notes.zip"
    text.write_text("not a model")
    other_zip = tmp_path / "other.zip"
    shutil.make_archive(str(other_zip.with_suffix("")), "zip", root_dir=h.ROOT / "tests" / "data" / "policies")
    bare = tmp_path / "bare.zip"
    shutil.copy(PPO_ZIP, bare)  # no training record beside it
    cases = [
        ((text, "--out", tmp_path / "a.onnx"), "not a Stable-Baselines3 model"),
        ((other_zip, "--out", tmp_path / "b.onnx"), "not a Stable-Baselines3 model"),
        (
            (continuous_model(tmp_path / "pendulum.zip"), "--out", tmp_path / "c.onnx"),
            "a line's policy acts in Discrete",
        ),
        ((bare, "--out", tmp_path / "d.onnx"), "give the line it was trained on with --setup"),
        ((tmp_path / "missing.zip", "--out", tmp_path / "e.onnx"), "no such file"),
        ((PPO_ZIP, "--out", tmp_path / "f.onnx", "--variant", "basic"), "does not fit its spaces"),
    ]
    from sorting_line_gym.training.export import main

    # In this process (torch is loaded once): main() returns the exit code and prints the message;
    # an exception would fail the test with its traceback.
    for args, message in cases:
        code = main([str(a) for a in args])
        err = capsys.readouterr().err
        assert code == 2 and message in err, (args, code, err)
    # The command line: the same message, no traceback; with --setup the bare model exports.
    r = export_cli(text, "--out", tmp_path / "a.onnx")
    assert r.returncode == 2 and "not a Stable-Baselines3 model" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert main([str(bare), "--out", str(tmp_path / "g.onnx"), "--setup", "B"]) == 0, capsys.readouterr().err
