"""`sorting-line-bridge`: run episodes through the Gymnasium bridge and print their KPIs.

    sorting-line-bridge --setup B --variant advanced --episodes 3 --agent constant:2
    sorting-line-bridge --node attach --namespace /plant --agent random --dashboard run.png

It is the smallest complete client of the bridge: it spawns (or attaches to) a node, resets with
the paper's evaluation seeds (42, 43, ...), acts, and reports reward, mean speed, purity and speed
changes per episode; ``--dashboard`` saves the last episode's dashboard.
"""

from __future__ import annotations

import argparse
import sys

import gymnasium as gym
import numpy as np

from ..line.errors import BridgeError
from ..line.vocabulary import (
    ENV_IDS,
    EVAL_FIRST_SEED,
    MODE_COUNT,
    MODES,
    SETUP_SPAN,
    SETUPS,
    SPEED_COUNT,
    VARIANT_CHOICE,
    VARIANTS,
    encode_actions,
)


def parse_agent(text: str, variant: str):
    """``random`` (seeded) or ``constant:K`` / ``constant:K:M`` as Gymnasium actions."""
    if text == "random":
        return None
    parts = text.split(":")
    try:
        if parts[0] != "constant" or len(parts) not in (2, 3):
            raise ValueError
        speed = int(parts[1])
        mode = int(parts[2]) if len(parts) == 3 else 0
        if speed not in range(SPEED_COUNT) or mode not in MODES.values() or (mode and variant == "basic"):
            raise ValueError
    except ValueError:
        raise SystemExit(
            f"sorting-line-bridge: agent {text!r} is not valid: allowed random, constant:K (K = 0..{SPEED_COUNT - 1}) "
            f"or, on the advanced line, constant:K:M (M = 0..{MODE_COUNT - 1})"
        ) from None
    return encode_actions(variant, speed, mode)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sorting-line-bridge", description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--setup", choices=list(SETUPS), default="A", help=f"the paper's setup {SETUP_SPAN} (default %(default)s)"
    )
    p.add_argument("--variant", choices=VARIANTS, default="basic", help=f"{VARIANT_CHOICE} line (default %(default)s)")
    p.add_argument("--episodes", type=int, default=3, help="episodes to run (default %(default)s)")
    p.add_argument("--seed", type=int, default=EVAL_FIRST_SEED, help="episode i is reset with seed + i")
    p.add_argument("--agent", default="random", help="random, constant:K or constant:K:M")
    p.add_argument(
        "--node",
        choices=["spawn", "attach"],
        default="spawn",
        help="spawn a node of its own, or attach to the one serving --namespace (default %(default)s)",
    )
    p.add_argument("--namespace", default=None, help="namespace of the node (needed with --node attach)")
    p.add_argument("--step-timeout", type=float, default=2.0, help="longest wait for one step, s (default %(default)s)")
    p.add_argument("--dashboard", default=None, help="save the last episode's dashboard (.png or .svg)")
    return p


def _run_episodes(env, args, action) -> list[float]:
    """Runs ``args.episodes`` episodes, a line printed for each; returns their rewards."""
    rewards = []
    for i in range(args.episodes):
        obs, info = env.reset(seed=args.seed + i)
        total, speeds, done = 0.0, [], False
        while not done:
            a = env.action_space.sample() if action is None else action
            obs, r, terminated, truncated, info = env.step(a)
            total += r
            speeds.append(info["speed"])
            done = terminated or truncated
        rewards.append(total)
        print(
            f"{i:7d} {args.seed + i:5d} {total:7.2f} {np.mean(speeds):10.2f}"
            f" {info['purity']:7.3f} {info['speed_changes']:14d}"
        )
    return rewards


def main(argv: list[str] | None = None) -> int:
    p = _parser()
    args = p.parse_args(argv)
    if args.episodes < 1:
        p.error(f"--episodes {args.episodes} is out of range: allowed 1 or more")
    action = parse_agent(args.agent, args.variant)
    env_id = f"sorting_line_gym:{ENV_IDS[args.variant]}"
    try:
        env = gym.make(
            env_id,
            setup=args.setup,
            node=args.node,
            namespace=args.namespace,
            step_timeout=args.step_timeout,
            render_mode="rgb_array" if args.dashboard else None,
        )
    except (BridgeError, ValueError) as e:
        print(f"sorting-line-bridge: {e}", file=sys.stderr)
        return 2
    try:
        env.action_space.seed(args.seed)
        print(f"{env_id} setup {args.setup}, agent {args.agent}, node {env.unwrapped.namespace}")
        print("episode  seed  reward  mean speed  purity  speed changes")
        rewards = _run_episodes(env, args, action)
        print(f"mean reward {np.mean(rewards):.2f} +- {np.std(rewards):.2f} over {args.episodes} episodes")
        if args.dashboard:
            from ..envs.render import save_dashboard

            save_dashboard(env.unwrapped.dashboard_frame(), args.dashboard)
            print(f"dashboard: {args.dashboard}")
    except BridgeError as e:
        print(f"sorting-line-bridge: {e}", file=sys.stderr)
        return 1
    finally:
        env.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
