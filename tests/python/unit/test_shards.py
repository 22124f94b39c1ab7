"""The ROS tier's sessions share its files (tests/python/support/shards.py), checked with real pytest sessions.

Each test writes a scratch suite (a conftest that installs shards.run_claimed as test.sh's sessions have it,
and a few files whose tests append to a log what ran and what set up), runs pytest on it in a subprocess and
reads the log: a file a session claims runs whole and once, in its order, the slowest files (SLOWEST_FIRST)
first; a file claimed before runs nowhere and counts as deselected; files of a TOGETHER group go to one
session; the session's fixture is set up once over several claimed files while a module fixture is torn down
at its file's end; a session left with nothing to claim exits 0 (pytest's "no tests ran" would fail
test.sh); without the claims folder pytest's own loop runs everything. No ROS; about 3 s.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from support import shards

SUPPORT = Path(shards.__file__).resolve().parent.parent

CONFTEST = f"""
import sys
sys.path.insert(0, {str(SUPPORT)!r})
import pytest
from support import shards

@pytest.hookimpl(tryfirst=True)
def pytest_runtestloop(session):
    return shards.run_claimed(session)

def record(what):
    with open({{log!r}}, "a") as f:
        f.write(what + "\\n")

@pytest.fixture(scope="session")
def per_session():
    record("session up")
    yield
    record("session down")

@pytest.fixture(scope="module")
def per_module(request):
    record("module up " + request.module.__name__)
    yield
    record("module down " + request.module.__name__)
"""

TESTS = """
from conftest import record

def test_one(per_session, per_module):
    record("{name}::test_one")

def test_two(per_session, per_module):
    record("{name}::test_two")
"""

FILES = ("test_a", "test_b", "test_rllib", "test_ray_cells")


def suite(tmp_path: Path) -> tuple[Path, Path]:
    root, log = tmp_path / "suite", tmp_path / "ran.log"
    root.mkdir()
    (root / "conftest.py").write_text(CONFTEST.format(log=str(log)))
    for name in FILES:
        (root / f"{name}.py").write_text(TESTS.format(name=name))
    return root, log


def session(root: Path, claims: Path | None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != shards.CLAIMS}
    if claims is not None:
        env[shards.CLAIMS] = str(claims)
    argv = [sys.executable, "-m", "pytest", str(root), "-q", "-p", "no:cacheprovider", "--rootdir", str(root)]
    return subprocess.run(argv, cwd=root, env=env, capture_output=True, text=True, timeout=120)


def ran(log: Path) -> list[str]:
    return log.read_text().splitlines() if log.exists() else []


def test_a_session_runs_the_files_it_claims_whole_and_skips_the_claimed_ones(tmp_path):
    root, log = suite(tmp_path)
    claims = tmp_path / "claims"
    claims.mkdir()
    (claims / "test_b.py.claim").write_text("another session\n")
    r = session(root, claims)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = ran(log)
    assert not [line for line in lines if "test_b" in line], lines
    assert lines == [
        "session up",
        "module up test_ray_cells",
        "test_ray_cells::test_one",
        "test_ray_cells::test_two",
        "module down test_ray_cells",
        "module up test_rllib",
        "test_rllib::test_one",
        "test_rllib::test_two",
        "module down test_rllib",
        "module up test_a",
        "test_a::test_one",
        "test_a::test_two",
        "module down test_a",
        "session down",
    ], lines
    assert "6 passed, 2 deselected" in r.stdout, r.stdout
    assert "shards: 2 tests of 1 files ran in another session" in r.stdout, r.stdout
    assert sorted(p.name for p in claims.iterdir()) == [
        "test_a.py.claim",
        "test_b.py.claim",
        "test_rllib.py+test_ray_cells.py.claim",
    ]


def test_a_session_with_nothing_left_to_claim_runs_nothing_and_passes(tmp_path):
    root, log = suite(tmp_path)
    claims = tmp_path / "claims"
    claims.mkdir()
    assert session(root, claims).returncode == 0
    log.unlink()
    r = session(root, claims)
    assert r.returncode == 0, r.stdout + r.stderr
    assert ran(log) == [], ran(log)
    assert "8 deselected" in r.stdout, r.stdout


def test_without_a_claims_folder_every_test_runs(tmp_path):
    root, log = suite(tmp_path)
    r = session(root, None)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "8 passed" in r.stdout, r.stdout
    assert len([line for line in ran(log) if "::" in line]) == 8


def test_a_claims_folder_that_does_not_exist_is_named(tmp_path):
    root, _ = suite(tmp_path)
    r = session(root, tmp_path / "nowhere")
    assert r.returncode != 0
    assert f"{shards.CLAIMS}={str(tmp_path / 'nowhere')!r}: no such folder" in r.stdout + r.stderr
