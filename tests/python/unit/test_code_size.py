"""Size limits of the Python code (bridge/, benches/, tests/python/): no function over 60 lines, no
file over 700 lines, so that every function fits on a screen and every module is one concept.
(Lines are at most 120 columns: ruff checks that, ruff.toml.) No node, no DDS; well under a second.

A function counts from its first decorator to its last line, docstring, comments and blank lines
included, as ``ruff format`` lays it out. ``OVER_60_LINES`` lists the functions that are longer
today: the list may only shrink (an entry whose function is gone fails the test too, so that the
list stays true); a new long function is a failure, not an entry.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
TREES = ("bridge", "benches", "tests/python")
MAX_FUNCTION_LINES = 60
MAX_FILE_LINES = 700

#: path::qualified name of the functions still over the limit (to be split; do not add to it).
OVER_60_LINES: set[str] = set()


def python_files() -> list[Path]:
    files = [p for tree in TREES for p in (ROOT / tree).rglob("*.py") if "__pycache__" not in p.parts]
    assert len(files) > 100, f"found only {len(files)} Python files under {TREES}"
    return sorted(files)


def function_lengths(path: Path) -> dict[str, int]:
    """Every function and method of ``path`` (nested ones too), by qualified name -> its lines."""
    lengths: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    first = min([child.lineno] + [d.lineno for d in child.decorator_list])
                    lengths[name] = child.end_lineno - first + 1
                visit(child, f"{name}.")
            else:
                visit(child, prefix)

    visit(ast.parse(path.read_text(), str(path)), "")
    return lengths


def test_no_python_file_is_over_700_lines():
    lines = {str(p.relative_to(ROOT)): len(p.read_text().splitlines()) for p in python_files()}
    long = {path: n for path, n in lines.items() if n > MAX_FILE_LINES}
    assert not long, f"files over {MAX_FILE_LINES} lines (split them by concept): {long}"


def test_no_python_function_is_over_60_lines():
    found = {f"{p.relative_to(ROOT)}::{name}": n for p in python_files() for name, n in function_lengths(p).items()}
    long = {k: n for k, n in found.items() if n > MAX_FUNCTION_LINES and k not in OVER_60_LINES}
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines (split them): {long}"
    gone = sorted(OVER_60_LINES - found.keys())
    assert not gone, f"OVER_60_LINES lists functions that no longer exist (remove them): {gone}"


def test_the_size_checks_can_fail(tmp_path):
    """The measure itself: a 61-line function is over the limit, decorators count."""
    body = "".join(f"        x{k} = {k}\n" for k in range(58))
    path = tmp_path / "long.py"
    path.write_text(f"class C:\n    @staticmethod\n    def f():\n{body}        return 0\n")
    assert function_lengths(path) == {"C.f": 61}
