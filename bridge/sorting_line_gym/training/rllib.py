"""Ray RLlib on the sorting line: our Gymnasium ids registered with Ray Tune, so that RLlib's
EnvRunners (actors, possibly on other machines of a Ray cluster) make their envs with
``gymnasium.make`` inside their own processes.

    import ray
    from ray.rllib.algorithms.ppo import PPOConfig
    from sorting_line_gym.training import rllib

    rllib.register()                                   # Tune name "sorting_line"
    config = (PPOConfig().environment("sorting_line", env_config={"setup": "B", "node": "shared"})
              .env_runners(num_env_runners=2, num_envs_per_env_runner=4))

``env_config`` holds ``gymnasium.make``'s keyword arguments (``id``, default
``sorting_line_gym:SortingLine-v0``; ``setup``, ``max_episode_steps``, ``node``, ...) plus one key
of ours, ``nodes``: a list of node namespaces, one per EnvRunner (runner i, counted from 1, takes
``nodes[(i - 1) % len(nodes)]``), each a ``sorting_line node --lines L`` (``lines_per_node``, default
4). The envs of runner i attach to that node's lines, one line each, so each EnvRunner's envs live
on the node of its own host. Without ``nodes``, ``node="shared"`` (the default here) leases lines
of the line server of whichever host the runner is on.

The envs start nothing until their first reset: the driver's own EnvRunner, which RLlib builds only
to read the spaces, costs no node and no DDS participant.

Ray is imported lazily (by :func:`register`): importing this module costs nothing without it.
"""

from __future__ import annotations

import itertools
import os
import sys
from collections import defaultdict
from collections.abc import Mapping
from typing import Any

import gymnasium

from ..line.vocabulary import EPISODE_STEPS, SETUP_SPAN, SETUPS

#: The name the envs are registered under with Ray Tune.
ENV_NAME = "sorting_line"
DEFAULT_ID = "sorting_line_gym:SortingLine-v0"

# Per process (an EnvRunner is one): the next line of each node to hand to a new env.
_next_line: dict[str, itertools.count] = defaultdict(itertools.count)


def env_kwargs(config: Mapping[str, Any], worker_index: int) -> tuple[str, dict[str, Any]]:
    """The Gymnasium id and ``gymnasium.make`` kwargs of the next env of EnvRunner
    ``worker_index`` (0: the driver's) under ``config`` (an RLlib ``env_config``)."""
    kwargs = dict(config)
    env_id = kwargs.pop("id", DEFAULT_ID)
    nodes = kwargs.pop("nodes", None)
    lines = int(kwargs.pop("lines_per_node", 4))
    if nodes:
        node = str(nodes[(max(worker_index, 1) - 1) % len(nodes)]).rstrip("/")
        k = next(_next_line[node]) % lines
        kwargs.update(node="attach", namespace=node if lines == 1 else f"{node}/line_{k}")
    else:
        kwargs.setdefault("node", "shared")
    return env_id, kwargs


def make_env(config) -> gymnasium.Env:
    """Ray Tune's env creator: ``config`` is RLlib's ``EnvContext`` (a dict of ``env_config``
    with ``worker_index``)."""
    import sorting_line_gym  # noqa: F401 - registers the Gymnasium ids in this (EnvRunner) process
    from sorting_line_gym.workarounds.participant_deletion_hang import keep_participant_until_killed

    worker_index = int(getattr(config, "worker_index", 0))
    if worker_index > 0:
        # A remote EnvRunner: RLlib closes its envs, then ray.kill()s it. Deleting the DDS
        # participant while the other EnvRunners close theirs can hang in Fast DDS 2.14.
        keep_participant_until_killed()
    env_id, kwargs = env_kwargs(config, worker_index)
    return gymnasium.make(env_id, **kwargs)


def register(name: str = ENV_NAME) -> str:
    """Registers :func:`make_env` with Ray Tune under ``name``; returns the name."""
    from ray.tune.registry import register_env

    register_env(name, make_env)
    return name


#: Environment variables for Ray's processes (set before ``ray.init`` / ``ray start``; Ray's own
#: processes inherit them):
#: - ``RAY_USAGE_STATS_ENABLED=0``: a Ray that talks to nobody outside the cluster.
#: - ``RAY_worker_niceness=0``: Ray starts its workers at nice 15, but here an EnvRunner is what
#:   its lock-step lines (node processes at nice 0) wait on every tick; at nice 15 any other work
#:   on the machine starves the runner and with it the lines (two CPU hogs made the two-runner
#:   PPO test take 6 min and then time out).
RAY_ENVIRONMENT = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_worker_niceness": "0"}


def quiet_ray_environment() -> dict[str, str]:
    """Sets :data:`RAY_ENVIRONMENT` in this process's environment; returns it."""
    os.environ.update(RAY_ENVIRONMENT)
    return dict(RAY_ENVIRONMENT)


def where_envs_live(algo) -> list[dict[str, Any]]:
    """For each remote EnvRunner: its Ray node's address, its pid, the namespaces of its envs'
    lines (known once they have reset), and whether its DDS participant outlives its envs
    (:func:`~sorting_line_gym.workarounds.participant_deletion_hang.keep_participant_until_killed`)."""

    def report(runner):
        import ray.util

        from sorting_line_gym.workarounds import participant_deletion_hang

        envs = getattr(runner.env.unwrapped, "envs", [])  # RLlib wraps Gymnasium's SyncVectorEnv
        return {
            "node_ip": ray.util.get_node_ip_address(),
            "pid": os.getpid(),
            "worker_index": runner.worker_index,
            "lines": [e.unwrapped.namespace for e in envs],
            "keeps_participant": participant_deletion_hang.keeps_participant(),
        }

    return algo.env_runner_group.foreach_env_runner(report, local_env_runner=False)


def _parser():
    import argparse

    p = argparse.ArgumentParser(prog="python -m sorting_line_gym.training.rllib", description=main.__doc__)
    p.add_argument("--id", default=DEFAULT_ID, help="Gymnasium id (default %(default)s)")
    p.add_argument(
        "--setup", default="B", choices=list(SETUPS), help=f"the paper's setup {SETUP_SPAN} (default %(default)s)"
    )
    p.add_argument("--env-runners", type=int, default=2, help="EnvRunner processes (default %(default)s)")
    p.add_argument("--envs-per-runner", type=int, default=4, help="envs in each EnvRunner (default %(default)s)")
    p.add_argument("--timesteps", type=int, default=4000, help="env steps to train for (whole iterations)")
    p.add_argument("--batch", type=int, default=1000, help="train batch size per iteration")
    p.add_argument("--episode-steps", type=int, default=EPISODE_STEPS, help="steps per episode (default %(default)s)")
    p.add_argument(
        "--nodes",
        nargs="*",
        default=None,
        help="node namespaces, one per EnvRunner (its envs attach to that node's lines); default: line servers",
    )
    p.add_argument(
        "--lines-per-node",
        type=int,
        default=4,
        help="lines of each --nodes node an EnvRunner uses (default %(default)s)",
    )
    p.add_argument("--address", default=None, help="a Ray cluster to join (default: start a local one)")
    p.add_argument(
        "--node-ip", default="127.0.0.1", help="this machine's address for a local Ray (default %(default)s)"
    )
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs of a local Ray (default: env runners + 1)")
    p.add_argument("--seed", type=int, default=42, help="seed of the algorithm (default %(default)s)")
    return p


#: hyperparams/ppo.yml's algorithm keys under their RLlib names (``PPOConfig.training``).
RLLIB_NAMES = {"gamma": "gamma", "learning_rate": "lr", "ent_coef": "entropy_coeff"}


def paper_training(env_id: str) -> dict[str, Any]:
    """The paper's PPO settings of ``env_id``'s line, read from hyperparams/ppo.yml (as
    ``sorting-line-train`` reads them) in RLlib's names; a key with no RLlib counterpart here fails,
    naming it, rather than being dropped."""
    from ..line.vocabulary import ENV_IDS
    from . import hyperparams

    # The evolving line is the advanced line over time (the transfer study trains it so, too).
    variants = {env: variant for variant, env in ENV_IDS.items()} | {"SortingLineEvolving-v0": "advanced"}
    name = env_id.split(":")[-1]
    if name not in variants:
        raise ValueError(f"--id {env_id}: the paper's PPO settings exist for {', '.join(sorted(variants))}")
    _, kwargs = hyperparams.split(hyperparams.load("ppo", variants[name]))
    unknown = sorted(set(kwargs) - set(RLLIB_NAMES))
    if unknown:
        raise ValueError(
            f"hyperparams/ppo.yml's {', '.join(unknown)}: no RLlib counterpart is mirrored (mirrored: "
            f"{', '.join(RLLIB_NAMES)})"
        )
    return {RLLIB_NAMES[k]: v for k, v in kwargs.items()}


def _ppo_config(ppo_config, args):
    """RLlib's PPO config for ``args``: the paper's gamma, learning rate and entropy coefficient
    (hyperparams/ppo.yml, :func:`paper_training`); the batch layout (``--batch`` per iteration,
    minibatches of up to 250, 4 epochs) is RLlib's own, not SB3's rollout of 2048 x 10 epochs."""
    env_config: dict[str, Any] = {"id": args.id, "setup": args.setup, "max_episode_steps": args.episode_steps}
    if args.nodes:
        env_config.update(nodes=args.nodes, lines_per_node=args.lines_per_node)
    return (
        ppo_config()
        .environment(register(), env_config=env_config)
        .env_runners(
            num_env_runners=args.env_runners,
            num_envs_per_env_runner=args.envs_per_runner,
            rollout_fragment_length="auto",
            num_cpus_per_env_runner=1,
        )
        .training(
            train_batch_size_per_learner=args.batch,
            minibatch_size=min(250, args.batch),
            num_epochs=4,
            **paper_training(args.id),
        )
        .learners(num_learners=0)
        .debugging(seed=args.seed)
    )


def _train(algo, timesteps: int, log) -> tuple[list[dict], int]:
    """Trains whole iterations until ``timesteps`` env steps are sampled: (a row per iteration, steps)."""
    import time

    history, sampled = [], 0
    while sampled < timesteps:
        t = time.monotonic()
        runners = algo.train().get("env_runners", {})
        sampled = int(runners.get("num_env_steps_sampled_lifetime", 0))
        row = {
            "iteration": len(history) + 1,
            "env_steps": sampled,
            "seconds": round(time.monotonic() - t, 2),
            "episode_return_mean": runners.get("episode_return_mean"),
            "episodes": runners.get("num_episodes_lifetime"),
        }
        history.append(row)
        log(
            f"iteration {row['iteration']}: {sampled} env steps, return mean {row['episode_return_mean']}, "
            f"{row['seconds']} s"
        )
    return history, sampled


def main(argv: list[str] | None = None) -> int:
    """`python -m sorting_line_gym.training.rllib`: PPO on the line with RLlib, progress per
    iteration on stderr, a JSON summary on stdout."""
    import json
    import time

    args = _parser().parse_args(argv)
    quiet_ray_environment()
    t0 = time.monotonic()
    try:
        import ray
        from ray.rllib.algorithms.ppo import PPOConfig
    except ImportError as e:
        print(
            f"sorting_line_gym.training.rllib: Ray RLlib is not installed ({e}): install it with "
            "`bash launch_scripts/setup.sh --rllib` (launch_scripts/requirements-rllib.txt)",
            file=sys.stderr,
        )
        return 2

    def log(msg: str) -> None:
        print(f"[rllib {time.monotonic() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    log("imported ray and rllib")
    if args.address:
        ray.init(address=args.address, log_to_driver=False)
    else:
        ray.init(
            num_cpus=args.num_cpus or args.env_runners + 1,
            include_dashboard=False,
            _node_ip_address=args.node_ip,
            log_to_driver=False,
        )
    log(f"ray up: {ray.cluster_resources()}")
    algo = _ppo_config(PPOConfig, args).build_algo()
    log("algorithm built")
    try:
        history, sampled = _train(algo, args.timesteps, log)
        placement = where_envs_live(algo)
    finally:
        algo.stop()
        ray.shutdown()
    summary = {"iterations": history, "env_steps": sampled, "env_runners": placement}
    print(json.dumps({**summary, "seconds": round(time.monotonic() - t0, 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
