"""The launch_testing example (tests/launch/test_line_with_controller.launch.py) under `launch_test`,
the runner of ROS's own integration-test framework, from the ros2 CLI venv (tests/python/support/ros2_cli.py;
`launch_test` beside its `ros2`, as after sourcing launch_scripts/ros2cli.sh's env.sh), so that test.sh
runs it: the node and `sorting-line-controller` started by a launch description, WaitForTopics on their topics, and the
post-shutdown exit-code check, all passing, as the JUnit file launch_test writes says.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
import xml.etree.ElementTree as ET

from support import ros_harness as h

EXAMPLE = h.ROOT / "tests" / "launch" / "test_line_with_controller.launch.py"
#: What the example checks: three tests while it runs, one after shutdown.
TESTS = {
    "test_sensors_state_and_commands_flow",
    "test_the_controllers_speeds_are_applied",
    "test_the_node_says_it_is_up",
    "test_every_process_exits_cleanly",
}


def test_launch_test_runs_the_line_with_a_controller(ros2, tmp_path):
    launch_test = shutil.which("launch_test", path=ros2.env["PATH"])
    assert launch_test, f"no launch_test beside {ros2.executable} ({ros2.origin})"
    # The controller runs on the project's interpreter, without the CLI venv's library paths.
    controller = [
        "env",
        "-u",
        "PYTHONPATH",
        "-u",
        "LD_LIBRARY_PATH",
        "-u",
        "AMENT_PREFIX_PATH",
        "-u",
        "VIRTUAL_ENV",
        "-u",
        "_ROS_WHEELS_BOOTSTRAP_COMPLETE",
        str(h.ROOT / ".venv" / "bin" / "sorting-line-controller"),
    ]
    env = dict(ros2.env, SORTING_LINE_BIN=str(h.node_binary()), SORTING_LINE_CONTROLLER=shlex.join(controller))
    junit = tmp_path / "launch_test.xml"
    run = subprocess.run(
        [launch_test, str(EXAMPLE), "--junit-xml", str(junit)],
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
        stdin=subprocess.DEVNULL,
    )
    output = f"--- stdout ---\n{_results(run.stdout)}\n--- stderr ---\n{_results(run.stderr)}"
    assert run.returncode == 0, f"launch_test exited with {run.returncode}\n{output}"
    cases = {c.get("name"): [x.tag for x in c] for c in ET.parse(junit).getroot().iter("testcase")}
    assert set(cases) == TESTS and not any(cases.values()), f"{cases}\n{output}"


def _results(text: str, keep: int = 6000) -> str:
    """launch_test's own lines (the test results), without the processes' log lines around them."""
    own = [line for line in text.splitlines() if not line.startswith(("[sorting_line-", "[controller-"))]
    return "\n".join(own)[-keep:]
