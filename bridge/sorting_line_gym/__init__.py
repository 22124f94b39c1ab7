"""sorting_line_gym: the sorting_line ROS 2 node as Gymnasium environments.

    import gymnasium
    env = gymnasium.make("sorting_line_gym:SortingLine-v0", setup="B")          # basic line
    env = gymnasium.make("sorting_line_gym:SortingLineAdvanced-v0", setup="D")  # speed x sort mode

By default each environment starts, owns and stops its own node process (``node="spawn"``) in a
namespace of its own; ``node="shared"`` leases a line of this host's line server (many envs per
host); ``node="attach"`` uses a node already serving ``namespace``. Nothing starts before the
first ``reset()``. Under the hood every step is a lock-step round trip over ROS 2 topics (see
``transport``).

Modules: ``transport`` (rclpy plumbing, the node process, waiting with timeouts, the fork rule),
``line_server`` and ``line_supervisor`` (line servers and leases), ``env`` (the single-line
environment), ``vector`` (N lines of one node as a Gymnasium VectorEnv), ``sb3_vec_env`` (the same
as an SB3 VecEnv), ``zoo`` (RL Zoo conf files), ``render`` (the dashboard).
"""

from gymnasium.envs.registration import register

from .env import SortingLineEnv
from .transport import BridgeError, BridgeTimeout

__all__ = ["SortingLineEnv", "BridgeError", "BridgeTimeout"]

# max_episode_steps here is the TimeLimit gymnasium.make applies (and overrides with its own
# max_episode_steps argument, which it never passes to the env): the env itself then leaves
# truncation to that wrapper.
register(
    id="SortingLine-v0",
    entry_point="sorting_line_gym.env:SortingLineEnv",
    kwargs={"variant": "basic"},
    max_episode_steps=50,
    vector_entry_point="sorting_line_gym.vector:SortingLineVectorEnv",
)
register(
    id="SortingLineAdvanced-v0",
    entry_point="sorting_line_gym.env:SortingLineEnv",
    kwargs={"variant": "advanced"},
    max_episode_steps=50,
    vector_entry_point="sorting_line_gym.vector:SortingLineVectorEnv",
)
register(
    id="SortingLineEvolving-v0",
    entry_point="sorting_line_gym.envs.evolving:SortingLineEvolvingEnv",
    max_episode_steps=50,
)
