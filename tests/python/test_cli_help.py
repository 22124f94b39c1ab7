"""Every option of every console script (and `python -m` entry point) of the bridge says what it is for.

The Rust side has its twin in src/main.rs (`every_flag_has_help_text`, walking clap's Command). Here each
entry point's `main` is run up to the moment it parses its arguments: the parser is captured there, before
anything starts, and every action of it and of its subcommands must carry help text.
"""

from __future__ import annotations

import argparse
import importlib
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# Entry points users run that are not console scripts (their `--help` is the documentation).
MODULE_ENTRY_POINTS = {"python -m sorting_line_gym.training.rllib": "sorting_line_gym.training.rllib:main"}


def entry_points() -> dict[str, str]:
    scripts = tomllib.loads((ROOT / "bridge" / "pyproject.toml").read_text())["project"]["scripts"]
    return {**scripts, **MODULE_ENTRY_POINTS}


class _Captured(Exception):
    def __init__(self, parser: argparse.ArgumentParser):
        super().__init__(parser.prog)
        self.parser = parser


def captured_parser(target: str, monkeypatch) -> argparse.ArgumentParser:
    """The parser `target`'s main parses its arguments with (nothing after the parse runs)."""

    def capture(self, *args, **kwargs):
        raise _Captured(self)

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", capture)
    monkeypatch.setattr(argparse.ArgumentParser, "parse_known_args", capture)
    module, function = target.split(":")
    with pytest.raises(_Captured) as caught:
        getattr(importlib.import_module(module), function)(["--help"])
    return caught.value.parser


def options_without_help(parser: argparse.ArgumentParser, path: str) -> list[str]:
    missing = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                missing += options_without_help(sub, f"{path} {name}")
            continue
        if not action.help or action.help == argparse.SUPPRESS:
            missing.append(f"{path} {'/'.join(action.option_strings) or action.dest}")
    return missing


@pytest.mark.parametrize("script", sorted(entry_points()))
def test_every_option_has_help(script, monkeypatch):
    parser = captured_parser(entry_points()[script], monkeypatch)
    assert parser._actions, f"{script}: no options found: the capture did not see its parser"
    missing = options_without_help(parser, script)
    assert not missing, "options without help text:\n" + "\n".join(missing)
