"""`sorting-line-train`: Stable-Baselines3 PPO, DQN or A2C on a sorting line, through ROS 2.

    sorting-line-train --algo ppo --setup B --variant advanced            # the paper's PPO, 100k steps
    sorting-line-train --algo dqn --setup D --variant basic --hp learning_rate=3e-4 --timesteps 50000
    sorting-line-train --algo ppo --setup B --variant advanced --n-envs 8 # 8 lines of one node
    sorting-line-train --algo ppo --setup B --variant advanced --engine batched --seeds 42 43 44 45

The environment is the real thing: a `sorting_line` node process started for the run, stepped in
lock-step over DDS by the bridge (one env, or with ``n_envs`` > 1 N lines of one node stepped by
one round trip). Defaults are the paper's (``hyperparams/<algo>.yml``, see ``hyperparams``): seed
42, 100k steps, 250-step training episodes.

Writes ``<out>/<algo>_<setup>_<variant>_seed<seed>.zip`` (the SB3 model) and a ``.json`` beside it
(algorithm, line, hyperparameters, wall time, steps per second, versions), and TensorBoard logs
under ``<out>/tensorboard/`` with the line KPIs (``line/purity``, ``line/mean_speed``, ... see
``callbacks``). A progress bar shows the steps unless ``--no-progress``.

``--engine batched`` trains all ``--seeds`` at once in this process (``train_batched``,
``training/batched``), each seed's model and record written as above: on native lines by default,
or with ``--backend ros`` on the S x L lines of one node started for the run.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..agents.learned_policy import TRAIN_HINT, missing_training_stack
from ..envs.native import BACKENDS
from ..line.flags import call_with_flags
from ..line.vocabulary import SETUPS, VARIANT_CHOICE, VARIANTS, check_setup
from . import hyperparams
from .run_record import TrainingRun, model_stem, write_record

#: How sorting-line-train trains: SB3 itself, or the batched trainer (training/batched, train_batched).
ENGINES = ("sb3", "batched")


def make_training_env(setup: str, variant: str, n_envs: int, episode_steps: int, backend: str = "ros"):
    """The VecEnv SB3 trains on, wrapped in VecMonitor for episode statistics. One line is a
    single-line env in a DummyVecEnv (the fastest round trip); N lines share one node (ROS) or one
    batch (native). Either backend gives the same model for the same seed."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    if n_envs == 1:
        from ..envs.backends import line_env

        # node="spawn": the run owns its node, which stops with it (a stopped benchmark takes its nodes along).
        venv = DummyVecEnv(
            [
                lambda: line_env(
                    backend=backend, setup=setup, variant=variant, max_episode_steps=episode_steps, node="spawn"
                )
            ]
        )
    else:
        from ..envs.sb3_vec_env import SortingLineSB3VecEnv

        venv = SortingLineSB3VecEnv(
            num_envs=n_envs, setup=setup, variant=variant, max_episode_steps=episode_steps, backend=backend
        )
    return VecMonitor(venv)


def train(
    algo: str,
    setup: str,
    variant: str,
    *,
    seed: int = 42,
    out: str | Path = "models",
    params: dict[str, Any] | None = None,
    tensorboard: str | Path | None = None,
    progress: bool = True,
    torch_threads: int = 1,
    verbose: int = 0,
    backend: str = "ros",
    callbacks: Sequence[Any] = (),
) -> TrainingRun:
    """Trains ``algo`` on the line (setup, variant) with ``params`` (as ``hyperparams.load`` gives them,
    which checks them; default: the packaged hyperparameters) and saves the model; returns what it did.
    ``callbacks``: SB3 callbacks run beside the KPI one (a study's learning curve)."""
    import torch

    from .callbacks import LineKpiCallback

    check_setup(setup)
    params = params if params is not None else hyperparams.load(algo, variant)
    own, kwargs = hyperparams.split(params)
    # Small MLPs on 2 cores: one torch thread leaves the other core to the node and the bridge.
    torch.set_num_threads(torch_threads)
    (out := Path(out)).mkdir(parents=True, exist_ok=True)
    stem = model_stem(algo, setup, variant, seed)
    env = make_training_env(setup, variant, own["n_envs"], own["episode_steps"], backend)
    log_dir = None if tensorboard is None else str(tensorboard)
    try:
        model = hyperparams.algorithm_class(algo)(
            own["policy"], env, seed=seed, verbose=verbose, tensorboard_log=log_dir, **kwargs
        )
        kpis = LineKpiCallback()
        start = time.perf_counter()
        model.learn(
            total_timesteps=own["n_timesteps"], callback=[kpis, *callbacks], progress_bar=progress, tb_log_name=stem
        )
        wall = time.perf_counter() - start
        model_path = out / f"{stem}.zip"
        model.save(model_path)
    finally:
        env.close()
    return write_record(
        algo, setup, variant, own, kwargs, seed, model_path, episodes=kpis.episodes, wall=wall,
        steps_per_s=own["n_timesteps"] / wall, torch_threads=torch_threads,
    )  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sorting-line-train",
        description="Train Stable-Baselines3 PPO, DQN or A2C on a sorting line through ROS 2"
        " (the paper's settings by default).",
    )
    p.add_argument("--algo", required=True, choices=hyperparams.ALGOS, help="the Stable-Baselines3 algorithm")
    p.add_argument(
        "--setup",
        required=True,
        choices=list(SETUPS),
        help=", ".join(
            f"{name} {s['input']}{' + noise' if s['obs_noise'] else ''}{' + penalty' if s['action_penalty'] else ''}"
            for name, s in SETUPS.items()
        ),
    )
    p.add_argument("--variant", default="basic", choices=VARIANTS, help=f"{VARIANT_CHOICE} line (default %(default)s)")
    p.add_argument("--seed", type=int, help="seed of the algorithm and of the first training episodes (default 42)")
    p.add_argument(
        "--timesteps", type=int, help="training budget (default: n_timesteps of the hyperparameters, 100000)"
    )
    p.add_argument("--n-envs", type=int, help="lines trained on at once (default: n_envs of the hyperparameters, 1)")
    p.add_argument(
        "--hyperparams", metavar="FILE", help="RL Zoo style YAML file (default: the packaged hyperparams/<algo>.yml)"
    )
    p.add_argument(
        "--hp",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override one hyperparameter (value read as YAML); repeatable",
    )
    p.add_argument("--out", default="models", help="directory for the model and its JSON (default models/)")
    p.add_argument(
        "--tensorboard", metavar="DIR", help="TensorBoard log directory (default <out>/tensorboard; 'none' to disable)"
    )
    p.add_argument("--torch-threads", type=int, default=1, help="torch CPU threads (default 1)")
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        help="ros: lines of a sorting_line node over ROS 2; native: the line in-process (same model) "
        "(default ros; with --engine batched native, and ros means one node of seeds x n_envs lines)",
    )
    p.add_argument(
        "--engine",
        default="sb3",
        choices=ENGINES,
        help="sb3: Stable-Baselines3, one seed after another; batched: all --seeds at once in one process, "
        "each equal to SB3's run of that seed (training/batched) (default sb3)",
    )
    p.add_argument(
        "--seeds", type=int, nargs="+", metavar="S", help="several seeds, one model each (instead of --seed)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("-v", "--verbose", action="count", default=0, help="SB3's console log (-v)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    missing = missing_training_stack()
    if missing:
        print(f"sorting-line-train: needs {' and '.join(missing)}, the training stack: {TRAIN_HINT}", file=sys.stderr)
        return 2
    if args.seeds is not None and args.seed is not None:
        print("sorting-line-train: --seed and --seeds: allowed one of them", file=sys.stderr)
        return 2
    args.seeds = args.seeds or [42 if args.seed is None else args.seed]
    params = training_params(args)
    if params is None:
        return 2
    if args.engine == "batched":
        from .train_batched import main_batched

        return main_batched(args, params)
    args.backend = args.backend or "ros"
    tensorboard = None if args.tensorboard == "none" else (args.tensorboard or str(Path(args.out) / "tensorboard"))
    for seed in args.seeds:
        print(
            f"training {args.algo.upper()} on setup {args.setup} {args.variant}, seed {seed}: {params}",
            file=sys.stderr,
        )
        run = call_with_flags(
            train,
            args,
            args.algo,
            args.setup,
            args.variant,
            seed=seed,
            params=params,
            tensorboard=tensorboard,
            progress=not args.no_progress,
        )
        print(
            f"trained {run.n_timesteps} steps in {run.wall_s:.1f} s ({run.steps_per_s:.0f} steps/s"
            f", {run.episodes} episodes); "
            f"model {run.model_path}"
        )
    return 0


def training_params(args: argparse.Namespace) -> dict[str, Any] | None:
    """The hyperparameters of the flags (``hyperparams.load``), or None after printing why not."""
    overrides = list(args.hp)
    if args.timesteps is not None:
        overrides.append(f"n_timesteps={args.timesteps}")
    if args.n_envs is not None:
        overrides.append(f"n_envs={args.n_envs}")
    if args.torch_threads < 1:
        print(
            f"sorting-line-train: --torch-threads = {args.torch_threads} is not valid: allowed 1 or more",
            file=sys.stderr,
        )
        return None
    try:
        return hyperparams.load(args.algo, args.variant, args.hyperparams, overrides)
    except ValueError as e:
        print(f"sorting-line-train: {e}", file=sys.stderr)
        return None


if __name__ == "__main__":
    sys.exit(main())
