"""How a command-line tool hands its parsed flags to the library function it is a front for.

A tool (`sorting-line-bag`'s subcommands, `sorting-line-eval`, `sorting-line-train`) is a thin layer
over a library function whose keyword-only parameters are named as the tool's flags (``--max-ticks``
is ``max_ticks=``). :func:`call_with_flags` passes each flag of such a name, so a flag added to the
parser and to the function reaches it without a third edit in between that could be forgotten; the
tool's call names only what is no flag (callbacks, a stop flag) or what it renames or transforms
(``progress=not args.no_progress``). No ROS here.
"""

from __future__ import annotations

import argparse
import inspect
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")


def call_with_flags(function: Callable[..., T], args: argparse.Namespace, *positional: Any, **given: Any) -> T:
    """``function(*positional, **given)``, plus for each keyword-only parameter of ``function`` that
    ``given`` leaves out the parsed flag of the same name, if the parser has one (else the parameter
    keeps its default)."""
    flags = {
        name: getattr(args, name)
        for name, parameter in inspect.signature(function).parameters.items()
        if parameter.kind is inspect.Parameter.KEYWORD_ONLY and name not in given and hasattr(args, name)
    }
    return function(*positional, **flags, **given)
