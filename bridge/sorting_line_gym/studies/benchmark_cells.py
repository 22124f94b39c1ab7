"""The benchmark's cells (``sorting-line-benchmark``, ``sorting-line-engine-check``): what a cell
is (an agent on a line, with its training seed, lines and engine) and its name, the plan of a run's
cells, how ``--engine batched`` groups them, and the saved records: their format, how a rerun
finds the cells it can keep, and which saved cells the report's learning curves add.

A record is ``<out>/cells/<name>.json``, written whole or not at all by the benchmark. Format 2
adds ``format`` and an RL cell's learning ``curve`` (studies/curves.py); a record without
``format`` is of format 1 (before curves) and is read as it is, without a curve; one of a later
format is refused (CellFormatError), naming its version and what to do.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from ..reports.benchmark_summary import BASELINES, Heldout
from ..training.hyperparams import ALGOS, DEFAULT_MAPPING

#: Who trains the RL cells: SB3 cell by cell, or the batched trainer with the seeds of a line at once.
ENGINES = ("sb3", "batched")
#: The format of a cell's record: 2 adds ``format`` and an RL cell's learning ``curve``. A record
#: without ``format`` is of format 1 (before curves) and is read as it is, without a curve.
CELL_FORMAT = 2


@dataclass(frozen=True)
class Cell:
    """One evaluation of the benchmark: an agent on a line (and its training seed and number of
    training lines, for RL)."""

    setup: str
    variant: str
    agent: str
    train_seed: int | None = None
    n_envs: int = 1
    #: How the one-line hyperparameters go to ``n_envs`` lines (``hyperparams.MAPPINGS``).
    mapping: str = DEFAULT_MAPPING
    #: Who trains it (``ENGINES``); in the name of a batched cell, so the engines' cells never mix.
    engine: str = "sb3"

    @property
    def lines(self) -> str:
        """``_n<N>`` for N lines, with the mapping when it is not the default; empty for one line."""
        if self.n_envs == 1:
            return ""
        return f"_n{self.n_envs}" + (f"_{self.mapping}" if self.mapping != DEFAULT_MAPPING else "")

    @property
    def name(self) -> str:
        lines = self.lines
        seed = f"_seed{self.train_seed}" if self.train_seed is not None else ""
        engine = f"_{self.engine}" if self.engine != "sb3" else ""
        return f"{self.setup}_{self.variant}_{self.agent}{lines}{engine}{seed}"

    def fields(self) -> dict[str, Any]:
        """The cell as its record holds it: an SB3 cell without the engine, as before there were two."""
        fields = asdict(self)
        if self.engine == "sb3":
            del fields["engine"]
        return fields


def plan(
    setups, variants, agents, train_seeds, n_envs: int = 1, mapping: str = DEFAULT_MAPPING, engine: str = "sb3"
) -> list[Cell]:
    """Baselines first (quick), then RL cells by training seed and algorithm, in the order given,
    so a partial run has whole rows: one algorithm on every line before the next. Baselines train
    nothing, so they are the same cells for both engines."""
    cells = [Cell(s, v, a) for s in setups for v in variants for a in agents if a in BASELINES]
    cells += [
        Cell(s, v, a, seed, n_envs, mapping if n_envs > 1 else DEFAULT_MAPPING, engine)
        for seed in train_seeds
        for a in agents
        if a in ALGOS
        for s in setups
        for v in variants
    ]
    return cells


class CellFormatError(ValueError):
    """A saved cell of a format this version does not read."""


def batches(todo: list[Cell]) -> list[list[Cell]]:
    """The cells as ``--engine batched`` runs them: a baseline alone, the RL cells that differ only
    by training seed together, in the order of each group's first cell."""
    groups: dict[Any, list[Cell]] = {}
    for c in todo:
        key = (c.setup, c.variant, c.agent, c.n_envs, c.mapping, c.engine) if c.agent in ALGOS else c
        groups.setdefault(key, []).append(c)
    return list(groups.values())


def load_cell(cell: Cell, out: Path, timesteps: int, heldout: Heldout) -> dict[str, Any] | None:
    """The saved record of ``cell`` if it was run with the same budget and held-out seeds. A record
    of format 1 (before learning curves) is read as it is, without a curve (its scores do not depend
    on one; delete the cell to record it again with its curve); one of a later format than
    ``CELL_FORMAT`` is a CellFormatError."""
    path = out / "cells" / f"{cell.name}.json"
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text())
    except json.JSONDecodeError:
        return None
    version = record.get("format", 1)
    if not isinstance(version, int) or version > CELL_FORMAT:
        raise CellFormatError(
            f"{path}: a cell of format {version!r}, written by a later version of sorting-line-benchmark (this one "
            f"reads formats 1 .. {CELL_FORMAT}): run it with that version, or use another --out"
        )
    return record if kept(cell, record, timesteps, heldout) else None


def kept(cell: Cell, record: dict[str, Any], timesteps: int, heldout: Heldout) -> bool:
    """Whether ``record`` of ``cell`` was run with this budget, engine and held-out seeds."""
    if cell.agent in ALGOS and record.get("timesteps") != timesteps:
        return False
    if cell.agent in ALGOS and record.get("engine", "sb3") != cell.engine:  # an SB3 record names none
        return False
    saved = record.get("heldout")
    return bool(saved) and (saved["seed"], saved["episodes"]) == (heldout.seed, heldout.episodes)


def saved_records(out: Path) -> list[dict[str, Any]]:
    """Every finished cell in ``out`` (any budget or number of lines), for the agreement check."""
    records = []
    for path in sorted((out / "cells").glob("*.json")):
        try:
            records.append(json.loads(path.read_text()))
        except json.JSONDecodeError:
            continue
    return records


def with_saved_curves(
    records: list[dict[str, Any]], saved: list[dict[str, Any]], timesteps: int, heldout: Heldout
) -> list[dict[str, Any]]:
    """``records`` and every other RL cell with a curve among ``saved`` (``saved_records``) that a
    run of this budget and held-out seeds keeps (:func:`kept`): another engine's cells, or the
    one-line cells of --n-envs's check, which the learning curves set beside the report's own, each
    as a series."""
    names = {Cell(**r["cell"]).name for r in records}
    found = list(records)
    for r in saved:
        if r.get("format") != CELL_FORMAT or not r.get("curve") or r["cell"]["agent"] not in ALGOS:
            continue  # a format-1 record has no curve; a later format is skipped, not refused: only a figure
        cell = Cell(**r["cell"])
        if cell.name not in names and kept(cell, r, timesteps, heldout):
            names.add(cell.name)
            found.append(r)
    return found
