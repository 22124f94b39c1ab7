"""Wall time of training through ROS against training on the reference's in-process Python env.

    .venv/bin/python benches/train_timing.py --reference /path/to/2024_Sorting_Env
    .venv/bin/python benches/train_timing.py --reference DIR --algo ppo --setup B --variant advanced --timesteps 100000

Target (issue 5): 100k PPO steps through ROS cost at most 1.2x the same training on the
reference's env. Both sides are measured the same way, one after the other in this process
tree: the algorithm with the paper's hyperparameters (``hyperparams/<algo>.yml``), seed 42,
250-step training episodes, a Monitor for episode statistics, TensorBoard logging and the progress
bar on, the same torch thread count, and the wall time of ``model.learn()`` alone (env start-up
and saving excluded on both sides). The reference (Storm-131/2024_Sorting_Env, read unmodified
from ``--reference``) is trained as its ``utils/benchmark.py`` does: ``reset(seed=100)``, Monitor,
``check_env``. Ours is ``sorting_line_gym.training.train.train`` (a node process, lock-step over DDS).

Prints both wall times, steps/s, the ratio, load average and CPU steal; ``--rounds N`` alternates
the two N times and reports medians. DDS stays on loopback: as root the script re-executes itself
under ``unshare -n``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from unittest.mock import MagicMock

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
import ros_harness as h  # noqa: E402
from sorting_line_gym.line.vocabulary import SETUPS, THRESHOLD, VARIANTS  # noqa: E402

#: The reference env's name of each input generator.
REFERENCE_INPUTS = {"random": "r", "seasonal": "s9"}
#: The setups as the reference env's keyword arguments.
REFERENCE_SETUPS = {
    name: dict(input=REFERENCE_INPUTS[s["input"]], noise_lv=s["obs_noise"], action_penalty=s["action_penalty"])
    for name, s in SETUPS.items()
}
TARGET_RATIO = 1.2


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def time_reference(ref_dir: Path, algo: str, setup: str, variant: str, timesteps: int, threads: int, tb: Path) -> float:
    """Seconds of ``model.learn`` on the reference env, trained as its utils/benchmark.py does."""
    import torch
    from stable_baselines3.common.env_checker import check_env
    from stable_baselines3.common.monitor import Monitor

    from sorting_line_gym.training import hyperparams

    sys.path.insert(0, str(ref_dir))
    # The reference's env modules import cv2 and seaborn at top level for plotting only; where they
    # are not installed, stand-ins let the env import (training never plots).
    for name in ("cv2", "seaborn"):
        try:
            __import__(name)
        except ImportError:
            sys.modules[name] = MagicMock(name=name)
    try:
        if variant == "advanced":
            from src.env_2_adv import SortingEnvironmentAdv as Env
        else:
            from src.env_1_simple import SortingEnvironment as Env
    except ImportError as e:
        sys.exit(f"train_timing.py: cannot import the reference env from {ref_dir} ({e})")
    own, kwargs = hyperparams.split(hyperparams.load(algo, variant, overrides=[f"n_timesteps={timesteps}"]))
    torch.set_num_threads(threads)
    env = Env(max_steps=own["episode_steps"], threshold=THRESHOLD, **REFERENCE_SETUPS[setup])
    env.reset(seed=100)
    env = Monitor(env)
    check_env(env)
    model = hyperparams.algorithm_class(algo)(own["policy"], env, seed=42, verbose=0, tensorboard_log=str(tb), **kwargs)
    start = time.perf_counter()
    model.learn(total_timesteps=timesteps, progress_bar=True, tb_log_name="reference")
    return time.perf_counter() - start


def time_ours(algo: str, setup: str, variant: str, timesteps: int, threads: int, tb: Path, out: Path) -> float:
    from sorting_line_gym.training import hyperparams
    from sorting_line_gym.training.train import train

    params = hyperparams.load(algo, variant, overrides=[f"n_timesteps={timesteps}"])
    run = train(algo, setup, variant, seed=42, out=out, params=params, tensorboard=tb, progress=True, torch_threads=threads)
    return run.wall_s


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--reference", required=True, type=Path, help="checkout of the reference implementation (Storm-131/2024_Sorting_Env)")
    p.add_argument("--algo", default="ppo", choices=("ppo", "dqn", "a2c"))
    p.add_argument("--setup", default="B", choices=tuple(REFERENCE_SETUPS))
    p.add_argument("--variant", default="advanced", choices=VARIANTS)
    p.add_argument("--timesteps", type=int, default=100_000)
    p.add_argument("--torch-threads", type=int, default=1)
    p.add_argument("--rounds", type=int, default=1, help="alternate reference and ours this many times; medians reported")
    args = p.parse_args()
    if not (args.reference / "src" / "env_1_simple.py").is_file():
        sys.exit(f"train_timing.py: {args.reference} does not look like the reference checkout (no src/env_1_simple.py)")
    h.run_isolated(__file__, "SORTING_LINE_TRAIN_TIMING_IN_NETNS")
    h.ros_environment("97")

    ours, theirs = [], []
    with tempfile.TemporaryDirectory(prefix="train_timing_") as tmp:
        tmp = Path(tmp)
        for r in range(args.rounds):
            progress(f"round {r + 1}/{args.rounds}: reference env, {args.algo} {args.timesteps} steps ({h.machine_conditions()})")
            theirs.append(time_reference(args.reference, args.algo, args.setup, args.variant, args.timesteps, args.torch_threads, tmp / "tb"))
            progress(f"  reference: {theirs[-1]:.1f} s")
            progress(f"round {r + 1}/{args.rounds}: through ROS ({h.machine_conditions()})")
            ours.append(time_ours(args.algo, args.setup, args.variant, args.timesteps, args.torch_threads, tmp / "tb", tmp / "models"))
            progress(f"  through ROS: {ours[-1]:.1f} s")
    ref_s, our_s = statistics.median(theirs), statistics.median(ours)
    ratio = our_s / ref_s
    print(f"\n{args.algo.upper()} {args.timesteps} steps, setup {args.setup} {args.variant}, torch threads {args.torch_threads}, "
          f"{args.rounds} round(s), medians ({h.machine_conditions()}):")
    print(f"  reference in-process env: {ref_s:8.1f} s  ({args.timesteps / ref_s:6.0f} steps/s)  runs {[round(x, 1) for x in theirs]}")
    print(f"  through ROS (this repo):  {our_s:8.1f} s  ({args.timesteps / our_s:6.0f} steps/s)  runs {[round(x, 1) for x in ours]}")
    print(f"  ratio ours/reference: {ratio:.2f}x (target <= {TARGET_RATIO}x: {'met' if ratio <= TARGET_RATIO else 'NOT met'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
