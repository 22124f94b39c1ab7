"""The pytest plugin `sorting_line_gym.testing` as a user runs it: the examples of
docs/testing-controllers.md (docs/examples/), copied with a golden bag into a directory of their
own and run by a pytest of their own (a subprocess: a fresh rclpy, no conftest of ours).

- the docs show both examples verbatim;
- test_my_controller.py, the short test of a controller, passes against the golden bag, open and
  closed loop; the same open-loop test of a changed controller (rba-hold instead of rba) fails,
  naming the tick and field;
- test_record_golden.py: a node, the controller, the recorder and three episodes make a bag
  that the controller then passes;
- the player fixture plays a bag into the test's namespace and the graph fixture sets the test's
  own ROS_DOMAIN_ID and LOCALHOST discovery; outside a loopback-only network namespace (faked
  here) the plugin warns once per run, or skips with --sorting-line-require-netns;
- pytest finds the plugin through its pytest11 entry point (no -p).
"""

from __future__ import annotations

import importlib.metadata
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from support import ros_harness as h
from support.bag_golden import DATA

EXAMPLES = h.ROOT / "docs" / "examples"
DOC = h.ROOT / "docs" / "testing-controllers.md"
PLUGIN = "sorting_line_gym.testing"

#: The player and the graph fixture, and the isolation rules (isolation_problem faked in a conftest).
FIXTURES_TEST = """
import os
from pathlib import Path

GOLDEN = Path(__file__).parent / "golden" / "basic_d"


def test_graph_of_its_own(sorting_line_graph):
    assert os.environ["ROS_DOMAIN_ID"] == str(sorting_line_graph.domain_id)
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert sorting_line_graph.namespace.startswith("/sorting_line_test/test_graph_of_its_own_")


def test_player_plays_into_the_tests_namespace(sorting_line_bag_player, sorting_line_graph):
    result = sorting_line_bag_player(GOLDEN, rate=0, topics=["input", "state"], wait_for=[])
    assert result.counts == {f"{sorting_line_graph.namespace}/input": 255, f"{sorting_line_graph.namespace}/state": 255}
"""
FAKE_HOST_NETWORK = """
import sorting_line_gym.testing as plugin

plugin.isolation_problem = lambda: "not in a loopback-only network namespace (interfaces eth9 besides lo)"
"""
WARNING_TEST = """
def test_warns(sorting_line_graph):
    pass
"""


#: A controller that starts later than a reset's first answer is waited for, on an evolving line.
EVOLVING_TEST = """
import subprocess
from pathlib import Path

import sorting_line_gym

UPGRADE = Path(sorting_line_gym.__file__).parent / "evolutions" / "upgrade.yaml"
CONTROLLER = "sorting-line-controller --setup B --variant basic --agent rba"


def test_a_late_controller_plays_the_schedules_first_episode(sorting_line_node):
    line = sorting_line_node(setup="B", variant="basic", evolution=str(UPGRADE), max_steps=20)
    # The sleep is the lateness under test, not a wait: the controller joins after the line has started.
    late = f"sleep 4; exec {CONTROLLER} --ros-args -r __ns:={line.namespace}"
    controller = subprocess.Popen(["sh", "-c", late])
    try:
        states = line.run_episode(7, attempts=10)
    finally:
        controller.terminate()
        controller.wait(10)
    assert states[-1].truncated
    assert {s.episode for s in states} == {1}, "the reset was repeated: the schedule moved on"
"""


def run_pytest(directory: Path, *args: str, timeout: float = 240.0) -> tuple[subprocess.CompletedProcess, dict]:
    """pytest in ``directory`` as a user runs it; returns the process and {"module::test": outcome}."""
    junit = directory / "junit.xml"
    env = dict(os.environ, SORTING_LINE_BIN=str(h.node_binary()))
    # Before setup.sh reinstalled the bridge from this pyproject.toml the entry point is not there yet.
    plugin = [] if _entry_point() else ["-p", PLUGIN]
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-rA", f"--junitxml={junit}", *plugin, *args],
        cwd=directory,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    outcomes = {}
    if junit.is_file():
        for case in ET.parse(junit).getroot().iter("testcase"):
            kinds = [child.tag for child in case if child.tag in ("failure", "error", "skipped")]
            outcomes[f"{case.get('classname')}::{case.get('name')}"] = kinds[0] if kinds else "passed"
    return proc, outcomes


def _entry_point() -> bool:
    return any(ep.value == PLUGIN for ep in importlib.metadata.entry_points(group="pytest11"))


def _user_project(tmp_path: Path) -> Path:
    """A user's directory: the examples, and the golden bag beside them as golden/basic_d."""
    for example in EXAMPLES.glob("test_*.py"):
        shutil.copy(example, tmp_path / example.name)
    shutil.copytree(DATA / "basic_d", tmp_path / "golden" / "basic_d")
    return tmp_path


def test_the_docs_show_the_examples_verbatim():
    doc = DOC.read_text()
    for example in sorted(EXAMPLES.glob("test_*.py")):
        assert f"```python\n{example.read_text()}```" in doc, f"{DOC.name} does not show {example.name} as it is"


def test_the_examples_pass_and_a_changed_controller_fails(tmp_path):
    project = _user_project(tmp_path)
    changed = (project / "test_my_controller.py").read_text().replace('--agent rba"', '--agent rba-hold"')
    (project / "test_changed_controller.py").write_text(changed)
    (project / "test_fixtures.py").write_text(FIXTURES_TEST)
    (project / "conftest.py").write_text(FAKE_HOST_NETWORK)  # the warning, once for the whole run
    proc, outcomes = run_pytest(
        project, "--deselect", "test_changed_controller.py::test_no_worse_than_recorded_in_closed_loop"
    )
    report = proc.stdout[-6000:] + proc.stderr[-2000:]
    assert outcomes == {
        "test_my_controller::test_answers_every_tick_as_recorded": "passed",
        "test_my_controller::test_no_worse_than_recorded_in_closed_loop": "passed",
        "test_record_golden::test_record_a_golden_bag_and_check_it": "passed",
        "test_fixtures::test_graph_of_its_own": "passed",
        "test_fixtures::test_player_plays_into_the_tests_namespace": "passed",
        "test_changed_controller::test_answers_every_tick_as_recorded": "failure",
    }, report
    # The changed controller's failure shows the check's summary: the first difference by tick and field.
    assert "first difference: cmd/speed at tick " in proc.stdout and ", field speed: bag " in proc.stdout, report
    warning = (
        "interfaces eth9 besides lo): the tests' DDS traffic stays on this host only through "
        "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"
    )
    assert proc.stdout.count(warning) == 1, report


def test_outside_a_network_namespace_it_can_skip_instead(tmp_path):
    (tmp_path / "conftest.py").write_text(FAKE_HOST_NETWORK)
    (tmp_path / "test_warning.py").write_text(WARNING_TEST)
    proc, outcomes = run_pytest(tmp_path, "--sorting-line-require-netns", timeout=60)
    assert outcomes == {"test_warning::test_warns": "skipped"}, proc.stdout
    assert "--sorting-line-require-netns: not in a loopback-only network namespace" in proc.stdout, proc.stdout


def test_each_test_gets_a_domain_of_its_own_within_the_range():
    from sorting_line_gym.testing import DOMAINS_PER_SESSION, domain_of_test

    ks = (0, 1, DOMAINS_PER_SESSION - 1, DOMAINS_PER_SESSION)
    assert [domain_of_test(150, k) for k in ks] == [150, 151, 150 + DOMAINS_PER_SESSION - 1, 150]
    assert {domain_of_test(150, k, same=True) for k in range(30)} == {150}
    assert all(100 <= domain_of_test(None, k) <= 199 for k in range(30))
    with pytest.raises(pytest.UsageError, match="--sorting-line-domain 220: the tests' domains 220..239"):
        domain_of_test(220, 0)


def test_pytest_finds_the_plugin_by_its_entry_point():
    assert _entry_point(), (
        f"no pytest11 entry point {PLUGIN!r} in this environment: the bridge was installed "
        "from an older bridge/pyproject.toml; run launch_scripts/setup.sh"
    )


def test_an_evolving_lines_reset_is_never_repeated(tmp_path):
    """run_episode repeats a reset nobody answered (a seeded reset repeated is the same episode),
    but not on an evolving line, where each reset is the schedule's next episode."""
    (tmp_path / "test_evolving_line.py").write_text(EVOLVING_TEST)
    proc, outcomes = run_pytest(tmp_path)
    assert outcomes == {"test_evolving_line::test_a_late_controller_plays_the_schedules_first_episode": "passed"}, (
        proc.stdout[-6000:] + proc.stderr[-2000:]
    )
