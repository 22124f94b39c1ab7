"""Speed of the batched DQN (training/batched/dqn.py) against SB3's DQN, side by side in one run,
on the native backend with the paper's DQN settings (hyperparams/dqn.yml: gamma 0.95, SB3's
defaults otherwise, one line per seed, 250-step episodes), one torch thread and one XLA thread:

    .venv/bin/python benches/batched_dqn.py                       # gradient steps, then 20k-step trainings
    .venv/bin/python benches/batched_dqn.py --seeds 1 4 16 32 --timesteps 100000

1. One gradient step (a replay batch of 32 sampled, TD target, Huber loss, backward, per-seed clip,
   Adam), one ``train(gradient_steps=1)`` call each as at the paper's settings: the engine's for S
   seeds at once, per seed, against SB3's.
2. A whole training of ``--timesteps`` steps per seed: the engine with S seeds at once (wall time
   per seed) against SB3's ``DQN.learn`` on ``sorting-line-train --backend native``'s env (no
   progress bar, no TensorBoard on either side; model building excluded on both).
3. Where the engine's time goes at the largest S: the gradient steps (one jitted call per
   ``train``), the replay batches (each seed's generator draws the indices, then the gather), the
   rollout's greedy forward, the native lines' step, and the rest (the loop, the buffers' writes,
   the epsilon coins and random actions, the counters).

Prints the times and the ratios, and the load average: on a shared machine the figures move with
what else runs, so both sides are measured in the same run.
"""

from __future__ import annotations

import argparse
import os
import time
from collections import defaultdict

import numpy as np
import torch

from batched_training import Clock  # this folder is on sys.path when a bench runs as a script
from sorting_line_gym.training import hyperparams
from sorting_line_gym.training.batched.dqn import BatchedDQN
from sorting_line_gym.training.train import make_training_env

LINE = dict(setup="B", variant="advanced")


def paper_settings() -> tuple[dict, dict]:
    return hyperparams.split(hyperparams.load("dqn", LINE["variant"]))


def gradient_step_times(seeds: list[int], rounds: int) -> dict[int, tuple[float, float]]:
    """Seconds per gradient step per seed: SB3 (key 0) and the engine at each S."""
    own, kwargs = paper_settings()
    kw = {**kwargs, "learning_starts": 10**9}  # fill the buffer only
    env = make_training_env(**LINE, n_envs=1, episode_steps=own["episode_steps"], backend="native")
    from stable_baselines3 import DQN

    model = DQN("MlpPolicy", env, seed=0, device="cpu", **kw).learn(2000)
    model.train(gradient_steps=10, batch_size=model.batch_size)
    with Clock() as clock:
        for _ in range(rounds):  # one step per call, as a training at the paper's settings calls it
            model.train(gradient_steps=1, batch_size=model.batch_size)
    out = {0: clock.per(rounds)}
    env.close()
    for n in seeds:
        engine = BatchedDQN(range(n), **LINE, episode_steps=own["episode_steps"], **kw).learn(2000)
        for _ in range(10):  # compiles the one-step call first
            np.asarray(engine.train(1, engine.batch_size))
        with Clock() as clock:
            for _ in range(rounds):
                np.asarray(engine.train(1, engine.batch_size))  # (train() dispatches; this waits)
        out[n] = clock.per(rounds * n)
        engine.close()
    return out


def training_times(seeds: list[int], timesteps: int) -> dict[int, tuple[float, float]]:
    """Seconds of training per seed: SB3 (key 0, one seed) and the engine with S seeds at once."""
    from stable_baselines3 import DQN

    own, kwargs = paper_settings()
    env = make_training_env(**LINE, n_envs=1, episode_steps=own["episode_steps"], backend="native")
    model = DQN("MlpPolicy", env, seed=42, device="cpu", **kwargs)
    with Clock() as clock:
        model.learn(timesteps)
    out = {0: clock.per(1)}
    env.close()
    for n in seeds:
        engine = BatchedDQN(range(42, 42 + n), **LINE, episode_steps=own["episode_steps"], **kwargs)
        with Clock() as clock:
            engine.learn(timesteps)
        out[n] = clock.per(n)
        engine.close()
    return out


def where_time_goes(n: int, timesteps: int) -> dict[str, float]:
    """Seconds (wall) of each part of a training of ``n`` seeds for ``timesteps`` steps."""
    own, kwargs = paper_settings()
    engine = BatchedDQN(range(42, 42 + n), **LINE, episode_steps=own["episode_steps"], **kwargs)
    spent: dict[str, float] = defaultdict(float)

    def timed(obj, name: str, part: str) -> None:
        inner = getattr(obj, name)

        def wrapper(*args, **kw):
            t = time.perf_counter()
            try:
                return inner(*args, **kw)
            finally:
                spent[part] += time.perf_counter() - t

        setattr(obj, name, wrapper)

    engine.learn(1)  # builds the lines and buffers, compiles; then the parts are wrapped
    timed(engine, "_gradient_steps", "gradient steps (jitted)")
    timed(engine.replay, "sample", "replay batches (indices + gather)")
    timed(engine.q_learning, "act", "rollout forward (greedy actions)")
    timed(engine.lines, "step", "native lines' step")
    with Clock() as clock:
        engine.learn(timesteps, reset_num_timesteps=False)
    engine.close()
    spent["rest (loop, buffer writes, coins, random actions)"] = clock.wall - sum(spent.values())
    return {"total": clock.wall, **spent}


def report(what: str, times: dict[int, tuple[float, float]], scale: float, unit: str) -> None:
    (wall0, cpu0), fmt = times[0], lambda w, c: f"wall {w * scale:.3f} {unit}, CPU {c * scale:.3f} {unit}"
    print(f"{what}, SB3 one seed: {fmt(wall0, cpu0)}")
    for n, (wall, cpu) in times.items():
        if n:
            print(f"{what}, engine S={n}, per seed: {fmt(wall, cpu)} ({wall0 / wall:.1f}x wall, {cpu0 / cpu:.1f}x CPU)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 4, 16, 32], help="S, seeds at once (default 1 4 16 32)")
    p.add_argument("--timesteps", type=int, default=20_000, help="steps per seed of a training (default 20000)")
    p.add_argument("--rounds", type=int, default=300, help="gradient steps timed (default 300)")
    p.add_argument("--skip-training", action="store_true", help="time the gradient steps only")
    p.add_argument("--skip-profile", action="store_true", help="leave out where the engine's time goes")
    args = p.parse_args()
    torch.set_num_threads(1)
    print(
        f"load average before: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; XLA_FLAGS={os.environ['XLA_FLAGS']}"
    )
    report("gradient step", gradient_step_times(args.seeds, args.rounds), 1e3, "ms")
    if not args.skip_training:
        report(f"{args.timesteps}-step training", training_times(args.seeds, args.timesteps), 1.0, "s")
    if not args.skip_profile:
        n = max(args.seeds)
        parts = where_time_goes(n, args.timesteps)
        total = parts.pop("total")
        print(f"where the time goes, engine S={n}, {args.timesteps} steps: {total:.2f} s wall")
        for part, seconds in parts.items():
            print(f"  {part}: {seconds:.2f} s ({100 * seconds / total:.0f}%)")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
