"""The options that travel from the command line through the tools to storage, as types: how a bag
is written (:class:`WriteOptions`: splitting and compression, each value checked with a message
naming its flag and the allowed range) and the node options a fresh node for a bag takes from flags
(:class:`NodeOverrides`: replay, closed-loop check)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

from .errors import BagError

#: The smallest split size: below it a file would hold little more than its schemas and summary.
MIN_SPLIT_SIZE = 16 * 1024
MIN_SPLIT_DURATION = 1.0
#: The chunk compressions a bag may be written with (``--compression``).
COMPRESSION_NAMES = ("none", "zstd", "lz4")


@dataclass
class WriteOptions:
    """How a bag is written: 0 = no splitting by that measure."""

    max_bag_size: int = 0
    max_bag_duration: float = 0.0
    compression: str = "none"

    def check(self) -> WriteOptions:
        check_max_bag_size(self.max_bag_size)
        check_max_bag_duration(self.max_bag_duration)
        check_compression(self.compression)
        return self


def check_max_bag_size(value: int) -> int:
    if value != 0 and not (isinstance(value, int) and value >= MIN_SPLIT_SIZE):
        raise BagError(
            f"--max-bag-size {value}: must be 0 (no splitting) or a whole number of bytes >= {MIN_SPLIT_SIZE}"
        )
    return value


def check_max_bag_duration(value: float) -> float:
    if value != 0 and not value >= MIN_SPLIT_DURATION or value == float("inf"):
        raise BagError(
            f"--max-bag-duration {value}: must be 0 (no splitting) or a finite number of seconds "
            f">= {MIN_SPLIT_DURATION:g}"
        )
    return value


def check_compression(value: str) -> str:
    if value not in COMPRESSION_NAMES:
        raise BagError(f"--compression {value}: must be one of {', '.join(COMPRESSION_NAMES)}")
    return value


class NodeOverrides(TypedDict, total=False):
    """Node options for a fresh node of a bag's line, overriding the bag's (needed where the bag
    does not store them), named as `sorting_line node` names them (underscores); ``setup`` (A..D)
    stands for the paper's input, obs_noise, action_penalty and threshold. A value of None is
    not given."""

    variant: str | None
    input: str | None
    obs_noise: float | None
    action_penalty: float | None
    threshold: float | None
    max_steps: int | None
    seed: int | None
    tick_period: float | None
    setup: str | None
