"""Agents: the non-learning agents behind one interface (``policies``, re-exported here), and the
rule-based agent as an rclpy node (``controller``, `sorting-line-controller`). Saved SB3 models act
through the same interface from the training layer (``training.trained_agent``, which also makes
any agent by its command-line name)."""

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
