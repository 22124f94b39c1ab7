"""Resumable studies, cell by cell: each finished cell's record is saved at once, whole or not at
all, in a directory keyed on the options that change results, and a progress display projects the
end of the study from the cells' own durations.

A *cell* is the unit a study saves (for the transfer study: one scenario x algorithm x training seed
x strategy, or a scenario's baselines). ``CellStore`` keeps ``<out>/study.json`` (the key and every
invocation of the study: when it started and which cells it ran) and ``<out>/cells/<name>.json``;
a store whose saved key differs from the one asked for is refused, naming the options that differ,
so cells of two configurations are never mixed. ``CellProgress`` is a tqdm bar over the cells on a
terminal, and plain lines otherwise (a log file, CI), each with the projected end time.

No ROS and no Stable-Baselines3 here.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any


def write_atomic(path: Path, data: Any) -> None:
    """``data`` as JSON in ``path``, through a temporary file and a rename: the file is whole or
    absent, even if the process is killed while writing."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1) + "\n")
    os.replace(tmp, path)


class ConfigurationMismatch(ValueError):
    """The results directory holds cells of another configuration."""


def _differences(saved: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    keys = sorted(set(saved) | set(wanted))
    return [f"{k}: saved {saved.get(k)!r}, asked {wanted.get(k)!r}" for k in keys if saved.get(k) != wanted.get(k)]


class CellStore:
    """The saved cells of one study configuration (``key``: the options that change results) in
    ``out``."""

    def __init__(self, out: Path, key: dict[str, Any]):
        self.out = Path(out)
        self.key = json.loads(json.dumps(key))  # as it reads back from JSON (tuples become lists)
        self.study_file = self.out / "study.json"
        self.cells_dir = self.out / "cells"
        self.study = {"key": self.key, "invocations": []}
        if self.study_file.is_file():
            saved = json.loads(self.study_file.read_text())
            differences = _differences(saved.get("key", {}), self.key)
            if differences:
                raise ConfigurationMismatch(
                    f"{self.out} holds cells of another configuration ({'; '.join(differences)}): "
                    "use another --out, or the options it was run with"
                )
            self.study = saved

    def path(self, name: str) -> Path:
        return self.cells_dir / f"{name}.json"

    def load(self, name: str) -> dict[str, Any] | None:
        """The saved record of cell ``name``, if it is there and of this configuration."""
        path = self.path(name)
        if not path.is_file():
            return None
        record = json.loads(path.read_text())
        return record if record.get("key") == self.key else None

    def begin(self, argv: Iterable[str]) -> int:
        """Records a new invocation of the study; returns its number (1 for the first)."""
        self.study["invocations"].append(
            {"started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "argv": list(argv), "ran": []}
        )
        write_atomic(self.study_file, self.study)
        return len(self.study["invocations"])

    def save(self, name: str, record: dict[str, Any]) -> dict[str, Any]:
        """Saves a finished cell (with the key and the invocation that ran it) and notes it in
        ``study.json``."""
        invocation = len(self.study["invocations"])
        record = {**record, "key": self.key, "invocation": invocation}
        write_atomic(self.path(name), record)
        self.study["invocations"][-1]["ran"].append(name)
        write_atomic(self.study_file, self.study)
        return record


def _clock(seconds_from_now: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(time.time() + seconds_from_now))


class CellProgress:
    """Progress over the cells of a study: a tqdm bar on a terminal, plain lines otherwise; the
    projected end from the durations of the finished cells of the same kind (``kind_of(name)``),
    or of all finished cells while a kind has none; ``parallel`` cells at a time."""

    def __init__(
        self, todo: list[str], done: dict[str, float], kind_of: Callable[[str], str], desc: str, parallel: int = 1
    ):
        from tqdm import tqdm

        self.stream = sys.stderr
        self.parallel = parallel
        self.todo = list(todo)
        self.kind_of = kind_of
        self.durations: dict[str, list[float]] = {}
        for name, seconds in done.items():
            self.durations.setdefault(kind_of(name), []).append(seconds)
        self.total = len(todo) + len(done)
        self.finished = len(done)
        self.tty = self.stream.isatty()
        self.bar = tqdm(
            total=self.total,
            initial=self.finished,
            unit="cell",
            desc=desc,
            file=self.stream,
            dynamic_ncols=True,
            disable=not self.tty,
        )
        self._show()

    def remaining_seconds(self) -> tuple[float, int] | None:
        """(the projected time the unfinished cells take one after the other, how many kinds of
        them have no finished cell yet: timed as the slowest kind so far); None before any is done."""
        if not self.todo:
            return 0.0, 0
        if not self.durations:
            return None
        estimate = {k: sum(v) / len(v) for k, v in self.durations.items()}
        slowest = max(estimate.values())
        untimed = {self.kind_of(name) for name in self.todo} - set(estimate)
        return sum(estimate.get(self.kind_of(name), slowest) for name in self.todo), len(untimed)

    def projection(self) -> str:
        found = self.remaining_seconds()
        if found is None:
            return "end projected once a cell is done"
        remaining, untimed = found[0] / self.parallel, found[1]
        if remaining < 120:
            left = f"{remaining:.0f} s"
        else:
            left = f"{remaining / 60:.0f} min" if remaining < 7200 else f"{remaining / 3600:.1f} h"
        rough = f"; rough: {untimed} kind(s) of cell not timed yet" if untimed else ""
        return f"projected end {_clock(remaining)} (in {left}, from the finished cells{rough})"

    def _show(self) -> None:
        self.bar.set_postfix_str(self.projection(), refresh=True)

    def line(self, text: str) -> None:
        stamped = f"[{time.strftime('%H:%M:%S')}] {text}"
        if self.tty:
            self.bar.write(stamped, file=self.stream)
        else:
            print(stamped, file=self.stream, flush=True)

    def done(self, name: str, seconds: float) -> None:
        """Cell ``name`` finished in ``seconds``: one line, and the bar and projection moved on."""
        self.todo.remove(name)
        self.durations.setdefault(self.kind_of(name), []).append(seconds)
        self.finished += 1
        self.bar.update(1)
        self._show()
        self.line(f"cell {self.finished}/{self.total} done: {name} ({seconds:.0f} s); {self.projection()}")

    def close(self) -> None:
        self.bar.close()
