"""`sorting-line-eval`: an agent on a sorting line through ROS 2, with the paper's protocol.

    sorting-line-eval --agent rba-hold --setup B --variant advanced
    sorting-line-eval --agent ppo:models/ppo_B_advanced_seed42.zip --setup B --variant advanced --out results/

Protocol (the reference's ``utils/benchmark.py``): episode i is reset with seed 42 + i (10
episodes, 50 steps each), the agent acts deterministically (the random agent is reseeded with the
episode's seed), and the score is the episode's summed reward; mean and population standard
deviation over the episodes. Agents: ``random``, ``rba``, ``rba-hold``, ``constant:K[:M|:cat]``,
or a saved SB3 model ``ppo:PATH`` / ``dqn:PATH`` / ``a2c:PATH`` (see ``training.trained_agent.make_agent``).

The line is a real node process stepped over DDS (``SortingLineEnv``), so the figures of the
built-in agents equal ``sorting_line eval --json``'s (the library, no ROS) number for number;
the test suite checks that. Outputs (with ``--out DIR``): ``<stem>.json`` (summary and episodes,
the keys of ``sorting_line eval --json``), ``<stem>.csv`` (one row per episode), ``<stem>.md``
(a one-row table) and ``<stem>_seed<first>.png`` (the first episode's dashboard). The markdown
row is also printed.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..agents.policies import Agent
from ..envs.native import BACKENDS
from ..line.flags import call_with_flags
from ..line.vocabulary import (
    EPISODE_STEPS,
    EVAL_EPISODES,
    EVAL_FIRST_SEED,
    EVAL_SEEDS,
    SETUP_SPAN,
    SETUPS,
    START_SPEED_INDEX,
    VARIANT_CHOICE,
    VARIANTS,
    check_setup,
    check_variant,
)
from ..training.trained_agent import make_agent

#: The paper's evaluation protocol (episodes of EPISODE_STEPS steps): the library's.
FIRST_SEED = EVAL_FIRST_SEED
EPISODES = EVAL_EPISODES


@dataclass
class EpisodeStats:
    """One episode; the fields of ``sorting_line eval --json``'s ``per_episode`` entries."""

    seed: int
    reward: float
    speed_mean: float
    accuracy_mean: float
    purity: float
    speed_changes: int


@dataclass
class Evaluation:
    """Summary over the episodes; the keys of ``sorting_line eval --json`` plus setup/variant."""

    agent: str
    setup: str
    variant: str
    seed: int
    episodes: int
    reward_mean: float
    reward_std: float
    reward_se: float
    speed_mean: float
    accuracy_mean: float
    purity_mean: float
    speed_changes_mean: float
    per_episode: list[EpisodeStats] = field(default_factory=list)

    @classmethod
    def of(cls, agent: str, setup: str, variant: str, seed: int, per_episode: list[EpisodeStats]) -> Evaluation:
        n = len(per_episode)

        def mean(values: list[float]) -> float:
            # Added left to right as the Rust side does (Python >= 3.12's sum() compensates), so
            # the two agree to the last bit.
            total = 0.0
            for v in values:
                total += v
            return total / n

        reward_mean = mean([e.reward for e in per_episode])
        reward_std = math.sqrt(mean([(e.reward - reward_mean) ** 2 for e in per_episode]))
        return cls(
            agent=agent,
            setup=setup,
            variant=variant,
            seed=seed,
            episodes=n,
            reward_mean=reward_mean,
            reward_std=reward_std,
            reward_se=reward_std / math.sqrt(n),
            speed_mean=mean([e.speed_mean for e in per_episode]),
            accuracy_mean=mean([e.accuracy_mean for e in per_episode]),
            purity_mean=mean([e.purity for e in per_episode]),
            speed_changes_mean=mean([float(e.speed_changes) for e in per_episode]),
            per_episode=per_episode,
        )

    def markdown_row(self) -> str:
        return (
            f"| {self.setup} | {self.variant} | {self.agent} | {self.reward_mean:.2f} +- {self.reward_std:.2f} | "
            f"{self.speed_mean:.3f} | {self.purity_mean:.4f} | {self.speed_changes_mean:.1f} |"
        )


MARKDOWN_HEADER = (
    "| setup | variant | agent | episode reward (mean +- std) | mean speed | purity | speed changes |\n"
    "|---|---|---|---|---|---|---|"
)


def run_episode(env, agent: Agent, seed: int) -> EpisodeStats:
    """One episode on ``env`` (a SortingLineEnv truncating at the episode length) from ``seed``."""
    obs, _ = env.reset(seed=seed)
    agent.reset(seed)
    speed_index = START_SPEED_INDEX
    reward = speed = accuracy = 0.0
    steps = 0
    info: dict = {}
    while True:
        obs, r, terminated, truncated, info = env.step(agent.predict(obs, speed_index))
        speed_index = info["speed_index"]
        reward += r
        speed += info["speed"]
        accuracy += info["accuracy"]
        steps += 1
        if terminated or truncated:
            break
    return EpisodeStats(
        seed=seed,
        reward=reward,
        speed_mean=speed / steps,
        accuracy_mean=accuracy / steps,
        purity=info["purity"],
        speed_changes=int(info["speed_changes"]),
    )


def evaluate(
    agent_spec: str,
    setup: str,
    variant: str,
    *,
    episodes: int = EPISODES,
    seed: int = FIRST_SEED,
    steps: int = EPISODE_STEPS,
    dashboard: Path | None = None,
    on_episode: Callable[[EpisodeStats], None] | None = None,
    backend: str = "ros",
) -> Evaluation:
    """Evaluates ``agent_spec`` on a node of its own (``backend="native"``: on the line in this
    process, the same episodes); saves the first episode's dashboard to ``dashboard`` if given (ROS
    backend only)."""
    check_setup(setup)
    check_variant(variant)
    if episodes < 1 or steps < 1:
        raise ValueError(f"episodes = {episodes}, steps = {steps}: both must be 1 or more")
    agent = make_agent(agent_spec, setup, variant, seed)
    return evaluate_agent(
        agent, agent_spec, setup, variant, episodes=episodes, seed=seed, steps=steps, dashboard=dashboard,
        on_episode=on_episode, backend=backend,
    )  # fmt: skip


def evaluate_agent(
    agent: Agent,
    name: str,
    setup: str,
    variant: str,
    *,
    episodes: int = EPISODES,
    seed: int = FIRST_SEED,
    steps: int = EPISODE_STEPS,
    dashboard: Path | None = None,
    on_episode: Callable[[EpisodeStats], None] | None = None,
    backend: str = "ros",
) -> Evaluation:
    """``evaluate`` of an agent already made (``name`` is its spec in the result): what a learning
    curve scores a model in training with, so that its points are scored as the final evaluation."""
    from ..envs.backends import line_env

    check_setup(setup)
    check_variant(variant)
    if episodes < 1 or steps < 1:
        raise ValueError(f"episodes = {episodes}, steps = {steps}: both must be 1 or more")
    per_episode = []
    env = line_env(  # a node of its own, which stops with the evaluation
        backend=backend,
        setup=setup,
        variant=variant,
        max_episode_steps=steps,
        render_mode="rgb_array" if dashboard else None,
        node="spawn",
    )
    try:
        for i in range(episodes):
            per_episode.append(run_episode(env, agent, seed + i))
            if i == 0 and dashboard is not None:
                from ..envs.render import save_dashboard

                save_dashboard(env.dashboard_frame(), dashboard)
            if on_episode is not None:
                on_episode(per_episode[-1])
    finally:
        env.close()
    return Evaluation.of(name, setup, variant, seed, per_episode)


def file_stem(agent_spec: str, setup: str, variant: str) -> str:
    """A file name for an agent spec: a model path becomes its file's stem."""
    from ..training.hyperparams import ALGOS

    algo, sep, path = agent_spec.partition(":")
    name = f"{algo}-{Path(path).stem}" if sep and algo in ALGOS else agent_spec.replace(":", "-")
    return f"eval_{name}_{setup}_{variant}"


def write_outputs(result: Evaluation, out: Path, stem: str) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{stem}.json", out / f"{stem}.csv", out / f"{stem}.md"]
    paths[0].write_text(json.dumps(asdict(result), indent=2) + "\n")
    with paths[1].open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(asdict(result.per_episode[0])))
        writer.writeheader()
        for e in result.per_episode:
            writer.writerow(asdict(e))
    paths[2].write_text(MARKDOWN_HEADER + "\n" + result.markdown_row() + "\n")
    return paths


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sorting-line-eval",
        description=f"Evaluate an agent on a sorting line through ROS 2 (seeds {EVAL_SEEDS}, {EPISODE_STEPS} steps,"
        " deterministic).",
    )
    p.add_argument(
        "--agent", required=True, help="random, rba, rba-hold, constant:K[:M|:cat], or ppo:PATH / dqn:PATH / a2c:PATH"
    )
    p.add_argument("--setup", required=True, choices=list(SETUPS), help=f"the paper's setup {SETUP_SPAN}")
    p.add_argument("--variant", default="basic", choices=VARIANTS, help=f"{VARIANT_CHOICE} line (default %(default)s)")
    p.add_argument(
        "--episodes", type=int, default=EPISODES, help=f"episodes, seeded seed, seed+1, ... (default {EPISODES})"
    )
    p.add_argument("--seed", type=int, default=FIRST_SEED, help=f"seed of the first episode (default {FIRST_SEED})")
    p.add_argument("--steps", type=int, default=EPISODE_STEPS, help=f"steps per episode (default {EPISODE_STEPS})")
    p.add_argument("--out", type=Path, help="write JSON, CSV, markdown and the first episode's dashboard PNG here")
    p.add_argument("--no-dashboard", action="store_true", help="skip the dashboard PNG")
    p.add_argument("--json", action="store_true", help="print the JSON summary instead of the markdown row")
    p.add_argument(
        "--backend",
        default="ros",
        choices=BACKENDS,
        help="ros: a sorting_line node over ROS 2; native: the line in-process, same episodes, no dashboard "
        "(default ros)",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.episodes < 1 or args.steps < 1:
        print(
            f"sorting-line-eval: --episodes = {args.episodes}, --steps = {args.steps}: allowed 1 or more",
            file=sys.stderr,
        )
        return 2
    stem = file_stem(args.agent, args.setup, args.variant)
    dashboard = None
    if args.out is not None and not args.no_dashboard and args.backend == "ros":  # the dashboard is ROS's
        args.out.mkdir(parents=True, exist_ok=True)
        dashboard = args.out / f"{stem}_seed{args.seed}.png"

    def show(e: EpisodeStats) -> None:
        print(
            f"  seed {e.seed}: reward {e.reward:.2f}, mean speed {e.speed_mean:.2f}, purity {e.purity:.3f}",
            file=sys.stderr,
        )

    try:
        result = call_with_flags(
            evaluate, args, args.agent, args.setup, args.variant, dashboard=dashboard, on_episode=show
        )
    except ValueError as e:
        print(f"sorting-line-eval: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(asdict(result)))
    else:
        print(MARKDOWN_HEADER)
        print(result.markdown_row())
    if args.out is not None:
        written = write_outputs(result, args.out, stem) + ([dashboard] if dashboard else [])
        print("written: " + ", ".join(str(p) for p in written), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
