"""Speed of the batched trainer (training/batched) against SB3, side by side in one run: wall time
per seed of a training at the paper's settings (hyperparams/<algo>.yml: one line per seed,
250-step episodes, 100k steps), the engine with S = 1, 4, 16, 32 seeds at once against SB3's own
``learn`` on ``sorting-line-train --backend native``'s env, one torch thread and one XLA thread
(the engine's arithmetic is JAX's: a per-core figure, as SB3 trains with one torch thread),
native backend:

    .venv/bin/python benches/batched_training.py                           # PPO and A2C, 100k steps
    .venv/bin/python benches/batched_training.py --algos ppo --seeds 1 16 --timesteps 20000
    .venv/bin/python benches/batched_training.py --algos ppo --update-only  # one PPO update per seed
    .venv/bin/python benches/batched_training.py --algos ppo a2c dqn --reference DIR  # + the reference env

Before the trainings, one PPO update (10 epochs of 32 minibatches of 64 over a 2048-step rollout)
and one 2048-step rollout are timed per seed, engine at each S against SB3's ``train()`` and
``collect_rollouts``, with the rollout's share spent stepping the lines (the same 2048 steps of
the S x L lines alone) and the first update's time with JAX's compilation. Model building is
excluded on both sides; neither side writes logs or shows a progress bar. JAX runs asynchronously:
every engine time waits for its results (``jax.block_until_ready``). Prints wall and CPU time
(this process's: the steadier figure on a shared machine), the ratios, the command and the load
average before and after: the figures move with what else runs, so both sides are measured in
the same run. With ``--reference DIR`` (a checkout of the reference implementation) each
algorithm is also trained by SB3 on the reference's own env, as its utils/benchmark.py does; each
engine run prints the process's peak memory and what each added seed added to it.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

# One XLA thread, set before JAX starts its CPU backend: the figures are per core, as SB3's with one
# torch thread (on a shared machine a second thread would only wait).
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from sorting_line_gym.training import hyperparams  # noqa: E402
from sorting_line_gym.training.train import make_training_env  # noqa: E402
from sorting_line_gym.training.train_batched import trainer  # noqa: E402

LINE = dict(setup="B", variant="advanced")


class Clock:
    """Wall and CPU time (this process's) of a block: on a busy machine the CPU time is the steadier
    figure, the wall time what a user waits. benches/batched_dqn.py times with it too."""

    def __enter__(self):
        self.wall, self.cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall, self.cpu = time.perf_counter() - self.wall, time.process_time() - self.cpu

    def per(self, n: int) -> tuple[float, float]:
        return self.wall / n, self.cpu / n


def paper(algo: str, timesteps: int | None = None) -> tuple[dict, dict]:
    overrides = [] if timesteps is None else [f"n_timesteps={timesteps}"]
    return hyperparams.split(hyperparams.load(algo, LINE["variant"], overrides=overrides))


def sb3_model(algo: str, seed: int = 42):
    own, kwargs = paper(algo)
    env = make_training_env(**LINE, n_envs=own["n_envs"], episode_steps=own["episode_steps"], backend="native")
    return hyperparams.algorithm_class(algo)("MlpPolicy", env, seed=seed, device="cpu", **kwargs), env


def update_times(seed_counts: list[int]) -> dict[str, dict[int, tuple[float, float]]]:
    """Seconds per seed of one PPO rollout and one PPO update: SB3 (key 0) and the engine at each S;
    the engine's line steps alone ("lines") and its first update with compilation ("first")."""
    from stable_baselines3.common.callbacks import ConvertCallback
    from stable_baselines3.common.logger import Logger

    model, env = sb3_model("ppo")
    model.learn(2048)  # warm: one rollout and update, the logger set up
    model.set_logger(Logger(None, []))
    callback = ConvertCallback(None)  # no callback, as learn() without one
    callback.init_callback(model)
    with Clock() as rollout:
        model.collect_rollouts(model.env, callback, model.rollout_buffer, model.n_steps)
    with Clock() as update:
        model.train()
    env.close()
    out: dict[str, dict[int, tuple[float, float]]] = {"rollout": {0: rollout.per(1)}, "update": {0: update.per(1)},
                                                      "lines": {0: (0.0, 0.0)}, "first": {0: (0.0, 0.0)}}  # fmt: skip
    own, kwargs = paper("ppo")
    for n in seed_counts:
        engine = trainer("ppo", LINE["setup"], LINE["variant"], list(range(42, 42 + n)), own, kwargs)
        with Clock() as first:  # a rollout and the first update, compiling both
            engine.learn(2048)
            jax.block_until_ready(engine.params)
        with Clock() as rollout:
            engine.collect_rollout()
        with Clock() as update:
            engine.train()
            jax.block_until_ready(engine.params)
        actions = np.zeros((n, engine.lines.n_lines), dtype=np.int64)
        with Clock() as lines:
            for _ in range(2048):
                engine.lines.step(actions)
        engine.close()
        out["rollout"][n], out["update"][n], out["lines"][n] = rollout.per(n), update.per(n), lines.per(n)
        out["first"][n] = (first.wall - rollout.wall - update.wall, first.cpu - rollout.cpu - update.cpu)
    return out


def peak_mb() -> float:
    """This process's peak resident memory so far (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def training_times(algo: str, seed_counts: list[int], timesteps: int) -> dict[int, tuple[float, float]]:
    """Seconds of training per seed: SB3 (key 0, one seed) and the engine with S seeds at once, S
    rising. Prints the process's peak memory after each engine and what each seed beyond the last S
    added to it: the first engine's figure carries JAX's runtime, the later ones the seeds alone."""
    model, env = sb3_model(algo)
    with Clock() as clock:
        model.learn(timesteps)
    env.close()
    out, (last_n, last_peak) = {0: clock.per(1)}, (0, peak_mb())
    own, kwargs = paper(algo, timesteps)
    for n in sorted(seed_counts):
        engine = trainer(algo, LINE["setup"], LINE["variant"], list(range(42, 42 + n)), own, kwargs)
        with Clock() as clock:
            engine.learn(timesteps)
            jax.block_until_ready(engine.params)
        engine.close()
        out[n] = clock.per(n)
        peak = peak_mb()
        print(f"{algo.upper()} engine S={n}: peak memory {peak:.0f} MB, {max(peak - last_peak, 0) / (n - last_n):.1f} "
              f"MB a seed beyond S={last_n}", flush=True)  # fmt: skip
        last_n, last_peak = n, peak
    return out


def reference_time(ref_dir: Path, algo: str, timesteps: int, tmp: Path) -> float:
    """Wall seconds of SB3's ``learn`` on the reference implementation's own env (as its
    utils/benchmark.py trains; benches/train_timing.py's ``time_reference``, progress bar and all)."""
    from train_timing import time_reference  # this folder is on sys.path when a bench runs as a script

    return time_reference(ref_dir, algo, LINE["setup"], LINE["variant"], timesteps, 1, tmp / algo)


def report(what: str, times: dict[int, tuple[float, float]], scale: float, unit: str) -> None:
    (wall0, cpu0), fmt = times[0], lambda w, c: f"wall {w * scale:.3f} {unit}, CPU {c * scale:.3f} {unit}"
    print(f"{what}, SB3 one seed: {fmt(wall0, cpu0)}", flush=True)
    for n, (wall, cpu) in times.items():
        if n:
            print(
                f"{what}, engine S={n}, per seed: {fmt(wall, cpu)} ({wall0 / wall:.1f}x wall, {cpu0 / cpu:.1f}x CPU)",
                flush=True,
            )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--algos", nargs="+", default=["ppo", "a2c"], choices=hyperparams.ALGOS, help="(default ppo a2c)")
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 4, 16, 32], help="S, seeds at once (default 1 4 16 32)")
    p.add_argument("--timesteps", type=int, default=100_000, help="steps per seed of a training (default 100000)")
    p.add_argument("--update-only", action="store_true", help="time one PPO rollout and update only")
    p.add_argument("--reference", type=Path, help="also SB3 on the reference implementation's env (its checkout)")
    args = p.parse_args()
    if args.reference is not None and not (args.reference / "src" / "env_1_simple.py").is_file():
        sys.exit(f"batched_training.py: {args.reference} is not the reference checkout (no src/env_1_simple.py)")
    torch.set_num_threads(1)
    print(f"command: {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    print(f"XLA_FLAGS={os.environ['XLA_FLAGS']}; JAX {jax.__version__} on {jax.devices()[0].platform}")
    print(f"load average before: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores", flush=True)
    if "ppo" in args.algos:
        times = update_times(args.seeds)
        report("PPO 2048-step rollout", times["rollout"], 1.0, "s")
        report("PPO update (10 epochs x 32 minibatches)", times["update"], 1.0, "s")
        for n in args.seeds:
            (lw, lc), (rw, _) = times["lines"][n], times["rollout"][n]
            print(f"S={n}: the lines' 2048 steps alone, per seed: wall {lw:.3f} s, CPU {lc:.3f} s "
                  f"({100 * lw / rw:.0f}% of the rollout's wall time); JAX's compilation and first "
                  f"calls: about {times['first'][n][0]:.1f} s wall once per training", flush=True)  # fmt: skip
    if not args.update_only:
        for algo in args.algos:
            times = training_times(algo, args.seeds, args.timesteps)
            report(f"{algo.upper()} {args.timesteps}-step training", times, 1.0, "s")
            if args.reference is not None:
                with tempfile.TemporaryDirectory() as tmp:
                    ref = reference_time(args.reference, algo, args.timesteps, Path(tmp))
                best = min(wall for n, (wall, _) in times.items() if n)
                print(f"{algo.upper()} on the reference env (SB3, one seed): wall {ref:.3f} s; SB3 native "
                      f"{ref / times[0][0]:.2f}x it, the engine's best S {ref / best:.1f}x it", flush=True)  # fmt: skip
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
