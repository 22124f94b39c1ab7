"""The bridge package's layers (docs/layout.md): each subpackage imports only the layers below it,
so that what needs no ROS loads without ROS and registering the Gymnasium ids costs nothing.

Each check imports modules in a fresh interpreter and lists the heavy dependencies it pulled in:
rclpy (and with it DDS), Stable-Baselines3 (and torch). No node, no DDS traffic.
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


def test_the_workarounds_the_line_layer_uses_need_no_ros():
    """The line layer starts processes and joins the graph through two workarounds; the package
    itself imports none of its modules."""
    assert loaded_after_import("sorting_line_gym.workarounds") == []
    no_ros = ["sorting_line_gym.workarounds.orphaned_processes", "sorting_line_gym.workarounds.simultaneous_discovery"]
    assert set(no_ros) < set(modules_of("workarounds"))
    assert loaded_after_import(*no_ros) == []


@pytest.mark.parametrize("subpackage", ["ros", "envs", "agents", "training", "reports", "bag", "workarounds"])
def test_no_layer_needs_sb3_but_those_that_train(subpackage):
    """SB3 and torch (half a GB, seconds of start-up) load only where a model is trained or loaded:
    the SB3 VecEnv, training, and the reports that train (the benchmark)."""
    allowed_sb3 = {
        "sorting_line_gym.envs.sb3_vec_env",
        "sorting_line_gym.training.callbacks",
        "sorting_line_gym.training.train",
        "sorting_line_gym.reports.benchmark",
    }
    modules = [m for m in modules_of(subpackage) if m not in allowed_sb3]
    assert modules
    assert "stable_baselines3" not in loaded_after_import(*modules), modules


def test_agents_do_not_import_training():
    """The agents layer sits below training: no module of agents/ imports training/, not even
    lazily (loading a saved SB3 model is training's: ``training.trained_agent``)."""
    offenders = []
    for path in sorted((PACKAGE / "agents").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                names = [("." * node.level) + (node.module or "")]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                continue
            names = [n + "." for n in names]
            if any(n.startswith(("..training.", "sorting_line_gym.training.")) for n in names):
                offenders.append(f"{path.name}:{node.lineno}")
    assert not offenders, f"agents/ imports training/ at {offenders}"
