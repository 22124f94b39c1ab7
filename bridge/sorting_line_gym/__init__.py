"""sorting_line_gym: the sorting_line ROS 2 node as Gymnasium environments.

    import gymnasium
    env = gymnasium.make("sorting_line_gym:SortingLine-v0", setup="B")          # basic line
    env = gymnasium.make("sorting_line_gym:SortingLineAdvanced-v0", setup="D")  # speed x sort mode

By default each environment starts, owns and stops its own node process (``node="spawn"``) in a
namespace of its own; ``node="shared"`` leases a line of this host's line server (started when
needed, stopped 8 s after its last env: many envs per host); ``node="attach"`` uses a node already
serving ``namespace``. Nothing starts before the
first ``reset()``. Under the hood every step is a lock-step round trip over ROS 2 topics (see
``ros.links``). ``backend="native"`` (every id, and ``make_vec``) runs the line in this process
instead, through the extension ``_native`` (``envs.native``): no node, no ROS, the same trajectories.

Subpackages, by what they depend on (each builds only on those before it; docs/layout.md's
"Layers" lists the order the tests check): ``line`` (nothing ROS: the vocabulary, options, the
node process, line servers), ``workarounds`` (every workaround for a defect outside this
repository: Fast DDS, rclpy, DDS discovery, orphaned processes; one module each, its docstring the
list), ``ros`` (rclpy: context, waits, links, the batch codec, the bank of lines), ``bag``
(record, play, replay), ``envs`` (the Gymnasium and SB3 environments, the dashboard), ``agents``,
``training`` (SB3), ``zoo`` (RL Zoo conf files), ``reports`` (tables, statistics and plots of
saved results) and ``studies`` (the runs behind them: evaluation, the benchmark, the transfer
study). ``evolutions`` holds ready schedules of the evolving line.

``import sorting_line_gym`` registers the Gymnasium ids and imports neither rclpy nor SB3: the
environment classes below load on first use.
"""

from gymnasium.envs.registration import register

from .line.errors import BridgeError, BridgeTimeout
from .line.vocabulary import ENV_IDS, EPISODE_STEPS

__all__ = ["SortingLineEnv", "SortingLineVectorEnv", "SortingLineSB3VecEnv", "BridgeError", "BridgeTimeout"]

_LAZY = {
    "SortingLineEnv": "envs.env",
    "SortingLineVectorEnv": "envs.vector",
    "SortingLineSB3VecEnv": "envs.sb3_vec_env",
}


def __getattr__(name: str):
    # PEP 562: the environment classes pull in rclpy (and SB3, torch), which registering the ids,
    # or RL Zoo's --gym-packages, must not need.
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# max_episode_steps here is the TimeLimit gymnasium.make applies (and overrides with its own
# max_episode_steps argument, which it never passes to the env): the env itself then leaves
# truncation to that wrapper.
for _variant, _env_id in ENV_IDS.items():
    register(
        id=_env_id,
        entry_point="sorting_line_gym.envs.backends:line_env",
        kwargs={"variant": _variant},
        max_episode_steps=EPISODE_STEPS,
        vector_entry_point="sorting_line_gym.envs.vector:SortingLineVectorEnv",
    )
register(
    id="SortingLineEvolving-v0",
    entry_point="sorting_line_gym.envs.backends:evolving_env",
    max_episode_steps=EPISODE_STEPS,
)
