"""The bridge package's layers (docs/layout.md): each subpackage imports only the layers below it,
so that what needs no ROS loads without ROS and registering the Gymnasium ids costs nothing.

Two kinds of check. On the source (no import, well under a second): docs/layout.md's
```layers-python block lists the layers, lowest first; every import in bridge/sorting_line_gym
(at the top of a module or inside a function, relative or absolute) goes to the importer's own
entry or one listed above it, and no module imports itself through others. At run time: modules
imported in a fresh interpreter list the heavy dependencies they pulled in, rclpy (and with it
DDS) and Stable-Baselines3 (and torch). No node, no DDS traffic.
"""

from __future__ import annotations

import ast
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import sorting_line_gym

PACKAGE = Path(sorting_line_gym.__file__).parent
HEAVY = ("rclpy", "stable_baselines3", "torch")


def loaded_after_import(*modules: str) -> list[str]:
    """The HEAVY packages present in ``sys.modules`` after importing ``modules`` in a new process."""
    code = (
        "import importlib, json, sys\n"
        f"for m in {list(modules)!r}: importlib.import_module(m)\n"
        f"print(json.dumps([h for h in {list(HEAVY)!r} if h in sys.modules]))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def modules_of(subpackage: str) -> list[str]:
    return [f"sorting_line_gym.{subpackage}.{m.name}" for m in pkgutil.iter_modules([str(PACKAGE / subpackage)])]


def test_registering_the_ids_loads_neither_rclpy_nor_sb3():
    """`import sorting_line_gym` (what RL Zoo's --gym-packages and gymnasium.make("sorting_line_gym:...")
    do) and making an env, which connects only at its first reset()."""
    assert loaded_after_import("sorting_line_gym") == []
    code = (
        "import sys, gymnasium, sorting_line_gym\n"
        "env = gymnasium.make('sorting_line_gym:SortingLineAdvanced-v0', setup='D')\n"
        "assert env.action_space.n == 30 and env.observation_space.shape == (2,)\n"
        "print('stable_baselines3' in sys.modules)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "False"


def test_the_line_layer_needs_no_ros():
    modules = modules_of("line")
    assert "sorting_line_gym.line.vocabulary" in modules and "sorting_line_gym.line.process" in modules
    assert loaded_after_import(*modules) == []


def test_the_workarounds_without_ros_need_no_ros():
    """Two workarounds need no ROS (the orphaned workers' parent-death signal, the host lock for
    joining the graph); the package itself imports none of its modules."""
    assert loaded_after_import("sorting_line_gym.workarounds") == []
    no_ros = ["sorting_line_gym.workarounds.orphaned_processes", "sorting_line_gym.workarounds.simultaneous_discovery"]
    assert set(no_ros) < set(modules_of("workarounds"))
    assert loaded_after_import(*no_ros) == []


def test_reports_need_neither_rclpy_nor_sb3():
    """reports/ analyses saved results: its tables, statistics and figures load without ROS and
    without SB3 (the runs that need them are studies/)."""
    modules = modules_of("reports")
    assert "sorting_line_gym.reports.benchmark_summary" in modules and "sorting_line_gym.reports.plots" in modules
    assert loaded_after_import(*modules) == []


@pytest.mark.parametrize(
    "subpackage", ["ros", "envs", "agents", "training", "reports", "studies", "bag", "workarounds"]
)
def test_no_layer_needs_sb3_but_those_that_train(subpackage):
    """SB3 and torch (half a GB, seconds of start-up) load only where a model is trained or loaded:
    the SB3 VecEnv and training (the studies that train import it inside their functions)."""
    allowed_sb3 = {
        "sorting_line_gym.envs.sb3_vec_env",
        "sorting_line_gym.training.callbacks",
        "sorting_line_gym.training.train",
    }
    modules = [m for m in modules_of(subpackage) if m not in allowed_sb3]
    assert modules
    assert "stable_baselines3" not in loaded_after_import(*modules), modules


# --- The order of the layers (docs/layout.md, "## Layers"), checked on the source ----------------------------------

ROOT = Path(__file__).resolve().parents[3]
LAYOUT = ROOT / "docs" / "layout.md"
#: The package's source tree (read, not imported).
SOURCE = ROOT / "bridge" / "sorting_line_gym"
#: Modules without Python source in the package: the extension maturin builds from native/.
EXTENSIONS = ("sorting_line_gym._native",)


def layer_order(text: str) -> list[str]:
    """The entries of the ```layers-python block under "## Layers", lowest layer first."""
    section = text.split("\n## Layers\n", 1)
    assert len(section) == 2, 'docs/layout.md has no "## Layers" section'
    block = section[1].split("```layers-python\n", 1)
    assert len(block) == 2, "docs/layout.md's Layers section has no ```layers-python block"
    entries = [line.strip() for line in block[1].split("```", 1)[0].splitlines() if line.strip()]
    repeated = sorted({e for e in entries if entries.count(e) > 1})
    assert not repeated, f"layers-python lists {repeated} more than once"
    return entries


def source_modules(package: Path) -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its own name, for its __init__.py)."""
    modules = {}
    for path in sorted(package.rglob("*.py")):
        parts = (package.name, *path.relative_to(package).with_suffix("").parts)
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def imports_of(name: str, path: Path, known: set[str]) -> list[tuple[int, str]]:
    """(line, module) for every import in ``path`` of a module in ``known``, at any depth (an import
    inside a function or under ``if TYPE_CHECKING`` counts as one at the top). The module named
    counts, not the packages around it whose ``__init__.py`` Python runs first; a name imported
    from a package is its submodule where there is one. Imports by a computed name
    (``importlib.import_module``: the root's lazy env classes, bag.schema's message types) are not
    seen."""
    own_package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = own_package.split(".")[: len(own_package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{alias.name}" for alias in node.names]
        else:
            continue
        for target in targets:
            # The longest known prefix: `from .links import Link` imports the module links.
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target:
                found.append((node.lineno, target))
    return found


def entry_of(module: str, entries: list[str]) -> str:
    """The layer entry a module belongs to: the longest entry that is a prefix of its path in the
    package (``bag/format`` for ``sorting_line_gym.bag.format.names``); the package's own
    ``__init__.py`` is the entry ``__init__``."""
    parts = module.split(".")[1:] or ["__init__"]
    matches = [e for e in entries if parts[: len(e.split("/"))] == e.split("/")]
    assert matches, f"{module} belongs to no entry of docs/layout.md's layers-python block: add it there"
    return max(matches, key=lambda e: len(e.split("/")))


def import_graph(package: Path) -> tuple[dict[str, Path], dict[str, list[tuple[int, str]]]]:
    """The package's modules (name -> file) and what each imports of the package: (line, module)."""
    modules = source_modules(package)
    known = set(modules) | set(EXTENSIONS)
    graph = {}
    for name, path in modules.items():
        graph[name] = [(line, target) for line, target in imports_of(name, path, known) if target != name]
    return modules, graph


def back_up_imports(package: Path, entries: list[str]) -> list[str]:
    """``file:line`` of every import of a module whose entry is listed after the importer's."""
    modules, graph = import_graph(package)
    rank = {entry: i for i, entry in enumerate(entries)}
    found = []
    for name, edges in graph.items():
        own = entry_of(name, entries)
        for line, target in edges:
            theirs = entry_of(target, entries)
            if rank[theirs] > rank[own]:
                where = modules[name].relative_to(package.parent)
                found.append(f"{where}:{line} ({own}) imports {target} ({theirs}, listed after {own})")
    return found


def import_cycles(graph: dict[str, list[tuple[int, str]]]) -> list[list[str]]:
    """One cycle (a -> b -> ... -> a) through each strongly connected set of modules (Tarjan)."""
    successors = {name: sorted({t for _, t in edges if t in graph}) for name, edges in graph.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    components = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in successors[v]:
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while not component or component[-1] != v:
                component.append(stack.pop())
            if len(component) > 1:
                components.append(set(component))

    for v in sorted(successors):
        if v not in index:
            connect(v)
    return [cycle_through(min(c), c, successors) for c in components]


def cycle_through(start: str, component: set[str], successors: dict[str, list[str]]) -> list[str]:
    """The shortest path from ``start`` back to itself within ``component`` (breadth first)."""
    came_from = {start: ""}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w in successors[v]:
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(came_from[path[-1]])
                    return [*reversed(path), start]
                if w in component and w not in came_from:
                    came_from[w] = v
                    following.append(w)
        frontier = following
    raise AssertionError(f"no cycle through {start}")


def test_every_module_belongs_to_a_layer_entry():
    """The block places every module (a new subpackage needs its line) and lists no entry that has none."""
    entries = layer_order(LAYOUT.read_text())
    modules, _ = import_graph(SOURCE)
    assert len(modules) > 50 and "sorting_line_gym.line.vocabulary" in modules
    used = {entry_of(m, entries) for m in [*modules, *EXTENSIONS]}
    assert used == set(entries), f"entries of the layers-python block with no module: {set(entries) - used}"


def test_no_import_runs_back_up_the_layers():
    """A module imports only modules of its own entry or of entries listed above it in the block."""
    found = back_up_imports(SOURCE, layer_order(LAYOUT.read_text()))
    assert not found, "imports against docs/layout.md's layer order:\n" + "\n".join(found)


def test_no_import_circle():
    """No module imports itself through others, not even through an import inside a function."""
    _, graph = import_graph(SOURCE)
    cycles = import_cycles(graph)
    assert not cycles, "import circles (one through each set of modules that import each other):\n" + "\n".join(
        " -> ".join(c) for c in cycles
    )


def test_the_checks_find_a_back_up_import_and_a_circle(tmp_path):
    """The checks on a package of three modules: imports up the order (one inside a function, one
    absolute) that close a circle, with a subpackage as an entry of its own; the order read from a
    layout written as ours."""
    files = {
        "__init__.py": "",
        "low/__init__.py": "",
        "low/a.py": "def f():\n    from ..high.b import g\n    return g\n",
        "high/__init__.py": "",
        "high/b.py": "import os\n\nfrom ..low import a\nfrom ..high.deep import c\n",
        "high/deep/__init__.py": "",
        "high/deep/c.py": "import pkg.high.b\n",
    }
    for name, text in files.items():
        (tmp_path / "pkg" / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "pkg" / name).write_text(text)
    layout = "# Layout\n\n## Layers\n\nText.\n\n```layers-python\nlow\nhigh/deep\nhigh\n__init__\n```\n"
    entries = layer_order(layout)
    assert entries == ["low", "high/deep", "high", "__init__"]
    assert entry_of("pkg.high.deep.c", entries) == "high/deep" and entry_of("pkg", entries) == "__init__"
    assert back_up_imports(tmp_path / "pkg", entries) == [
        "pkg/high/deep/c.py:1 (high/deep) imports pkg.high.b (high, listed after high/deep)",
        "pkg/low/a.py:2 (low) imports pkg.high.b (high, listed after low)",
    ]
    _, graph = import_graph(tmp_path / "pkg")
    assert import_cycles(graph) == [["pkg.high.b", "pkg.high.deep.c", "pkg.high.b"]]
