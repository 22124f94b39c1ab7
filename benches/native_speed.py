"""Steps per second of the native backend (``backend="native"``: the Rust line in-process) beside
the reference implementation's env (SortingEnv's own Python env, in this process, same setup), in
one run, and optionally the wall time of PPO training on the native backend, the ROS backend and the
reference env.

    .venv/bin/python benches/native_speed.py --reference /path/to/2024_Sorting_Env
    .venv/bin/python benches/native_speed.py --reference DIR --ppo --timesteps 100000   # + PPO (minutes)

Rows: the reference env stepped directly (its class, random actions, a reset every 50 steps); one
native env through ``gymnasium.make`` (its wrappers included); the native vector env at N lines
(``make_vec(..., vectorization_mode="vector_entry_point")``, line-steps/s = N x calls/s). Targets:
one native env >= 10x the reference's steps/s, the vector env at 256 lines >= 100x. Each figure is
the median of ``--rounds`` timed runs of ``--seconds`` each; actions are drawn before timing.
``--ppo`` adds PPO with the paper's settings (hyperparams/ppo.yml) for ``--timesteps`` steps on one
line: native, ROS (as root re-executed under ``unshare -n``, DDS on loopback) and the reference
(``train_timing.py``'s way), wall time of ``model.learn`` alone.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benches"))

import numpy as np  # noqa: E402

from sorting_line_gym.line.vocabulary import ENV_IDS, SETUPS, THRESHOLD, VARIANTS  # noqa: E402

EPISODE = 50
TARGETS = {"single": 10.0, "vector": 100.0}


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def reference_env(ref_dir: Path, setup: str, variant: str):
    """The reference's env class, built as train_timing.py builds it."""
    from train_timing import REFERENCE_SETUPS, import_reference_env  # the one way in

    env_class = import_reference_env(ref_dir, variant)
    return env_class(max_steps=EPISODE, threshold=THRESHOLD, **REFERENCE_SETUPS[setup])


def steps_per_second(step, reset, n_actions: int, seconds: float, batch: int = 1) -> float:
    """Steps (line-steps for a batch) per second of ``step`` over ``seconds``, a reset every episode."""
    actions = np.random.default_rng(0).integers(0, n_actions, (4096, batch) if batch > 1 else 4096)
    actions = actions if batch > 1 else actions.tolist()
    reset()
    done, t = 0, 0
    start = time.perf_counter()
    deadline = start + seconds
    while True:
        for a in actions:
            step(a)
            t += 1
            if batch == 1 and t == EPISODE:
                reset()
                t = 0
        done += len(actions)
        if time.perf_counter() > deadline:
            break
    return done * batch / (time.perf_counter() - start)


def measure(args) -> dict[str, float]:
    import gymnasium

    import sorting_line_gym  # noqa: F401 - registers the ids

    env_id = f"sorting_line_gym:{ENV_IDS[args.variant]}"
    runs: dict[str, list[float]] = {}
    for r in range(args.rounds):
        progress(f"round {r + 1}/{args.rounds}")
        if args.reference is not None:
            ref = reference_env(args.reference, args.setup, args.variant)
            ref.reset(seed=100)
            rate = steps_per_second(ref.step, ref.reset, ref.action_space.n, args.seconds)
            runs.setdefault("reference env", []).append(rate)
        env = gymnasium.make(env_id, setup=args.setup, backend="native")
        rate = steps_per_second(env.step, env.reset, env.action_space.n, args.seconds)
        runs.setdefault("native, one env (gymnasium.make)", []).append(rate)
        for n in args.lines:
            vec = gymnasium.make_vec(
                env_id, num_envs=n, vectorization_mode="vector_entry_point", setup=args.setup, backend="native"
            )
            vec.reset(seed=1)
            rate = steps_per_second(vec.step, lambda: None, vec.single_action_space.n, args.seconds, batch=n)
            runs.setdefault(f"native, vector env of {n} lines", []).append(rate)
    return {name: statistics.median(v) for name, v in runs.items()}


def time_ppo(args) -> dict[str, float]:
    """Wall seconds of PPO's ``model.learn`` on one line: native, ROS and (with --reference) the reference."""
    from train_timing import time_ours, time_reference

    walls = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.reference is not None:
            progress("PPO on the reference env")
            walls["reference"] = time_reference(
                args.reference, "ppo", args.setup, args.variant, args.timesteps, 1, tmp / "tb"
            )
        for backend in ("native", "ros"):
            progress(f"PPO on the {backend} backend")
            walls[backend] = time_ours(
                "ppo", args.setup, args.variant, args.timesteps, 1, tmp / "tb", tmp / backend, backend=backend
            )
    return walls


def machine() -> str:
    load = os.getloadavg()
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), "?")
    return f"{os.cpu_count()} CPUs ({cpu}), load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"


def report(args, rates: dict[str, float], walls: dict[str, float] | None) -> None:
    ref = rates.get("reference env")
    print(f"setup {args.setup} {args.variant}; {machine()}")
    print(f"command: {' '.join(sys.argv)}")
    print("| env | steps/s (median) | vs reference | target |")
    print("|---|---:|---:|---:|")
    for name, rate in rates.items():
        ratio = f"{rate / ref:.1f}x" if ref and name != "reference env" else ""
        target = ""
        if name.startswith("native, one env"):
            target = f">= {TARGETS['single']:.0f}x"
        elif name == "native, vector env of 256 lines":
            target = f">= {TARGETS['vector']:.0f}x"
        print(f"| {name} | {rate:,.0f} | {ratio} | {target} |")
    if walls:
        print(f"\nPPO, {args.timesteps} steps, the paper's settings, one line (wall s of model.learn):")
        for side, wall in walls.items():
            print(f"  {side:9s} {wall:8.1f} s  {args.timesteps / wall:8.0f} steps/s")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--reference", type=Path, help="checkout of the reference implementation (2024_Sorting_Env)")
    p.add_argument("--setup", default="B", choices=tuple(SETUPS))
    p.add_argument("--variant", default="advanced", choices=VARIANTS)
    p.add_argument("--lines", type=int, nargs="+", default=[16, 256], help="vector env sizes (default 16 256)")
    p.add_argument("--seconds", type=float, default=2.0, help="timed seconds per figure and round")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--ppo", action="store_true", help="also time PPO training (minutes; ROS needs root for unshare)")
    p.add_argument("--timesteps", type=int, default=100_000)
    return p


def main() -> int:
    args = parser().parse_args()
    if args.reference is not None and not (args.reference / "src" / "env_1_simple.py").is_file():
        sys.exit(f"native_speed.py: {args.reference} is not the reference checkout (no src/env_1_simple.py)")
    if args.ppo and os.geteuid() == 0 and not os.environ.get("SORTING_LINE_NETNS"):
        script = 'ip link set lo up && exec "$0" "$@"'
        env = dict(os.environ, SORTING_LINE_NETNS="1")
        cmd = ["unshare", "-n", "bash", "-c", script, sys.executable, *sys.argv]
        return subprocess.run(cmd, env=env).returncode
    rates = measure(args)
    walls = time_ppo(args) if args.ppo else None
    report(args, rates, walls)
    return 0


if __name__ == "__main__":
    sys.exit(main())
