"""The errors of the bag tools, shared by reading, writing and every tool above them: the command
line turns :class:`BagError` into a message and exit code 2 (bad input), :class:`BagWriteError`
into exit code 3 (the disk failed the run)."""

from __future__ import annotations


class BagError(Exception):
    """The bag (or what was asked of it) is not usable: the message says why."""


class BagWriteError(BagError):
    """Writing the bag failed (a full disk, an output that became unwritable): the recording
    stopped; the message says what is in the bag."""
