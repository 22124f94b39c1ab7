"""Recorded bags of a sorting line, without rosbag2: record a running line into a ROS 2 bag
(metadata.yaml + MCAP, schemas embedded), replay a bag's resets and commands into a fresh
lock-step node and compare field by field, and play a bag's recorded data to a controller.

Modules: :mod:`.schema` (types, topics, decoding), :mod:`.bagfile` (reading bags),
:mod:`.writer` (writing them: crash-safe, split and compressed), :mod:`.recovery` (`reindex`: a
bag whose recorder died), :mod:`.losses` (what a recording missed), :mod:`.rosnode` (the tools'
rclpy context), :mod:`.record`, :mod:`.replay`, :mod:`.compare`, :mod:`.play`, :mod:`.check` (a
controller against a bag: a verdict; ``check_controller``) and :mod:`.cli` (the `sorting-line-bag`
command).
"""

from .bagfile import Bag, BagError, open_bag
from .writer import BagWriteError, rewrite_bag

__all__ = ["Bag", "BagError", "BagWriteError", "Verdict", "check_controller", "open_bag", "rewrite_bag"]


def __getattr__(name: str):
    # On first use only: the check needs rclpy, reading a bag does not.
    if name == "check_controller":
        from .check import check_controller

        return check_controller
    if name == "Verdict":
        from .check_verdict import Verdict

        return Verdict
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
