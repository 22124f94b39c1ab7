"""sorting-line-train, sorting-line-eval, sorting-line-benchmark and the report's plots, on tiny
budgets, against real nodes over DDS (each CLI spawns its own node in a namespace of its own).

What must hold:
- eval through ROS equals the library's `sorting_line eval --json` episode for episode, bit for bit;
- training writes a model, its JSON and TensorBoard events with the line KPIs, and is
  deterministic: the same seed gives the same network weights, through the node;
- a saved model evaluates, deterministically;
- the benchmark resumes from its saved cells and draws its figures; the plots are real images;
- bad arguments fail at once with exit code 2 and a message naming the value.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from support import ros_harness as h
from support.images import assert_real_image
from support.waits import wait_until

TIMEOUT = 300


def run(argv: list[str], cwd: Path, check: bool = True) -> subprocess.CompletedProcess:
    """A console script of the bridge, in this test's ROS environment."""
    env = dict(os.environ, **h.ros_environment())
    result = subprocess.run(
        argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT, stdin=subprocess.DEVNULL
    )
    if check and result.returncode != 0:
        raise AssertionError(f"{' '.join(argv)} exited {result.returncode}:\n{result.stderr[-3000:]}")
    return result


def script(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def eval_flags(agent: str, setup: str, variant: str, episodes: int) -> list[str]:
    """The flags `sorting_line eval` and sorting-line-eval share for one evaluation, with --json."""
    return ["--agent", agent, "--setup", setup, "--variant", variant, "--episodes", str(episodes), "--json"]


def library_eval(agent: str, setup: str, variant: str, episodes: int, seed: int = 42, gap: bool = False) -> dict:
    argv = [str(h.node_binary()), "eval", *eval_flags(agent, setup, variant, episodes), "--seed", str(seed)]
    argv += ["--gap"] if gap else []
    return json.loads(subprocess.run(argv, capture_output=True, text=True, check=True, timeout=60).stdout)


@pytest.mark.parametrize("agent,setup,variant", [("rba", "D", "basic"), ("rba-hold", "B", "advanced")])
def test_eval_through_ros_equals_the_library(agent, setup, variant, tmp_path, capsys):
    from sorting_line_gym.studies import evaluate

    assert evaluate.main([*eval_flags(agent, setup, variant, 3), "--out", str(tmp_path)]) == 0
    ours = json.loads(capsys.readouterr().out)
    theirs = library_eval(agent, setup, variant, 3)
    assert ours["per_episode"] == theirs["per_episode"]
    for key in ("reward_mean", "reward_std", "speed_mean", "accuracy_mean", "purity_mean", "speed_changes_mean"):
        assert ours[key] == theirs[key], key
    stem = f"eval_{agent.replace(':', '-')}_{setup}_{variant}"
    rows = (tmp_path / f"{stem}.csv").read_text().splitlines()
    assert rows[0] == "seed,reward,speed_mean,accuracy_mean,purity,speed_changes" and len(rows) == 4
    assert f"| {setup} | {variant} | {agent} | {theirs['reward_mean']:.2f}" in (tmp_path / f"{stem}.md").read_text()
    assert json.loads((tmp_path / f"{stem}.json").read_text())["per_episode"] == theirs["per_episode"]
    assert_real_image(tmp_path / f"{stem}_seed42.png")


@pytest.mark.parametrize(
    "argv,names",
    [
        (["--agent", "rba-fast", "--setup", "A"], "rba-fast"),
        (["--agent", "constant:12", "--setup", "A"], "constant:12"),
        (["--agent", "ppo:/nonexistent/model.zip", "--setup", "A"], "/nonexistent/model.zip"),
        (["--agent", "rba", "--setup", "A", "--episodes", "0"], "--episodes = 0"),
    ],
)
def test_eval_rejects_bad_arguments(argv, names, capsys):
    from sorting_line_gym.studies import evaluate

    assert evaluate.main(argv) == 2  # before any node is started
    assert names in capsys.readouterr().err


def tiny_training(algo: str, out: Path) -> dict:
    """sorting-line-train's main, in this process (it spawns its node like the console script)."""
    from sorting_line_gym.training import train

    hp = {
        "ppo": ["--hp", "n_steps=128", "--hp", "batch_size=64", "--hp", "n_epochs=2"],
        "dqn": ["--hp", "learning_starts=64"],
        "a2c": [],
    }[algo]
    argv = [
        "--algo",
        algo,
        "--setup",
        "B",
        "--variant",
        "advanced",
        "--timesteps",
        "256",
        "--hp",
        "episode_steps=100",
        *hp,
        "--out",
        str(out),
        "--no-progress",
    ]
    assert train.main(argv) == 0
    return json.loads((out / f"{algo}_B_advanced_seed42.json").read_text())


def policy_weights(model_zip: Path) -> bytes:
    with zipfile.ZipFile(model_zip) as z:
        return z.read("policy.pth")


def test_training_writes_model_kpis_and_is_deterministic(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    first = tiny_training("ppo", tmp_path / "a")
    assert first["n_timesteps"] == 256 and first["episode_steps"] == 100 and first["episodes"] == 2
    assert first["hyperparams"]["gamma"] == 0.85 and first["hyperparams"]["ent_coef"] == 0.03
    model = Path(first["model_path"])
    assert model.is_file()
    events = list((tmp_path / "a" / "tensorboard").rglob("events.out.tfevents.*"))
    assert events, "no TensorBoard events written"
    acc = EventAccumulator(str(events[0].parent))
    acc.Reload()
    scalars = set(acc.Tags()["scalars"])
    for tag in ("line/purity", "line/mean_speed", "line/mean_accuracy", "line/speed_changes", "rollout/ep_rew_mean"):
        assert tag in scalars, f"{tag} not logged (have {sorted(scalars)})"
    purity = [e.value for e in acc.Scalars("line/purity")]
    assert all(0.0 < p <= 1.0 for p in purity)

    # Same seed, same commands, same trajectory: the same weights after training through a node.
    second = tiny_training("ppo", tmp_path / "b")
    assert policy_weights(Path(second["model_path"])) == policy_weights(model)

    from sorting_line_gym.studies.evaluate import evaluate

    evals = [evaluate(f"ppo:{model}", "B", "advanced", episodes=2) for _ in range(2)]
    assert evals[0].per_episode == evals[1].per_episode
    assert evals[0].episodes == 2 and np.isfinite(evals[0].reward_mean)


@pytest.mark.parametrize("algo", ["dqn", "a2c"])
def test_dqn_and_a2c_train_through_ros(algo, tmp_path):
    record = tiny_training(algo, tmp_path)
    assert Path(record["model_path"]).is_file() and record["episodes"] == 2
    defaults = {"dqn": {"gamma": 0.95}, "a2c": {"gamma": 0.9, "learning_rate": 0.0005, "ent_coef": 0.06}}[algo]
    for key, value in defaults.items():
        assert record["hyperparams"][key] == value


@pytest.mark.parametrize(
    "argv,names",
    [
        (["--hp", "gamma"], "gamma"),
        (["--hp", "no_such_argument=1"], "no_such_argument"),
        (["--timesteps", "0"], "n_timesteps = 0"),
        (["--hyperparams", "/nonexistent.yml"], "/nonexistent.yml"),
        (["--n-envs", "3"], "n_envs = 3"),
    ],
)
def test_train_rejects_bad_hyperparameters(argv, names, tmp_path, capsys):
    from sorting_line_gym.training import train

    assert train.main(["--algo", "ppo", "--setup", "A", "--out", str(tmp_path), "--no-progress", *argv]) == 2
    assert names in capsys.readouterr().err
    assert not list(tmp_path.iterdir()), "nothing is written when the arguments are bad"


def test_hyperparameters_are_mapped_from_one_line_to_n_lines():
    """What one update sees stays the paper's: PPO's 2048-step rollout, DQN's gradient step per 4
    transitions, A2C's update as near 5 transitions as N lines allow; explicit keys are kept."""
    from sorting_line_gym.training import hyperparams

    def rollout(algo, *overrides):
        params = hyperparams.load(algo, "advanced", overrides=list(overrides))
        return {k: params[k] for k in ("n_steps", "train_freq", "gradient_steps") if k in params}

    assert rollout("ppo") == {} and rollout("dqn", "n_envs=1") == {}
    assert rollout("ppo", "n_envs=8") == {"n_steps": 256}
    assert rollout("ppo", "n_envs=8", "n_steps=64") == {"n_steps": 64}
    assert rollout("dqn", "n_envs=2") == {"train_freq": 2, "gradient_steps": 1}
    assert rollout("dqn", "n_envs=8") == {"train_freq": 1, "gradient_steps": 2}
    assert rollout("a2c", "n_envs=2") == {"n_steps": 2} and rollout("a2c", "n_envs=8") == {"n_steps": 1}
    with pytest.raises(ValueError, match="n_envs = 6 .* power of two"):
        hyperparams.load("ppo", "basic", overrides=["n_envs=6"])


def test_named_lines_mappings_keep_minibatches_and_gradient_steps_per_transition():
    """Both one-line to N-line mappings keep PPO's and DQN's gradient steps per transition and the
    minibatch size; same-line-rollout keeps each line's rollout (PPO N x 2048 steps per update, DQN a
    training round every 4 vector steps with N gradient steps, A2C N x 5 transitions per update)."""
    from sorting_line_gym.training import hyperparams as hp

    assert hp.mapped_rollout("ppo", 8) == {"n_steps": 256} and hp.mapped_rollout("a2c", 8) == {"n_steps": 1}
    assert hp.mapped_rollout("dqn", 8) == {"train_freq": 1, "gradient_steps": 2}
    assert hp.mapped_rollout("ppo", 8, "same-line-rollout") == {"n_steps": 2048}
    assert hp.mapped_rollout("dqn", 8, "same-line-rollout") == {"train_freq": 4, "gradient_steps": 8}
    assert hp.mapped_rollout("a2c", 8, "same-line-rollout") == {"n_steps": 5}
    one = {algo: hp.load(algo, "advanced") for algo in hp.ALGOS}
    assert hp.gradient_steps_per_transition("ppo", one["ppo"]) == pytest.approx(10 * (2048 // 64) / 2048)
    assert hp.gradient_steps_per_transition("dqn", one["dqn"]) == 0.25
    assert hp.gradient_steps_per_transition("a2c", one["a2c"]) == pytest.approx(1 / 5)
    for mapping in hp.MAPPINGS:
        for n in (2, 8, 64):
            for algo in ("ppo", "dqn"):
                params = hp.load(algo, "advanced", overrides=[f"n_envs={n}"], mapping=mapping)
                assert hp.gradient_steps_per_transition(algo, params) == pytest.approx(
                    hp.gradient_steps_per_transition(algo, one[algo])
                ), (algo, mapping, n)
                assert "batch_size" not in params  # the minibatch stays SB3's default, as on one line
    a2c = hp.load("a2c", "advanced", overrides=["n_envs=8"], mapping="same-line-rollout")
    assert hp.gradient_steps_per_transition("a2c", a2c) == pytest.approx(1 / 40)
    with pytest.raises(ValueError, match="lines mapping 'fast' is not valid: allowed same-rollout, same-line-rollout"):
        hp.load("ppo", "basic", overrides=["n_envs=2"], mapping="fast")


def test_hyperparameter_files_need_an_entry_for_the_line(tmp_path):
    from sorting_line_gym.training import hyperparams

    path = tmp_path / "mine.yml"
    path.write_text(
        "SortingLine-v0: {n_timesteps: 5000, policy: MlpPolicy, n_envs: 2, episode_steps: 250, gamma: 0.5}\n"
    )
    assert hyperparams.load("dqn", "basic", path)["gamma"] == 0.5
    with pytest.raises(ValueError, match="no entry for SortingLineAdvanced-v0"):
        hyperparams.load("dqn", "advanced", path)
    defaults = hyperparams.load("ppo", "advanced", overrides=["policy_kwargs={net_arch: [32, 32]}"])
    assert defaults["policy_kwargs"] == {"net_arch": [32, 32]} and defaults["learning_rate"] == 0.0007


def test_console_scripts_are_installed(tmp_path):
    for name in ("sorting-line-train", "sorting-line-eval", "sorting-line-benchmark"):
        assert "usage: " + name in run([script(name), "--help"], tmp_path).stdout


@pytest.mark.parametrize(
    "module, argv, says",
    [
        (
            "studies.benchmark",
            ["--agents", "rba", "ppo", "--setups", "A", "--variants", "basic"],
            "--agents random rba",
        ),
        ("studies.transfer", ["--smoke"], "sorting-line-transfer: needs stable_baselines3"),
    ],
)
def test_studies_without_the_training_stack_fail_naming_setup_train(module, argv, says, tmp_path):
    """A core install (setup.sh without --train) has no SB3: the benchmark's RL agents and the transfer
    study fail at start with exit code 2 naming the install command, no traceback, nothing written.
    (SB3 is hidden from the process, so this holds with the training stack installed too.)"""
    code = (
        "import sys; sys.modules['stable_baselines3'] = sys.modules['sb3_contrib'] = None\n"
        f"from sorting_line_gym.{module} import main\n"
        f"sys.exit(main({[*argv, '--out', str(tmp_path / 'out')]!r}))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "bash launch_scripts/setup.sh --train" in r.stderr and says in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out" / "cells").exists(), r.stderr


def test_benchmark_resumes_and_draws_its_figures(tmp_path, capsys):
    """Baselines on B advanced: the paper's seeds and 5 held-out seeds through ROS equal the
    library's `sorting_line eval --gap` (agent, oracle and gap), and the statistics and figures
    are drawn; a rerun skips the finished cells."""
    from sorting_line_gym.studies import benchmark

    out = tmp_path / "bench"
    argv = [
        "--setups",
        "B",
        "--variants",
        "advanced",
        "--agents",
        "random",
        "rba",
        "rba-hold",
        "--heldout-seed",
        "10000",
        "--heldout-episodes",
        "5",
        "--out",
        str(out),
    ]
    assert benchmark.main(argv) == 0
    assert "3 to run" in capsys.readouterr().err
    table = (out / "table.md").read_text()
    paper = library_eval("rba", "B", "advanced", 10, gap=True)
    heldout = library_eval("rba", "B", "advanced", 5, seed=10000, gap=True)
    # One deterministic run: the IQM of 5 episodes is the mean of the middle 3, its interval the point.
    iqm = float(np.mean(sorted(e["reward"] for e in heldout["per_episode"])[1:4]))
    row = (
        f"| B5 | B | Adv | rba | 1 | {paper['reward_mean']:.2f} +- {paper['reward_std']:.2f} | "
        f"{heldout['reward_mean']:.2f} | "
        f"{iqm:.2f} [{iqm:.2f}, {iqm:.2f}] | "
    )
    assert row in table, table
    assert table.split(row)[1].startswith(f"{heldout['gap_mean']:.2f} |")  # the gap to the oracle
    oracle_row = f"| B | Adv | oracle |  | {paper['oracle_mean']:.2f} +- "
    assert oracle_row in table and f"| {heldout['oracle_mean']:.2f} | exact: " in table
    assert "| B | Adv | rba-hold | 1 | **" in table  # the better of the two on B is bold
    assert "27.33" in table and "22.58 +- 3.29" in table
    assert "| rba-hold | 1 |" in table  # the aggregate over lines, normalized between random and the oracle
    report = json.loads((out / "table.json").read_text())
    aggregate = report["aggregate_normalized"]
    assert aggregate["random"]["iqm"]["point"] == pytest.approx(0.0, abs=1e-12)
    assert 0.5 < aggregate["rba-hold"]["iqm"]["point"] < 1.0
    for name in (
        "figure7.png",
        "figure3.png",
        "intervals.png",
        "runs.png",
        "aggregate.png",
        "dashboards/B_advanced_rba-hold.png",
    ):
        assert_real_image(out / name)
    assert (out / "figure7.svg").stat().st_size > 10_000
    assert benchmark.main(argv) == 0
    assert "3 already done, 0 to run" in capsys.readouterr().err
    assert (out / "table.md").read_text() == table


def test_benchmark_statistics_over_training_seeds_and_lines(tmp_path, capsys):
    """DQN on D basic, two training seeds on 2 lines of one node and (--check-n-envs) on one line,
    a few hundred steps each: the RL row has 2 runs and an IQM interval, P(dqn > rba-hold) is
    reported, the one-line cells go to the agreement check only, and the 2-line trainings ran with
    the mapped hyperparameters (one gradient step per 4 transitions)."""
    from sorting_line_gym.studies import benchmark

    out = tmp_path / "bench"
    flags = "--setups D --variants basic --agents rba-hold dqn --train-seeds 42 43 --timesteps 200 --n-envs 2"
    argv = [*flags.split(), "--check-n-envs", "--heldout-episodes", "3", "--out", str(out)]
    assert benchmark.main(argv) == 0
    assert "5 cells, 0 already done, 5 to run" in capsys.readouterr().err
    report = json.loads((out / "table.json").read_text())
    (row,) = [r for r in report["rows"] if r["agent"] == "dqn"]
    assert row["seeds"] == 2 and row["n_envs"] == 2
    iqm = row["heldout"]["iqm"]
    assert iqm["low"] <= iqm["point"] <= iqm["high"]
    assert row["heldout"]["gap_mean"] > 0  # nothing this short reaches the clairvoyant optimum
    (poi,) = report["probability_of_improvement_over_rba_hold"]
    assert poi["agent"] == "dqn" and 0.0 <= poi["low"] <= poi["point"] <= poi["high"] <= 1.0
    (check,) = report["n_envs_agreement"]
    assert (check["setup"], check["variant"], check["agent"], check["n_envs"], check["runs"]) == (
        "D",
        "basic",
        "dqn",
        2,
        [2, 2],
    )
    assert check["mapping"] == "same-rollout" and check["gradient_steps_per_transition"] == [0.25, 0.25]
    # Each side's runs, drawn beside the intervals in runs.png: one held-out mean per training seed.
    assert [len(side) for side in check["per_run"]] == [2, 2] and row["heldout"]["per_seed"] != []
    assert (out / "runs.png").is_file()
    (verdict,) = report["n_envs_agreement_by_algorithm"]
    assert (verdict["agent"], verdict["lines"], verdict["verdict"]) == (
        "dqn",
        ["D basic"],
        "too few runs (fewer than 5 a side)",
    )
    table = (out / "table.md").read_text()
    assert (
        "| D2 | D | Basic | dqn | 2 |" in table
        and "P(dqn > rba-hold)" in table
        and "| D | Basic | dqn | 2 | same-rollout | 2 / 2 |" in table
    )
    for seed in (42, 43):
        two = json.loads((out / "cells" / f"D_basic_dqn_n2_seed{seed}.json").read_text())["training"]
        one = json.loads((out / "cells" / f"D_basic_dqn_seed{seed}.json").read_text())["training"]
        assert (two["n_envs"], two["hyperparams"]["train_freq"], two["hyperparams"]["gradient_steps"]) == (2, 2, 1)
        assert one["n_envs"] == 1 and "train_freq" not in one["hyperparams"]
        assert Path(two["model_path"]).parent.name == "models_n2" and Path(one["model_path"]).parent.name == "models"


def children(pid: int) -> list[int]:
    """The live child processes of `pid` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_benchmark_stops_on_sigterm_with_its_workers_and_nodes(tmp_path):
    """A stopped benchmark takes its workers and their nodes with it, at once, not after their
    trainings (rclpy's signal handler keeps a worker from dying of SIGTERM by itself)."""
    import signal

    env = dict(os.environ, **h.ros_environment())
    flags = "--setups A --variants basic --agents ppo --train-seeds 42 43 --timesteps 200000 --jobs 2".split()
    argv = [script("sorting-line-benchmark"), *flags, "--out", str(tmp_path / "bench")]
    pipes = dict(stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL)
    bench = subprocess.Popen(argv, env=env, text=True, **pipes)
    workers: list[int] = []
    try:

        def training_nodes() -> list[int]:
            workers[:] = children(bench.pid)
            nodes = [
                n
                for w in workers
                for n in children(w)
                if "sorting_line" in Path(f"/proc/{n}/cmdline").read_bytes().decode(errors="replace")
            ]
            return nodes if len(nodes) >= 2 else []

        nodes = wait_until(
            training_nodes,
            90,
            "two training nodes under the benchmark",
            poll=0.5,
            context=lambda: f"workers {children(bench.pid)}",
        )
        assert len(nodes) == 2, f"not two training nodes under the benchmark: {nodes}, workers {children(bench.pid)}"
        # The trainings are under way once each has its TensorBoard events file: SB3's learn() makes
        # it after the env's first reset. (A new wait, for what a 2 s sleep hoped for: a node's env
        # connects and resets in seconds, more under load; 60 s is the bound of a start that hangs.)
        wait_until(
            lambda: len(list((tmp_path / "bench" / "tensorboard").glob("*/events.out.tfevents.*"))) >= 2,
            60,
            "both trainings' TensorBoard events files (learn() has begun)",
            poll=0.2,
            context=lambda: f"under {tmp_path / 'bench'}: {sorted(str(f) for f in (tmp_path / 'bench').rglob('*'))}",
            abort=lambda: None if bench.poll() is None else f"the benchmark exited with {bench.returncode}",
        )
        bench.send_signal(signal.SIGTERM)
        _, err = bench.communicate(timeout=20)
        assert bench.returncode == 130, err[-2000:]
        assert "interrupted; 0 of 2 cells are saved" in err, err[-2000:]
        wait_until(
            lambda: not any(alive(p) for p in workers + nodes),
            10,
            "the benchmark's workers and nodes to exit",
            poll=0.2,
            context=lambda: f"left running: {[p for p in workers + nodes if alive(p)]}",
        )
    finally:
        if bench.poll() is None:
            bench.kill()
        for p in workers:
            if alive(p):
                os.kill(p, signal.SIGKILL)  # else they keep the pipes open and communicate() never returns
        bench.communicate(timeout=30)
