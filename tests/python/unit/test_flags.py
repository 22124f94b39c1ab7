"""`call_with_flags`, how the command-line tools pass their parsed flags to the library functions they
front (sorting-line-bag's subcommands, sorting-line-eval, sorting-line-train). No node, no ROS."""

from __future__ import annotations

import argparse

from sorting_line_gym.line.flags import call_with_flags


def front(bag, overrides=None, *, rate=1.0, wait=10.0, wait_for=None, progress=False):
    return {"bag": bag, "overrides": overrides, "rate": rate, "wait": wait, "wait_for": wait_for, "progress": progress}


def parsed(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    p.add_argument("bag")
    p.add_argument("--overrides", default="from a flag")
    p.add_argument("--rate", type=float, default=2.0)
    p.add_argument("--wait-for", action="append")
    p.add_argument("--no-wait", action="store_true")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--json", action="store_true")
    return p.parse_args(argv)


def test_each_keyword_only_parameter_takes_the_flag_of_its_name():
    args = parsed("run1", "--rate", "0", "--wait-for", "input", "--json")
    got = call_with_flags(front, args, args.bag)
    # rate and wait_for are flags; wait is none (its default stays); --json is no parameter; overrides
    # is no keyword-only parameter (the call passes it or not).
    want = {"bag": "run1", "overrides": None, "rate": 0.0, "wait": 10.0, "wait_for": ["input"], "progress": False}
    assert got == want


def test_what_the_call_names_wins_over_a_flag_of_the_same_name():
    args = parsed("run1", "--wait-for", "input", "--no-wait", "--no-progress")
    got = call_with_flags(front, args, args.bag, {"seed": 3}, wait_for=[], progress=not args.no_progress)
    assert got["wait_for"] == [] and got["progress"] is False and got["overrides"] == {"seed": 3}
    assert got["rate"] == 2.0
