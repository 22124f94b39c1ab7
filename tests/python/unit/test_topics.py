"""One topic vocabulary per language: the Python package's (sorting_line_gym.line.topics) against
the node's table (src/ros/topics.rs, printed by ``sorting_line vocabulary``), and no module of the
package but that one writing a topic name, nor any helper of the tests or benchmark.

No ROS: the node's side speaks through ``sorting_line vocabulary``; the other checks read the
source (string constants, not docstrings or comments).
"""

from __future__ import annotations

import ast
import dataclasses
import json
import re
import subprocess
from pathlib import Path

import pytest

from sorting_line_gym.bag.format import topics as bag_topics
from sorting_line_gym.line import topics
from support import ros_harness as h

PACKAGE = h.ROOT / "bridge" / "sorting_line_gym"
VOCABULARY = PACKAGE / "line" / "topics.py"


@pytest.fixture(scope="module")
def rust():
    r = subprocess.run([str(h.node_binary()), "vocabulary"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_the_endpoints_are_the_nodes(rust):
    assert [dataclasses.asdict(e) for e in topics.ENDPOINTS] == rust["topics"]
    assert topics.QOS_PROFILES == rust["qos_profiles"]


def test_the_names_are_the_tables():
    """Each name constant is an endpoint's, and the derived tables hold the endpoints they say."""
    public = {k: v for k, v in vars(topics).items() if k.isupper() and not k.startswith("_")}
    constants = {k: v for k, v in public.items() if isinstance(v, str) and k != "INTERFACES"}
    names = {e.name for e in topics.ENDPOINTS}
    assert set(constants.values()) <= names, set(constants.values()) - names
    assert len(set(constants.values())) == len(constants)
    lines = {e.name for e in topics.ENDPOINTS if e.scope == "line" and e.kind != "service"}
    assert set(topics.LINE_TYPES) == lines == set(topics.PUBLISHED) | set(topics.COMMANDS)
    assert topics.HARDWARE == (topics.SENSORS_RATIO, topics.SORT_MODE_CMD)
    assert set(topics.line_types(evolving=True)) - set(topics.line_types()) == {topics.EVOLUTION_EVENT}
    assert set(h.LINE_TYPES) == set(topics.line_types()) and h.LINE_TYPES == topics.line_types()
    # The bag's layers see the same objects, not copies.
    assert bag_topics.LINE_TYPES is topics.LINE_TYPES and bag_topics.PUBLISHED is topics.PUBLISHED


# -- No topic name outside the vocabulary --------------------------------------------------------

#: Names with a `/` in them (or absolute): a string holding one, anywhere, names that topic.
_PATHS = sorted((e.name for e in topics.ENDPOINTS if "/" in e.name and e.scope != "private"), key=len, reverse=True)
_PATH = re.compile(r"(?<!\w)(" + "|".join(map(re.escape, _PATHS)) + r")(?![\w/])")
#: One-word names of a line's endpoints: as a piece of a joined name (`f"{ns}/state"`) anywhere...
_WORDS = [e.name for e in topics.ENDPOINTS if "/" not in e.name and e.scope == "line"]
_JOINED = re.compile(r"(?<![\w/])/(" + "|".join(_WORDS) + r")(?![\w/])")
#: ... and whole, where a topic is what the code means: an argument of a call that takes a topic,
#: a key of a table of topics, a comparison with a topic.
_TOPIC_CALLS = {
    "join",
    "join_ns",
    "name",
    "create_publisher",
    "create_subscription",
    "create_client",
    "create_service",
    "count_publishers",
    "count_subscribers",
    "raw_subscription",
    "resolve_topic_name",
    "get_publishers_info_by_topic",
    "get_subscriptions_info_by_topic",
}
_TOPIC_HOLDERS = re.compile(r"TYPES|msgs|messages|topic", re.IGNORECASE)


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the docstring nodes in ``tree``."""
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def _holder(node: ast.AST) -> str:
    """The name an expression ends in (``self.rel_msgs`` -> ``rel_msgs``), or ""."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Call):
        return _holder(node.func)
    return ""


def topic_strings(source: str) -> list[tuple[int, str]]:
    """(line, string) of every string constant in ``source`` (docstrings aside) that names one of
    the node's topics."""
    tree = ast.parse(source)
    skip = _docstrings(tree)
    found = []
    whole: set[int] = set()
    for node in ast.walk(tree):
        candidates: list[ast.AST] = []
        if isinstance(node, ast.Call) and _holder(node.func) in _TOPIC_CALLS:
            candidates = list(node.args)
        elif isinstance(node, ast.Call) and _holder(node.func) == "get" and isinstance(node.func, ast.Attribute):
            candidates = list(node.args[:1]) if _TOPIC_HOLDERS.search(_holder(node.func.value)) else []
        elif isinstance(node, ast.Subscript) and _TOPIC_HOLDERS.search(_holder(node.value)):
            candidates = [node.slice]
        elif isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            if any(_TOPIC_HOLDERS.search(_holder(s)) or _holder(s) == "rel" for s in sides):
                candidates = sides
        whole.update(id(c) for c in candidates if isinstance(c, ast.Constant) and c.value in _WORDS)
    for node in ast.walk(tree):
        if not isinstance(node, ast.Constant) or not isinstance(node.value, str) or id(node) in skip:
            continue
        if _PATH.search(node.value) or _JOINED.search(node.value) or id(node) in whole:
            found.append((node.lineno, node.value))
    return found


def test_the_check_finds_what_it_should():
    caught = """
x = join(ns, "state")
y = LINE_TYPES["input"]
z = f"{ns}/reset refused"
w = rel_msgs.get("events/reset", [])
if rel == "state": pass
node.create_publisher(T, "/diagnostics", 10)
"""
    assert [line for line, _ in topic_strings(caught)] == [2, 3, 4, 5, 6, 7]
    fine = '''
"""A docstring names cmd/speed and /clock."""
rec.get("state")  # a recording's state, not a topic
options = {"input": "random"}
path = "/clocks/x"; other = "cmd/speedy"
'''
    assert topic_strings(fine) == []


def test_no_module_but_the_vocabulary_writes_a_topic_name():
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == VOCABULARY:
            continue
        for line, text in topic_strings(path.read_text()):
            offenders.append(f"{path.relative_to(h.ROOT)}:{line}: {text!r}")
    assert not offenders, "topic names outside sorting_line_gym.line.topics:\n" + "\n".join(offenders)


def test_no_helper_or_benchmark_writes_a_topic_name():
    """The test harness (tests/python/support) and the benchmarks use the line's topics without
    checking them: they take the names from the vocabulary too. (The test files themselves state
    the node's public names on their own, as a user writes them: that is what they check.)"""
    offenders = []
    for folder in (h.ROOT / "tests" / "python" / "support", h.ROOT / "benches"):
        for path in sorted(folder.rglob("*.py")):
            for line, text in topic_strings(path.read_text()):
                offenders.append(f"{path.relative_to(h.ROOT)}:{line}: {text!r}")
    assert not offenders, "topic names outside sorting_line_gym.line.topics:\n" + "\n".join(offenders)


def test_the_vocabulary_is_standard_library_only():
    """launch_scripts/docs.py loads it from its file before any set-up."""
    tree = ast.parse(Path(VOCABULARY).read_text())
    imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert imported <= {"__future__", "dataclasses"}, imported
