"""``results.csv``: the benchmark's held-out scores as one row per (setup, variant, agent, training
seed, held-out seed), the machine-readable form of Table 1 that a user's own agent is compared in
(``comparison``; `sorting-line-benchmark --compare MY_RESULTS`).

Columns (``COLUMNS``, in this order; ``COLUMN_MEANINGS`` says the same for the docs):

- ``setup``: A, B, C or D (the paper's setups); ``variant``: basic or advanced;
- ``agent``: random, rba, rba-hold, dqn, ppo, a2c, or oracle (the exact clairvoyant optimum of the
  seed, one row per seed); a user's file names its own agent(s) here;
- ``train_seed``: the training seed of an RL run; empty for the deterministic baselines and the
  oracle (one run each);
- ``heldout_seed``: the evaluation episode's seed (the held-out seeds, 10000..10099 by default);
- ``reward``: the episode's summed reward (50 steps, deterministic policy: `sorting-line-eval`'s protocol);
- ``normalized``: (reward - random's) / (oracle's - random's) on that seed; empty where the line has no
  random cell or the seed has no scale (the oracle does no better than random). Optional in a file
  to compare: ``--compare`` recomputes it from the table's own random and oracle rows.

Pure: rows from the cells' records, and rows to and from the file, with a clear error for a file
that is not in this format. No ROS, no training.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..line.vocabulary import EPISODE_STEPS, SETUPS, VARIANT_CHOICE, VARIANTS, alternatives
from .benchmark_summary import References, by_cell, episode_seeds, references

COLUMNS = ("setup", "variant", "agent", "train_seed", "heldout_seed", "reward", "normalized")
#: What a file to compare must have (``normalized`` is recomputed from the table's references).
REQUIRED = COLUMNS[:-1]
COLUMN_MEANINGS = {
    "setup": f"{alternatives(SETUPS)}: the paper's setup",
    "variant": VARIANT_CHOICE,
    "agent": "random, rba, rba-hold, dqn, ppo, a2c, or oracle (the exact optimum of the seed); yours: its own name",
    "train_seed": "the training seed of an RL run (one run); empty for a deterministic baseline and the oracle",
    "heldout_seed": "the evaluation episode's seed",
    "reward": f"the episode's summed reward ({EPISODE_STEPS} steps, deterministic policy)",
    "normalized": "(reward - random's) / (oracle's - random's) on that seed; empty without a scale or random cell",
}


class ResultsError(ValueError):
    """A results file that is not in ``COLUMNS``' format, with what is wrong and what is allowed."""


@dataclass(frozen=True)
class ResultRow:
    """One row of ``results.csv``."""

    setup: str
    variant: str
    agent: str
    train_seed: int | None
    heldout_seed: int
    reward: float
    normalized: float | None = None

    @property
    def line(self) -> tuple[str, str]:
        return (self.setup, self.variant)


def rows_of(
    records: list[dict[str, Any]], oracles: dict[tuple[str, str], dict[str, Any]] | None = None
) -> list[ResultRow]:
    """The rows of the cells' ``records`` (their held-out episodes), each RL run under its training
    seed; with ``oracles`` also the oracle's rows and every row's normalized score."""
    refs = references(records, oracles) if oracles else {}
    rows = []
    for (setup, variant, agent), rs in sorted(by_cell([r for r in records if "heldout" in r]).items()):
        for r in rs:
            rows += _run_rows(setup, variant, agent, r["cell"].get("train_seed"), r, refs.get((setup, variant)))
    for (setup, variant), oracle in sorted((oracles or {}).items()):
        record = {"heldout": oracle}
        rows += _run_rows(setup, variant, "oracle", None, record, refs.get((setup, variant)))
    return rows


def _run_rows(
    setup: str, variant: str, agent: str, train_seed, record: dict[str, Any], refs: References | None
) -> list[ResultRow]:
    seeds = episode_seeds(record)
    rewards = np.array([[e["reward"] for e in record["heldout"]["per_episode"]]], dtype=float)
    normalized: list[float | None] = [None] * len(seeds)
    if refs is not None:
        values, left_out = refs.normalize(seeds, rewards)
        kept = iter(values[0].tolist())
        normalized = [None if s in left_out else next(kept) for s in seeds]
    return [
        ResultRow(setup, variant, agent, train_seed, s, float(x), n)
        for s, x, n in zip(seeds, rewards[0], normalized, strict=True)
    ]


def write(path: Path, rows: list[ResultRow]) -> Path:
    """``rows`` as ``path`` (``COLUMNS``; floats as Python's repr, so they read back exactly)."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(COLUMNS)
        for r in rows:
            seed = "" if r.train_seed is None else r.train_seed
            normalized = "" if r.normalized is None else repr(r.normalized)
            writer.writerow([r.setup, r.variant, r.agent, seed, r.heldout_seed, repr(r.reward), normalized])
    return path


def read(path: Path) -> list[ResultRow]:
    """The rows of a results file; ``ResultsError`` naming the file, the line and the value for
    anything not in the format: a missing column, an unknown setup or variant, an empty agent, a
    seed that is not a whole number, a reward that is not a finite number, a row given twice."""
    try:
        text = Path(path).read_text()
    except OSError as e:
        raise ResultsError(f"{path}: cannot be read: {e.strerror}") from None
    reader = csv.DictReader(text.splitlines())
    missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
    if missing:
        raise ResultsError(
            f"{path}: no column {', '.join(missing)}; needed: {', '.join(REQUIRED)} (normalized optional), "
            f"found: {', '.join(reader.fieldnames or []) or 'no header'}"
        )
    rows, seen = [], set()
    for number, fields in enumerate(reader, start=2):  # line 1 is the header
        row = _row(fields, f"{path}, line {number}")
        key = (row.setup, row.variant, row.agent, row.train_seed, row.heldout_seed)
        if key in seen:
            raise ResultsError(f"{path}, line {number}: {_key(key)} is given twice: allowed once")
        seen.add(key)
        rows.append(row)
    if not rows:
        raise ResultsError(f"{path}: has a header but no rows")
    return rows


def _key(key: tuple) -> str:
    setup, variant, agent, train_seed, heldout_seed = key
    return f"agent {agent!r} on {setup} {variant}, train_seed {train_seed}, heldout_seed {heldout_seed}"


def _row(fields: dict[str, str | None], where: str) -> ResultRow:
    def value(column: str) -> str:
        return (fields.get(column) or "").strip()

    if value("setup") not in SETUPS:
        raise ResultsError(f"{where}: setup {value('setup')!r} is not known: allowed {', '.join(SETUPS)}")
    if value("variant") not in VARIANTS:
        raise ResultsError(f"{where}: variant {value('variant')!r} is not known: allowed {', '.join(VARIANTS)}")
    if not value("agent"):
        raise ResultsError(f"{where}: agent is empty: allowed any name")
    train_seed = _whole(value("train_seed"), "train_seed", where) if value("train_seed") else None
    normalized = _finite(value("normalized"), "normalized", where) if value("normalized") else None
    return ResultRow(
        value("setup"),
        value("variant"),
        value("agent"),
        train_seed,
        _whole(value("heldout_seed"), "heldout_seed", where),
        _finite(value("reward"), "reward", where),
        normalized,
    )


def _whole(text: str, column: str, where: str) -> int:
    try:
        number = int(text)
    except ValueError:
        raise ResultsError(f"{where}: {column} {text!r} is not valid: allowed a whole number >= 0") from None
    if number < 0:
        raise ResultsError(f"{where}: {column} {number} is not valid: allowed a whole number >= 0")
    return number


def _finite(text: str, column: str, where: str) -> float:
    try:
        number = float(text)
    except ValueError:
        number = math.nan
    if not math.isfinite(number):
        raise ResultsError(f"{where}: {column} {text!r} is not valid: allowed a finite number")
    return number
