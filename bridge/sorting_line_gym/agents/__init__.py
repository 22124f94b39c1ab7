"""Agents: the non-learning agents behind one interface (``policies``, re-exported here), and the
rule-based agent as an rclpy node (``controller``, `sorting-line-controller`), and the smallest client
of the envs (``bridge_node``, `sorting-line-bridge`: episodes of a random or constant agent through
the bridge, their KPIs and dashboard). Saved SB3 models act through the same interface from the
training layer (``training.trained_agent``, which also makes any agent by its command-line name)."""

from .policies import (
    START_SPEED_INDEX,
    Agent,
    ConstantAgent,
    RandomAgent,
    RuleBasedAgent,
    level,
    load_policy,
)

__all__ = ["START_SPEED_INDEX", "Agent", "ConstantAgent", "RandomAgent", "RuleBasedAgent", "level", "load_policy"]
