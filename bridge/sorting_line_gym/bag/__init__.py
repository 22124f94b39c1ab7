"""Recorded bags of a sorting line, without rosbag2: record a running line into a ROS 2 bag
(metadata.yaml + MCAP, schemas embedded), replay a bag's resets and commands into a fresh
lock-step node and compare field by field, and play a bag's recorded data to a controller.

Layered as rosbag2 is, each folder using only those before it (none imports one after it):

- :mod:`.format`: the leaf: topic names and types, custom_data keys and the line's description,
  write options, errors;
- :mod:`.storage`: bags on disk: reading (``reader``), writing (``writer``, crash-safe, split and
  compressed; ``metadata``), copying (``rewrite``), ``recovery`` (`reindex`: a bag whose recorder
  died), ``losses`` (what a recording missed), ``foreign`` (bags of other recorders), ``schema``
  (types, decoding);
- :mod:`.transport`: the tools on a ROS graph (rclpy): ``record``, ``play``, ``replay`` (with
  ``replay_plan`` and ``compare``), their node (``rosnode``);
- :mod:`.check`: a controller against a bag: a verdict (``check_controller``);
- :mod:`.cli`: the `sorting-line-bag` command, one function per verb.
"""

from .format.errors import BagError, BagWriteError
from .storage.reader import Bag, open_bag
from .storage.rewrite import rewrite_bag

__all__ = ["Bag", "BagError", "BagWriteError", "Verdict", "check_controller", "open_bag", "rewrite_bag"]


def __getattr__(name: str):
    # On first use only: the check needs rclpy (most of a second to import), reading a bag does not.
    if name == "check_controller":
        from .check.checker import check_controller

        return check_controller
    if name == "Verdict":
        from .check.verdict import Verdict

        return Verdict
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
