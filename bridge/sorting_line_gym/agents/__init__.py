"""Agents: the non-learning agents and trained SB3 models behind one interface (``policies``,
re-exported here), and the rule-based agent as an rclpy node (``controller``,
`sorting-line-controller`)."""

from .policies import (
    START_SPEED_INDEX,
    Agent,
    ConstantAgent,
    RandomAgent,
    RuleBasedAgent,
    TrainedAgent,
    level,
    load_policy,
    make_agent,
)

__all__ = [
    "START_SPEED_INDEX", "Agent", "ConstantAgent", "RandomAgent", "RuleBasedAgent", "TrainedAgent", "level",
    "load_policy", "make_agent",
]
