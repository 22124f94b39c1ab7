"""Recorded bags of a sorting line, without rosbag2: record a running line into a ROS 2 bag
(metadata.yaml + MCAP, schemas embedded), replay a bag's resets and commands into a fresh
lock-step node and compare field by field, and play a bag's recorded data to a controller.

Modules: :mod:`.schema` (types, topics, decoding), :mod:`.bagfile` (reading and writing bags),
:mod:`.rosnode` (the tools' rclpy context), :mod:`.record`, :mod:`.replay`, :mod:`.compare`,
:mod:`.play`, and :mod:`.cli` (the `sorting-line-bag` command).
"""

from .bagfile import Bag, BagError, open_bag, rewrite_bag

__all__ = ["Bag", "BagError", "open_bag", "rewrite_bag"]
