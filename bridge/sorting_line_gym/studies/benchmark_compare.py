"""`sorting-line-benchmark --compare MY_RESULTS`: a user's agent beside Table 1, with Table 1's own
statistics (``reports.comparison``), from the cells the benchmark has (also with ``--report-only``:
nothing is trained for it).

MY_RESULTS is a CSV in the columns of the table's ``results.csv`` (``reports.results_csv``), with
the user's agent under its own name. Its format is checked when the command line is read (a
missing column, an unknown setup or variant, a value that is not a number), and its fit to the
table (its lines, its held-out seeds, at least two runs) once the cells are loaded: either way a
clear error and exit 2, before anything is drawn. The comparison is written to
``<out>/compare/<MY_RESULTS' stem>.md``, ``.json`` and ``.png``/``.svg`` (a strip plot of every
run), and printed after the table.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..reports import comparison, results_csv


@dataclass(frozen=True)
class Compared:
    """The file given to ``--compare`` and its rows."""

    path: Path
    rows: list[results_csv.ResultRow]


def _results_file(text: str) -> Compared:
    """``--compare``'s value: the file, read and checked as ``results.csv``'s format (argparse
    reports the error and exits 2)."""
    try:
        return Compared(Path(text), results_csv.read(Path(text)))
    except results_csv.ResultsError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--compare",
        metavar="MY_RESULTS",
        type=_results_file,
        default=None,
        help="a CSV of your agent's held-out rewards in results.csv's columns (docs/benchmark.md): put beside the "
        "table with the same statistics, in <out>/compare/; works with --report-only",
    )


def report(args, records: list[dict[str, Any]], write_report: Callable[[], list[Path]]) -> int | None:
    """Checks ``--compare``'s file against the table's cells (exit code 2 if it does not fit, before
    anything is written), then ``write_report()`` and the comparison; prints what was written,
    the table and the comparison. None when all went well."""
    theirs: Compared | None = args.compare
    if theirs is not None:
        problem = comparison.mismatch(theirs.rows, results_csv.rows_of(records))
        if problem:
            print(f"sorting-line-benchmark: --compare {theirs.path}: {problem}", file=sys.stderr)
            return 2
    written = write_report()
    text = None
    if theirs is not None:
        result = comparison.compare(theirs.rows, results_csv.read(args.out / "results.csv"))
        stem = args.out / "compare" / theirs.path.stem.replace(".", "_")  # (a dot would be taken for a suffix)
        stem.parent.mkdir(parents=True, exist_ok=True)
        text = comparison.markdown(result, str(theirs.path))
        stem.with_suffix(".md").write_text(text)
        stem.with_suffix(".json").write_text(json.dumps({"source": str(theirs.path), **result}, indent=2) + "\n")
        written += [stem.with_suffix(".md"), stem.with_suffix(".json"), *comparison.figure(result, stem)]
    for path in written:
        print(f"written: {path}", file=sys.stderr)
    print((args.out / "table.md").read_text())
    if text is not None:
        print(text)
    return None
