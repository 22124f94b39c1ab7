"""The sorting line and a controller under ROS's own integration-test framework (launch_testing):

    launch_test tests/launch/test_line_with_controller.launch.py

A launch description starts the `sorting_line` node (realtime, 10 ticks/s, setup D) and
`sorting-line-controller` in one namespace; while they run, `launch_testing_ros.WaitForTopics`
waits for the line's sensors and state and for the controller's commands, and the states must show
the controller's speeds applied; after shutdown, every process must have exited cleanly.

Where the executables come from (a ROS 2 install would use `launch_ros.actions.Node(package=...)`
for its own packages): the node is $SORTING_LINE_BIN, else `sorting_line` on PATH; the controller is
the command line in $SORTING_LINE_CONTROLLER, else `sorting-line-controller` on PATH. Put your own
controller there to test it the same way. tests/python/test_launch_testing.py runs this file in CI.
"""

import os
import shlex
import shutil
import time
import unittest

import launch
import launch_ros.actions
import launch_testing
import launch_testing.actions
import launch_testing.asserts
import pytest
from launch_testing_ros import WaitForTopics
from sorting_line_interfaces.msg import BeltOccupancy, LineState, MaterialInput, SpeedCommand

NAMESPACE = "/launch_test_line"
SPEEDS = {round(0.1 * k, 1) for k in range(1, 11)}


def _executable(variable: str, default: str) -> list[str]:
    command = shlex.split(os.environ.get(variable, "")) or [shutil.which(default) or default]
    return command


def _seconds(stamp) -> int:
    return stamp.sec  # one tick = 1 simulated second (the node's default tick_period)


@pytest.mark.launch_test
def generate_test_description():
    node = launch_ros.actions.Node(
        executable=_executable("SORTING_LINE_BIN", "sorting_line")[0],
        name="sorting_line",
        namespace=NAMESPACE,
        arguments=["node", "--mode", "realtime", "--rate", "10", "--setup", "D", "--seed", "5"],
        output="screen",
        sigterm_timeout="10",
    )
    controller_command = _executable("SORTING_LINE_CONTROLLER", "sorting-line-controller")
    controller = launch.actions.ExecuteProcess(
        cmd=[*controller_command, "--setup", "D", "--variant", "basic", "--ros-args", "-r", f"__ns:={NAMESPACE}"],
        name="controller",
        output="screen",
        sigterm_timeout="10",
    )
    description = launch.LaunchDescription([node, controller, launch_testing.actions.ReadyToTest()])
    return description, {"node": node, "controller": controller}


class TestTheLineRuns(unittest.TestCase):
    def test_sensors_state_and_commands_flow(self):
        topics = [
            (f"{NAMESPACE}/input", MaterialInput),
            (f"{NAMESPACE}/belt/occupancy", BeltOccupancy),
            (f"{NAMESPACE}/state", LineState),
            (f"{NAMESPACE}/cmd/speed", SpeedCommand),
        ]
        with WaitForTopics(topics, timeout=60.0, messages_received_buffer_length=50) as wait:
            commands = wait.received_messages(f"{NAMESPACE}/cmd/speed")
            self.assertTrue(all(round(c.speed, 1) in SPEEDS for c in commands), [c.speed for c in commands])

    def test_the_controllers_speeds_are_applied(self):
        # The controller answers the readings of tick T with a speed stamped T; the node applies it
        # in its next step, or a later one if the answer came late (a busy machine), and the state
        # says so. The controller changes speeds often (rule-based, seasonal input): seen applied,
        # they cannot be the node's own.
        state, command = f"{NAMESPACE}/state", f"{NAMESPACE}/cmd/speed"
        with WaitForTopics(
            [(state, LineState), (command, SpeedCommand)], timeout=60.0, messages_received_buffer_length=200
        ) as wait:
            time.sleep(3.0)  # ~30 ticks at 10 ticks/s
            states, commands = wait.received_messages(state), wait.received_messages(command)
        sent = {_seconds(c.header.stamp): round(c.speed, 1) for c in commands}
        applied = {
            round(s.speed, 1)
            for s in states
            if round(s.speed, 1) in [sent.get(_seconds(s.header.stamp) - k) for k in (1, 2, 3)]
        }
        seen = [(_seconds(s.header.stamp), round(s.speed, 1)) for s in states][:20]
        self.assertGreater(
            len(applied), 1, f"speeds applied {applied}; sent {sorted(sent.items())[:20]}; states (stamp, speed) {seen}"
        )

    def test_the_node_says_it_is_up(self, proc_output, node):
        proc_output.assertWaitFor("up on ROS_DOMAIN_ID", process=node, timeout=30, stream="stderr")


@launch_testing.post_shutdown_test()
class TestCleanExit(unittest.TestCase):
    def test_every_process_exits_cleanly(self, proc_info):
        # Both stop on SIGINT with exit code 0 (launch sends it at the end of the test).
        launch_testing.asserts.assertExitCodes(proc_info, allowable_exit_codes=[launch_testing.asserts.EXIT_OK])
