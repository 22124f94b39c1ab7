#!/usr/bin/env python3
"""Soak test of the bridge: N lock-step line-ticks through ``SortingLineVectorEnv`` (16 lines of one
node by default, batch topics, 50-step episodes with same-step autoreset), every observation checked.

What it proves, and how a failure would show:
- nothing lost: every round trip must return each line's next state; a wait that times out is
  counted as lost (every line of that round trip) and the run re-seeds and carries on;
- nothing misaligned: each line's info must name the episode's seed (the soak knows every seed: the
  vector env draws them from per-line generators seeded with seed + k, mirrored here) and the step
  that follows the previous one;
- nothing wrong: every line's whole stream (actions, seeded resets) is replayed through the simulation
  library (``sorting_line trace``, one call per line per ``--verify-episodes`` episodes) and each
  step's reward, cumulative reward and observation, and each reset's first observation, must equal it;
- memory flat: RSS of the node process and of this (bridge) process at start, per window and at end;
- throughput flat: line-ticks/s per window of ``--window`` line-ticks.
It prints load average and CPU steal with the figures (the machine may be shared), can write the
per-window series as JSON (``--json``) and a plot of throughput and RSS over the run (``--plot``).

    .venv/bin/python benches/soak.py                     # the full soak: 1,000,000 line-ticks
    .venv/bin/python benches/soak.py --ticks 50000       # what tests/python/test_reliability.py runs
    .venv/bin/python benches/soak.py --plot docs/results/reliability/reliability_soak.png --json /tmp/soak.json

Like the other benchmarks it refuses to run outside a loopback-only network namespace and, as root,
re-executes itself under ``unshare -n`` (ros_harness.run_isolated); ROS_DOMAIN_ID is its own
(--domain, default 91). The exit code is 1 when anything was lost, misaligned or wrong.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
sys.path.insert(0, str(ROOT / "benches"))

from sorting_line_gym.line.vocabulary import EPISODE_STEPS, SETUPS, VARIANTS  # noqa: E402
from support import ros_harness as h  # noqa: E402


def progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------------
# Checking one line's stream


@dataclass
class LineLedger:
    """What one line did since its last verification: the tokens ``sorting_line trace`` replays
    (Gymnasium actions and ``r<seed>`` resets) and what the bridge reported for each of them.

    ``expect_step`` checks alignment as the run goes (the step must follow the previous one and the
    seed must be the episode's); ``verify`` replays the tokens through the library and compares
    values. Both count problems rather than raise, so the run reports all of them."""

    setup: str
    variant: str
    seed: int  # seed of the first episode in this ledger
    tokens: list[str] = field(default_factory=list)
    # Per token: ("step", reward, cumulative reward, observation) or ("reset", observation).
    seen: list[tuple] = field(default_factory=list)
    step: int = 0  # steps taken in the current episode
    episode_seed: int = 0
    episodes: int = 0

    def __post_init__(self):
        self.episode_seed = self.seed

    def expect_step(
        self, action: int, info_seed: int, info_step: int, reward: float, cumulative: float, observation: tuple
    ) -> bool:
        """Records one step; False if it is not the step this line should have taken next."""
        self.step += 1
        self.tokens.append(str(int(action)))
        self.seen.append(("step", float(reward), float(cumulative), observation))
        return int(info_seed) == self.episode_seed and int(info_step) == self.step

    def expect_reset(self, seed: int, observation: tuple) -> None:
        self.tokens.append(f"r{seed}")
        self.seen.append(("reset", observation))
        self.episode_seed, self.step = seed, 0
        self.episodes += 1

    def verify(self) -> tuple[int, int]:
        """Replays the ledger through ``sorting_line trace``; returns (entries compared, mismatches)
        and starts a new ledger at the current episode (a reset with a seed is a clean cut)."""
        if not self.tokens:
            return 0, 0
        # The ledger may end mid-episode; trace from the first episode's seed over every token.
        trace = h.run_trace(self.setup, self.variant, self.seed, self.tokens, max_steps=EPISODE_STEPS)[1:]
        mismatches = 0 if len(trace) == len(self.seen) else abs(len(trace) - len(self.seen))
        for entry, seen in zip(trace, self.seen, strict=False):
            if seen[0] == "reset":
                want = ("reset", observation_of(self.variant, entry["reset"]["observation"]))
            else:
                s = entry["step"]
                want = ("step", s["reward"], entry["cumulative_reward"], observation_of(self.variant, s["observation"]))
            mismatches += want != seen
        compared = len(self.seen)
        # Carry on from the current episode: everything before it is verified. An episode in
        # progress is kept (its steps re-verified next time) because trace starts from a reset.
        self._cut_at_current_episode()
        return compared, mismatches

    def _cut_at_current_episode(self) -> None:
        last_reset = max((i for i, s in enumerate(self.seen) if s[0] == "reset"), default=None)
        if last_reset is None:
            return  # the first episode is still running: keep it all
        self.tokens = self.tokens[last_reset + 1 :]
        self.seen = self.seen[last_reset + 1 :]
        self.seed = self.episode_seed
        self.episodes = 0


def observation_of(variant: str, obs) -> tuple:
    """An observation as the env returns it (float32), from a trace entry or an env array."""
    import numpy as np

    if isinstance(obs, dict):
        values = [obs["quantity"]] + ([h.CATEGORIES[obs["category"]]] if variant == "advanced" else [])
        return tuple(np.asarray(values, dtype=np.float32).tolist())
    return tuple(np.asarray(obs, dtype=np.float32).tolist())


# ------------------------------------------------------------------------------------------
# The soak


@dataclass
class SoakResult:
    ticks: int = 0  # line-ticks (env-steps) run
    round_trips: int = 0
    lost: int = 0
    misaligned: int = 0
    verified: int = 0  # trace entries compared
    mismatched: int = 0
    resets: int = 0
    seconds: float = 0.0
    rss_node_start: float = 0.0
    rss_node_end: float = 0.0
    rss_bridge_start: float = 0.0
    rss_bridge_end: float = 0.0
    windows: list[dict] = field(default_factory=list)
    load_before: str = ""
    load_after: str = ""
    steal: float = 0.0
    config: dict = field(default_factory=dict)

    def ok(self) -> bool:
        return self.lost == 0 and self.misaligned == 0 and self.mismatched == 0 and self.verified > 0


class _Ledgers:
    """Every line's ledger and seed mirror: what the soak expects of each line, checked step by step."""

    def __init__(self, env, setup: str, variant: str, verify_episodes: int):
        self.env, self.setup, self.variant, self.verify_episodes = env, setup, variant, verify_episodes
        self.lines = env.num_envs

    def start(self, run_seed: int) -> None:
        """reset(seed) seeds line k with run_seed + k; later resets come from the mirrored generators."""
        import numpy as np

        obs, _ = self.env.reset(seed=run_seed)
        self.mirrors = [np.random.default_rng(run_seed + k) for k in range(self.lines)]
        self.ledgers = [LineLedger(self.setup, self.variant, run_seed + k) for k in range(self.lines)]
        for k in range(self.lines):
            self.ledgers[k].seen.append(("reset", observation_of(self.variant, obs[k])))
            self.ledgers[k].tokens.append(f"r{run_seed + k}")

    def account(self, result: SoakResult, actions, obs, rewards, truncated, infos) -> None:
        """Checks one round trip of every line against its ledger; counts into ``result``."""
        from sorting_line_gym.envs.env import SEED_BOUND

        for k, ledger in enumerate(self.ledgers):
            final = truncated[k]
            observation = observation_of(self.variant, infos["final_obs"][k] if final else obs[k])
            step = (actions[k], infos["seed"][k], infos["step"][k], rewards[k], infos["cumulative_reward"][k])
            result.misaligned += not ledger.expect_step(*step, observation)
            if final:
                if ledger.step != EPISODE_STEPS:
                    result.misaligned += 1  # an episode must end exactly at its last step
                ledger.expect_reset(int(self.mirrors[k].integers(0, SEED_BOUND)), observation_of(self.variant, obs[k]))
                result.resets += 1
                if ledger.episodes >= self.verify_episodes:
                    self.verify(result, ledger)

    def verify(self, result: SoakResult, ledger: LineLedger) -> None:
        compared, bad = ledger.verify()
        result.verified += compared
        result.mismatched += bad


class _Window:
    """The measurement window: ticks and CPU since it opened, closed into ``result.windows``."""

    def __init__(self, node_pid: int):
        from node_lockstep import cpu_times

        self.node_pid = node_pid
        self.t0 = self.opened = time.perf_counter()
        self.ticks, self.cpu = 0, cpu_times()

    def close(self, result: SoakResult) -> None:
        from node_lockstep import cpu_times, loadavg, steal_percent

        now = time.perf_counter()
        result.windows.append(
            {
                "ticks": result.ticks,
                "seconds": round(now - self.t0, 3),
                "ticks_per_s": round(self.ticks / (now - self.opened), 1),
                "rss_node_mb": round(h.rss_mb(self.node_pid), 2),
                "rss_bridge_mb": round(h.rss_mb(os.getpid()), 2),
                "load": loadavg(),
                "steal": round(steal_percent(self.cpu, cpu_times()), 1),
            }
        )
        self.opened, self.ticks, self.cpu = now, 0, cpu_times()


def _soak_env(lines: int, setup: str, variant: str, step_timeout: float, namespace, node: str):
    from sorting_line_gym import SortingLineVectorEnv

    line = dict(setup=setup, variant=variant, namespace=namespace, node=node)
    return SortingLineVectorEnv(num_envs=lines, max_episode_steps=EPISODE_STEPS, step_timeout=step_timeout, **line)


def _progress_bar(ticks: int, show: bool):
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=ticks, unit="tick", unit_scale=True, file=sys.stderr, mininterval=2.0)


def _drive(env, expected: _Ledgers, result: SoakResult, measured: _Window, bar, ticks: int, window: int, seed: int):
    """Steps every line with seeded random actions until ``ticks`` line-ticks, checking each step;
    a lost round trip restarts the ledgers on new, known seeds."""
    import numpy as np

    from sorting_line_gym import BridgeTimeout

    lines, n_actions = env.num_envs, int(env.single_action_space.n)
    actions_rng = np.random.default_rng(seed + 1_000_003)
    while result.ticks < ticks:
        actions = actions_rng.integers(0, n_actions, size=lines)
        try:
            obs, rewards, _, truncated, infos = env.step(actions)
        except BridgeTimeout as e:
            result.lost += lines
            progress(f"soak: LOST a round trip at line-tick {result.ticks}: {e}")
            seed += 10_000  # new, known seeds: the ledgers restart cleanly
            expected.start(seed)
            continue
        result.round_trips += 1
        result.ticks += lines
        measured.ticks += lines
        expected.account(result, actions, obs, rewards, truncated, infos)
        if bar is not None:
            bar.update(lines)
        if measured.ticks >= window or result.ticks >= ticks:
            measured.close(result)


def run_soak(
    ticks: int,
    lines: int = 16,
    setup: str = "A",
    variant: str = "basic",
    seed: int = 7,
    window: int = 50_000,
    verify_episodes: int = 20,
    step_timeout: float = 5.0,
    show_progress: bool = True,
    namespace=None,
    node: str = "spawn",
) -> SoakResult:
    """Runs the soak in this process (rclpy must be importable; the caller ensures isolation).
    ``namespace`` and ``node`` are the vector env's (a list of node namespaces with ``node="attach"``
    soaks lines on several hosts: benches/multihost.py); the node's RSS is reported only for a node
    the env spawned."""
    from node_lockstep import cpu_times, loadavg, steal_percent

    nodes = 1 if isinstance(namespace, (str, type(None))) else len(namespace)
    config = dict(ticks=ticks, lines=lines, setup=setup, variant=variant, seed=seed, window=window)
    result = SoakResult(load_before=loadavg(), config=dict(config, verify_episodes=verify_episodes, nodes=nodes))
    cpu_before = cpu_times()
    env = _soak_env(lines, setup, variant, step_timeout, namespace, node)
    bar = None
    try:
        expected = _Ledgers(env, setup, variant, verify_episodes)
        expected.start(seed)
        # The node the env spawned at its first reset (none when it attached to others' nodes).
        spawned = getattr(env._lines.bank, "process", None)
        node_pid = spawned.process.pid if spawned is not None else -1
        result.rss_node_start, result.rss_bridge_start = h.rss_mb(node_pid), h.rss_mb(os.getpid())
        bar = _progress_bar(ticks, show_progress)
        measured = _Window(node_pid)
        _drive(env, expected, result, measured, bar, ticks, window, seed)
        result.seconds = time.perf_counter() - measured.t0
        result.rss_node_end, result.rss_bridge_end = h.rss_mb(node_pid), h.rss_mb(os.getpid())
        for ledger in expected.ledgers:  # what is left, including episodes still running
            expected.verify(result, ledger)
    finally:
        if bar is not None:
            bar.close()
        env.close()
    result.load_after = loadavg()
    result.steal = steal_percent(cpu_before, cpu_times())
    return result


def report(r: SoakResult) -> str:
    rates = [w["ticks_per_s"] for w in r.windows]
    first, last = (rates[0], rates[-1]) if rates else (0, 0)
    c = r.config
    lines = [
        f"soak: {r.ticks:,} lock-step line-ticks through SortingLineVectorEnv ({c['lines']} "
        f"lines of {c.get('nodes', 1)} node(s), "
        f"setup {c['setup']} {c['variant']}, 50-step episodes, seed {c['seed']}), {r.round_trips:,} round trips, "
        f"{r.resets:,} autoresets, in {r.seconds:.1f} s",
        f"  lost {r.lost}, misaligned {r.misaligned}, values compared with `sorting_line trace` {r.verified:,}, "
        f"mismatched {r.mismatched}  -> {'OK' if r.ok() else 'FAILED'}",
        f"  RSS node {r.rss_node_start:.1f} -> {r.rss_node_end:.1f} MB, bridge {r.rss_bridge_start:.1f} -> "
        f"{r.rss_bridge_end:.1f} MB (start = after the first reset, end = after the last step)",
        f"  throughput {r.ticks / max(r.seconds, 1e-9):,.0f} line-ticks/s overall; per window of {c['window']:,}: "
        f"first {first:,.0f}, last {last:,.0f}, min {min(rates, default=0):,.0f}, max {max(rates, default=0):,.0f}",
        f"  {os.cpu_count()} CPUs; load average {r.load_before} before, {r.load_after} after; "
        f"CPU steal {r.steal:.0f} %",
        "  windows (line-ticks, line-ticks/s, RSS node MB, RSS bridge MB, load average, CPU steal %):",
    ]
    for w in r.windows:
        lines.append(
            f"    {w['ticks']:>10,} {w['ticks_per_s']:>10,.0f} {w['rss_node_mb']:>8.1f} {w['rss_bridge_mb']:>8.1f}"
            f"  {w['load']}  {w['steal']:>4.1f}"
        )
    return "\n".join(lines)


def plot(r: SoakResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = [w["ticks"] / 1000 for w in r.windows]
    fig, (top, middle, bottom) = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    top.plot(x, [w["ticks_per_s"] for w in r.windows], marker=".")
    top.set_ylabel("line-ticks/s (per window)")
    top.set_ylim(bottom=0)
    top.set_title(
        f"soak: {r.ticks:,} line-ticks, {r.config['lines']} lines; lost {r.lost}, misaligned "
        f"{r.misaligned}, mismatched {r.mismatched}",
        fontsize=10,
    )
    middle.plot(x, [w["rss_node_mb"] for w in r.windows], marker=".", label="node")
    middle.plot(x, [w["rss_bridge_mb"] for w in r.windows], marker=".", label="bridge (Python)")
    middle.set_ylabel("RSS (MB)")
    middle.set_ylim(bottom=0)
    middle.legend()
    # The machine is shared: what else ran explains the swings in throughput.
    bottom.plot(x, [float(w["load"].split()[0]) for w in r.windows], marker=".", label="load average (1 min)")
    bottom.plot(x, [w["steal"] for w in r.windows], marker=".", label="CPU steal %")
    bottom.set_ylim(bottom=0)
    bottom.set_xlabel("line-ticks (thousands)")
    bottom.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ticks", type=int, default=1_000_000, help="line-ticks to run (default 1,000,000)")
    parser.add_argument("--lines", type=int, default=16, help="lines of the node (default 16)")
    parser.add_argument("--setup", default="A", choices=list(SETUPS))
    parser.add_argument("--variant", default="basic", choices=VARIANTS)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--window", type=int, default=50_000, help="line-ticks per throughput/RSS sample")
    parser.add_argument(
        "--verify-episodes",
        type=int,
        default=20,
        help="episodes per line between two `sorting_line trace` replays (default 20); the "
        "unverified episodes are memory this (bridge) process holds",
    )
    parser.add_argument("--domain", type=int, default=91, help="ROS_DOMAIN_ID (default 91)")
    parser.add_argument("--json", type=Path, help="write the result (with the per-window series) here")
    parser.add_argument("--plot", type=Path, help="write a PNG of throughput and RSS over the run here")
    args = parser.parse_args()

    h.run_isolated(__file__, "SORTING_LINE_SOAK_IN_NETNS")
    os.environ["ROS_DOMAIN_ID"] = str(args.domain)
    env = h.ros_environment()
    progress(f"soak: node {h.node_binary()}; " + ", ".join(f"{k}={v}" for k, v in env.items()))
    os.environ.setdefault("SORTING_LINE_BIN", str(h.node_binary()))
    result = run_soak(args.ticks, args.lines, args.setup, args.variant, args.seed, args.window, args.verify_episodes)
    print(report(result))
    if args.json:
        args.json.write_text(json.dumps(result.__dict__, indent=1))
    if args.plot:
        plot(result, args.plot)
        print(f"  plot: {args.plot}")
    return 0 if result.ok() else 1


if __name__ == "__main__":
    sys.exit(main())
