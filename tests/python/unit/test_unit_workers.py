"""How many pytest-xdist workers a session of the unit tier starts (support/tiers.unit_workers, which
unit/conftest.py's pytest_xdist_auto_num_workers answers pytest.ini's ``-n auto`` with): the CPUs, at
most four, for folders; none for a file or a test, so that one test starts at once in one process. And
pytest.ini is the tier's own: it asks for ``-n auto``, which needs pytest-xdist from the pinned set."""

from __future__ import annotations

import configparser
import os
from pathlib import Path
from types import SimpleNamespace

from support import tiers

UNIT = Path(__file__).resolve().parent
ROOT = UNIT.parents[2]


def workers(*args: str) -> int:
    return tiers.unit_workers(SimpleNamespace(args=list(args), invocation_params=SimpleNamespace(dir=ROOT)))


def test_a_folder_gets_a_worker_per_cpu_and_at_most_four():
    cpus = len(os.sched_getaffinity(0))
    assert workers("tests/python/unit") == min(tiers.MAX_UNIT_WORKERS, cpus) == min(4, cpus)
    assert workers() == min(4, cpus)  # pytest's own default: the current folder


def test_a_file_or_a_test_runs_in_one_process():
    assert workers("tests/python/unit/test_stats.py") == 0
    assert workers("tests/python/unit/test_stats.py::test_iqm_is_the_mean_of_the_middle_half") == 0
    assert workers("tests/python/unit", "tests/python/unit/test_stats.py") == 0


def test_the_tiers_ini_asks_for_auto_and_the_pins_hold_xdist():
    ini = configparser.ConfigParser()
    ini.read(UNIT / "pytest.ini")
    assert ini["pytest"]["addopts"].split() == ["-n", "auto"]
    pins = (ROOT / "launch_scripts" / "requirements-ros.txt").read_text().splitlines()
    assert any(line.startswith("pytest-xdist==") for line in pins)
