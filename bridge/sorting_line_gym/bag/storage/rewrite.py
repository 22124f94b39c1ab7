"""Copying a bag into a new one (custom_data included), written as given options say (split,
compressed), changing messages on the way: for tests (a tampered golden bag, a split or compressed
copy) and for trimming a bag by hand. Reads through :mod:`.reader`, writes through :mod:`.writer`."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ..format.options import WriteOptions
from .reader import BagMessage, open_bag
from .schema import typestore
from .writer import BagWriter


def rewrite_bag(
    src: str | Path,
    dst: str | Path,
    change: Callable[[BagMessage], object | None] = lambda m: None,
    options: WriteOptions | None = None,
) -> int:
    """Copies bag ``src`` to ``dst`` (custom_data included), written as ``options`` say (split,
    compressed). ``change(message)`` may return a new message object (a rosbags message of the
    same type) to store instead; returns how many were changed. For tests (a tampered golden bag,
    a split or compressed copy) and for trimming a bag by hand."""
    bag = open_bag(src)
    store = typestore()
    writer = BagWriter(dst, bag.custom, options)
    changed = 0
    try:
        for topic, msgtype in bag.types.items():
            writer.add_topic(topic, msgtype)
        for m in bag.messages:
            new = change(m)
            data = m.data
            if new is not None:
                data = bytes(store.serialize_cdr(new, m.msgtype))
                changed += 1
            writer.write(m.topic, m.log_time, data)
    finally:
        writer.close()
    return changed
