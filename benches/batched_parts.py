"""Where the batched trainer's time goes, part by part (training/batched), and the two choices its
speed rests on, each timed against the alternative in the same run, one XLA thread, CPU time of
this process (the steadier figure on a shared machine) per call:

    .venv/bin/python benches/batched_parts.py                 # S = 32, setup B advanced
    .venv/bin/python benches/batched_parts.py --seeds 16 --calls 500

1. The rollout's forward pass for S seeds of one line each (one row per seed): numpy on the host
   (``host.HostPolicy.act``, what the trainer runs) against the jitted ``act`` it replaced
   (``actor_critic.JittedPolicy``), for the paper's PPO/A2C networks; and one stacked layer
   (S, 1, 64) x (S, 64, 64) alone, XLA against numpy.
2. A matmul of one minibatch (S, B, 64) x (S, 64, 64) in XLA on the weight as the engine stores it
   (W.T, contiguous: ``params.forward``) against the earlier ``x @ barrier(W.T)``, which copied W
   transposed at each use; the same bits either way (printed).
3. One update per algorithm at the paper's settings (PPO: 10 epochs of 32 minibatches; A2C: one
   5-step update; DQN: one gradient step with its replay batch), a 5-step rollout of A2C, a DQN
   replay sample and a 4-step DQN rollout, per S seeds.

Prints each figure with the machine's load average before and after.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from batched_training import LINE, paper  # noqa: E402  (this folder is on sys.path when a bench runs as a script)
from sorting_line_gym.training.batched import host  # noqa: E402
from sorting_line_gym.training.batched.actor_critic import JittedPolicy, exponential_noise  # noqa: E402
from sorting_line_gym.training.train_batched import trainer  # noqa: E402


def cpu_us(f, calls: int) -> float:
    """CPU microseconds per call of ``f`` (after one call that compiles)."""
    f()
    start = time.process_time()
    for _ in range(calls):
        f()
    return (time.process_time() - start) / calls * 1e6


def matmul(w: np.ndarray, x: np.ndarray, calls: int) -> str:
    """One stacked layer x @ W.T three ways; ``w`` in torch's layout (S, out, in)."""
    w_t = np.ascontiguousarray(w.transpose(0, 2, 1))  # the engine's layout (in, out)
    copied = jax.jit(jax.vmap(lambda w, x: x @ jax.lax.optimization_barrier(w.T)))
    stored = jax.jit(jax.vmap(lambda w_t, x: x @ w_t))
    wj, wtj, xj = jax.numpy.asarray(w), jax.numpy.asarray(w_t), jax.numpy.asarray(x)
    t_copied = cpu_us(lambda: jax.block_until_ready(copied(wj, xj)), calls)
    t_stored = cpu_us(lambda: jax.block_until_ready(stored(wtj, xj)), calls)
    t_numpy = cpu_us(lambda: np.matmul(x, w_t), calls)
    same = np.array_equal(np.asarray(copied(wj, xj)), np.asarray(stored(wtj, xj)))
    return (
        f"XLA on W.T as stored {t_stored:.1f} us, XLA with a transposed copy of W {t_copied:.1f} us "
        f"(same bits: {same}), numpy {t_numpy:.1f} us"
    )


def matmuls(seeds: int, calls: int) -> None:
    rng = np.random.default_rng(0)
    w = rng.standard_normal((seeds, 64, 64), dtype=np.float32)
    for rows in (1, 64):
        x = rng.standard_normal((seeds, rows, 64), dtype=np.float32)
        print(f"matmul ({seeds}, {rows}, 64) x ({seeds}, 64, 64): {matmul(w, x, calls)}", flush=True)


def on_policy_parts(algo: str, seeds: int, calls: int) -> None:
    own, kwargs = paper(algo, 2048)
    engine = trainer(algo, LINE["setup"], LINE["variant"], list(range(42, 42 + seeds)), own, kwargs)
    engine.learn(2048 if algo == "ppo" else 500)  # builds, compiles, and leaves a filled rollout
    obs = engine._last_obs
    q = exponential_noise(engine.generators, (1, engine.lines.n_lines, engine.lines.n_actions))[:, 0]
    on_host = host.HostPolicy(engine.specs, engine.params)
    jitted = JittedPolicy(engine.compiled, engine.params)
    t_host, t_jit = cpu_us(lambda: on_host.act(obs, q), calls), cpu_us(lambda: jitted.act(obs, q), calls)
    print(f"{algo.upper()} rollout forward, S={seeds}: host {t_host:.1f} us, jitted {t_jit:.1f} us a step", flush=True)

    def update():
        engine.train()
        jax.block_until_ready(engine.params)

    t_update = cpu_us(update, max(calls // (100 if algo == "ppo" else 5), 3))
    line = f"{algo.upper()} update, S={seeds}: {t_update / 1e3:.2f} ms ({t_update / seeds / 1e3:.3f} ms a seed)"
    if algo == "a2c":
        line += f"; a 5-step rollout {cpu_us(engine.collect_rollout, calls // 5) / 1e3:.2f} ms"
    print(line, flush=True)
    engine.close()


def dqn_parts(seeds: int, calls: int) -> None:
    own, kwargs = paper("dqn", 3000)
    engine = trainer("dqn", LINE["setup"], LINE["variant"], list(range(42, 42 + seeds)), own, kwargs)
    engine.learn(3000)
    batch = engine.replay.sample(1, engine.batch_size, engine.np_rngs)
    t_step = cpu_us(lambda: np.asarray(engine._gradient_steps(batch)), calls)  # (dispatched: wait for it)
    t_sample = cpu_us(lambda: engine.replay.sample(1, engine.batch_size, engine.np_rngs), calls)
    t_rollout = cpu_us(engine._collect_rollout, calls)
    per_seed = (t_step + t_sample + t_rollout) / seeds / 1e3
    print(f"DQN, S={seeds}: gradient step {t_step / 1e3:.2f} ms, replay sample {t_sample / 1e3:.2f} ms, 4-step "
          f"rollout {t_rollout / 1e3:.2f} ms: {per_seed:.3f} ms a seed per 4 steps", flush=True)  # fmt: skip
    engine.close()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--seeds", type=int, default=32, help="S, seeds at once (default 32)")
    p.add_argument("--calls", type=int, default=1000, help="calls timed per part (default 1000)")
    args = p.parse_args()
    if args.seeds < 1 or args.calls < 10:
        p.error(f"--seeds {args.seeds} --calls {args.calls}: allowed --seeds >= 1 and --calls >= 10")
    torch.set_num_threads(1)
    print(f"command: {' '.join([sys.executable, *sys.argv])}; load average before: {os.getloadavg()}", flush=True)
    matmuls(args.seeds, args.calls)
    for algo in ("a2c", "ppo"):
        on_policy_parts(algo, args.seeds, args.calls)
    dqn_parts(args.seeds, args.calls)
    print(f"load average after: {os.getloadavg()}", flush=True)


if __name__ == "__main__":
    main()
