"""Wall time of training through ROS, on one line and on N lines of one node, against training on
the reference's in-process Python env.

    .venv/bin/python benches/train_timing.py --reference /path/to/2024_Sorting_Env
    .venv/bin/python benches/train_timing.py --reference DIR --algo ppo dqn a2c --n-envs 1 8 --timesteps 20000

Targets: 100k PPO steps through ROS on one line cost at most 1.2x the same training on the
reference's env; the whole Table 1 with 5 seeds per RL cell (``run.sh --full``) takes under 2
hours on 2 cores: the last lines project the full study's training time from
the steps/s measured here. Both sides are measured the same way, one after the other in this process
tree: the algorithm with the paper's hyperparameters (``hyperparams/<algo>.yml``; on N lines
mapped as ``hyperparams.for_lines`` says), seed 42,
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
from sorting_line_gym.line.vocabulary import SETUPS, THRESHOLD, VARIANTS  # noqa: E402
from support import ros_harness as h  # noqa: E402

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


def import_reference_env(ref_dir: Path, variant: str):
    """The reference's env class of ``variant``, imported unmodified from its checkout."""
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
            from src.env_2_adv import SortingEnvironmentAdv as Env  # noqa: N813
        else:
            from src.env_1_simple import SortingEnvironment as Env  # noqa: N813
    except ImportError as e:
        sys.exit(f"train_timing.py: cannot import the reference env from {ref_dir} ({e})")
    return Env


def time_reference(ref_dir: Path, algo: str, setup: str, variant: str, timesteps: int, threads: int, tb: Path) -> float:
    """Seconds of ``model.learn`` on the reference env, trained as its utils/benchmark.py does."""
    import torch
    from stable_baselines3.common.env_checker import check_env
    from stable_baselines3.common.monitor import Monitor

    from sorting_line_gym.training import hyperparams

    Env = import_reference_env(ref_dir, variant)
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


def time_ours(
    algo: str,
    setup: str,
    variant: str,
    timesteps: int,
    threads: int,
    tb: Path,
    out: Path,
    n_envs: int = 1,
    backend: str = "ros",
) -> float:
    from sorting_line_gym.training import hyperparams
    from sorting_line_gym.training.train import train

    params = hyperparams.load(algo, variant, overrides=[f"n_timesteps={timesteps}", f"n_envs={n_envs}"])
    run = train(
        algo,
        setup,
        variant,
        seed=42,
        out=out,
        params=params,
        tensorboard=tb,
        progress=True,
        torch_threads=threads,
        backend=backend,
    )
    return run.wall_s


#: What run.sh --full trains: 8 lines x 5 seeds per algorithm on N lines, and for the --n-envs
#: check 5 one-line trainings each of PPO (B advanced) and DQN (D basic); two cells at a time.
FULL_STUDY = {"cells_per_algo": 8 * 5, "one_line_cells": {"ppo": 5, "dqn": 5}, "timesteps": 100_000, "jobs": 2}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--reference",
        type=Path,
        help="checkout of the reference implementation (Storm-131/2024_Sorting_Env); without it only ours is timed",
    )
    p.add_argument("--algo", nargs="+", default=["ppo"], choices=("ppo", "dqn", "a2c"))
    p.add_argument(
        "--n-envs",
        nargs="+",
        type=int,
        default=[1],
        help="lines of one node for our side (default 1); several values: each timed",
    )
    p.add_argument("--setup", default="B", choices=tuple(REFERENCE_SETUPS))
    p.add_argument("--variant", default="advanced", choices=VARIANTS)
    p.add_argument("--timesteps", type=int, default=100_000)
    p.add_argument("--torch-threads", type=int, default=1)
    p.add_argument(
        "--rounds", type=int, default=1, help="alternate reference and ours this many times; medians reported"
    )
    return p


def _time_all(args) -> dict[tuple[str, str], list[float]]:
    """Training seconds by (algorithm, side), one per round: the reference's and ours on each --n-envs."""
    times: dict[tuple[str, str], list[float]] = {}
    with tempfile.TemporaryDirectory(prefix="train_timing_") as tmp:
        tmp = Path(tmp)
        for r in range(args.rounds):
            for algo in args.algo:
                if args.reference is not None:
                    progress(
                        f"round {r + 1}/{args.rounds}: {algo} on the reference env, "
                        f"{args.timesteps} steps ({h.machine_conditions()})"
                    )
                    wall = time_reference(
                        args.reference, algo, args.setup, args.variant, args.timesteps, args.torch_threads, tmp / "tb"
                    )
                    times.setdefault((algo, "reference"), []).append(wall)
                    progress(f"  reference: {wall:.1f} s")
                for n in args.n_envs:
                    progress(
                        f"round {r + 1}/{args.rounds}: {algo} through ROS on {n} line(s) ({h.machine_conditions()})"
                    )
                    how = (args.setup, args.variant, args.timesteps, args.torch_threads, tmp / "tb")
                    wall = time_ours(algo, *how, tmp / f"models_n{n}", n)
                    times.setdefault((algo, f"ros x{n}"), []).append(wall)
                    progress(f"  through ROS, {n} line(s): {wall:.1f} s")
    return times


def _print_table(args, times: dict[tuple[str, str], list[float]]) -> None:
    print(
        f"\n{args.timesteps} training steps, setup {args.setup} {args.variant}, torch threads {args.torch_threads}, "
        f"{args.rounds} round(s), medians ({h.machine_conditions()}):"
    )
    print("| algorithm | trained on | wall s | steps/s | vs reference |")
    print("|---|---|---|---|---|")
    for algo in args.algo:
        ref = statistics.median(times[(algo, "reference")]) if (algo, "reference") in times else None
        for side in (["reference"] if ref else []) + [f"ros x{n}" for n in args.n_envs]:
            wall = statistics.median(times[(algo, side)])
            label = "reference in-process env" if side == "reference" else f"ROS, {side[5:]} line(s) of one node"
            ratio = f"{wall / ref:.2f}x" if ref and side != "reference" else ""
            print(f"| {algo} | {label} | {wall:.1f} | {args.timesteps / wall:.0f} | {ratio} |")


def _print_projection(args, times: dict[tuple[str, str], list[float]]) -> None:
    """The full study's training time at the measured rates, when they were all measured."""
    n = max(args.n_envs)
    if (
        all((a, f"ros x{n}") in times for a in ("ppo", "dqn", "a2c"))
        and 1 in args.n_envs
        and all((a, "ros x1") in times for a in ("ppo", "dqn"))
    ):
        rate = {a: args.timesteps / statistics.median(times[(a, f"ros x{n}")]) for a in ("ppo", "dqn", "a2c")}
        one = {a: args.timesteps / statistics.median(times[(a, "ros x1")]) for a in ("ppo", "dqn")}
        total = sum(FULL_STUDY["cells_per_algo"] * FULL_STUDY["timesteps"] / rate[a] for a in rate)
        total += sum(k * FULL_STUDY["timesteps"] / one[a] for a, k in FULL_STUDY["one_line_cells"].items())
        hours = total / FULL_STUDY["jobs"] / 3600
        print(
            f"projected training time of run.sh --full (--n-envs {n}, {FULL_STUDY['jobs']} cells at once, "
            f"at these rates): "
            f"{hours:.1f} h (target < 2 h: {'met' if hours < 2 else 'NOT met'}; "
            f"measured one training at a time, so two at once on "
            f"2 cores may be slower; evaluations add about 20 s per cell)"
        )


def main() -> int:
    args = _parser().parse_args()
    if args.reference is not None and not (args.reference / "src" / "env_1_simple.py").is_file():
        sys.exit(
            f"train_timing.py: {args.reference} does not look like the reference checkout (no src/env_1_simple.py)"
        )
    h.run_isolated(__file__, "SORTING_LINE_TRAIN_TIMING_IN_NETNS")
    h.ros_environment("97")
    times = _time_all(args)
    _print_table(args, times)
    if args.reference is not None and "ppo" in args.algo and 1 in args.n_envs:
        ratio = statistics.median(times[("ppo", "ros x1")]) / statistics.median(times[("ppo", "reference")])
        print(
            f"PPO on one line, ours/reference: {ratio:.2f}x "
            f"(target <= {TARGET_RATIO}x: {'met' if ratio <= TARGET_RATIO else 'NOT met'})"
        )
    _print_projection(args, times)
    return 0


if __name__ == "__main__":
    sys.exit(main())
