"""The node as a standard simulator: ROS 2's simulation_interfaces services in its private namespace
(`<ns>/sorting_line/get_simulator_features`, `get_simulation_state`, `set_simulation_state`,
`step_simulation`, `reset_simulation`) and the SimulateSteps action (`simulate_steps`), driven by
real rclpy clients built against the interface package (msg/simulation_interfaces, compiled by
setup.sh) and by the real `ros2` CLI.

The line is driven through the standard services only, and every state it publishes is compared
with `sorting_line trace` for its seed: StepSimulation runs ticks on the held command (the start
speed here, since nobody commands), a line at its time limit starts a new episode as in realtime,
SCOPE_STATE restarts the seed's streams, SCOPE_DEFAULT also rewinds the stamps to 0, PLAYING ticks
at `--rate`. Every result code the node answers with is provoked on its cause, and the refusals are
counted on /diagnostics.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys

import pytest

from sorting_line_gym.line.process import with_parent_death_signal
from sorting_line_gym.line.vocabulary import START_SPEED_INDEX  # held each episode until commanded
from support import ros_harness as h
from support.ros_harness import show_ns, stamp_ns
from support.waits import wait_until

SETUP, VARIANT, SEED, RATE = "B", "basic", 13, 40.0
FEATURES = [20, 21, 22, 24, 25, 26, 31, 32, 33]  # reset (time, state), state get/set/pause, step single/multiple/action
SERVICES = {
    "get_simulator_features": "simulation_interfaces/srv/GetSimulatorFeatures",
    "get_simulation_state": "simulation_interfaces/srv/GetSimulationState",
    "set_simulation_state": "simulation_interfaces/srv/SetSimulationState",
    "step_simulation": "simulation_interfaces/srv/StepSimulation",
    "reset_simulation": "simulation_interfaces/srv/ResetSimulation",
}


class Simulator:
    """rclpy clients of the five services of one node, and its line's `state` and /diagnostics."""

    def __init__(self, ros, ns: str, node_proc: h.NodeProcess):
        from diagnostic_msgs.msg import DiagnosticArray
        from simulation_interfaces import srv
        from sorting_line_interfaces.msg import LineState, SpeedCommand

        self.ros, self.ns, self.proc = ros, ns, node_proc
        self.fqn = h.join_ns(ns, "sorting_line")
        self.node = ros.make_node("simif_client")
        self.types = {name: getattr(srv, t.rsplit("/", 1)[1]) for name, t in SERVICES.items()}
        self.clients = {name: self.node.create_client(t, f"{self.fqn}/{name}") for name, t in self.types.items()}
        # Deep enough for a 50-tick burst of StepSimulation.
        self.states = h.TopicRecorder(ros, self.node, h.join_ns(ns, "state"), LineState, qos=200)
        self.diag = h.TopicRecorder(ros, self.node, "/diagnostics", DiagnosticArray)
        self.speed_pub = self.node.create_publisher(SpeedCommand, h.join_ns(ns, "cmd/speed"), 10)
        self.SpeedCommand = SpeedCommand

    def context(self) -> str:
        last = [(show_ns(stamp_ns(s.header.stamp)), s.episode, s.step) for s in self.states.msgs[-3:]]
        return f"{len(self.states.msgs)} states received, last {last}\n{self.proc.describe()}"

    def gone(self):
        return None if self.proc.running() else f"the node exited with {self.proc.proc.returncode}"

    def call(self, name: str, timeout: float = 10.0, **fields):
        """One call (never retried: steps and resets are not idempotent), after the service is ready
        and /diagnostics shows that the node has discovered us (see ros_harness, the volatile-reply trap)."""
        client = self.clients[name]
        self.ros.spin_until(client.service_is_ready, 10.0, f"{self.fqn}/{name}", self.context, abort=self.gone)
        self.ros.spin_until(lambda: self.diag.msgs, 10.0, "/diagnostics from the node", self.context, abort=self.gone)
        request = self.types[name].Request(**fields)
        return self.ros.wait_future(
            client.call_async(request), timeout, f"the reply of {name} {fields}", self.context, abort=self.gone
        )

    def result(self, name: str, **fields) -> tuple[int, str]:
        r = self.call(name, **fields).result
        return r.result, r.error_message

    def state(self) -> int:
        reply = self.call("get_simulation_state")
        assert reply.result.result == OK, reply
        return reply.state.state

    def set_state(self, state: int) -> tuple[int, str]:
        from simulation_interfaces.msg import SimulationState

        return self.result("set_simulation_state", state=SimulationState(state=state))

    def states_after(self, stamp: int, count: int, timeout: float = 10.0) -> list:
        """The first `count` states stamped after `stamp` (ns), in order (waits for them)."""

        def enough():
            later = [s for s in self.states.msgs if stamp_ns(s.header.stamp) > stamp]
            return later[:count] if len(later) >= count else None

        return self.ros.spin_until(
            enough, timeout, f"{count} states after {show_ns(stamp)}", self.context, abort=self.gone
        )

    def last_stamp(self) -> int:
        return stamp_ns(self.states.msgs[-1].header.stamp)

    def destroy(self) -> None:
        self.ros.destroy_node(self.node)


# simulation_interfaces/msg/Result and SetSimulationState codes; SimulationState values.
FEATURE_UNSUPPORTED, OK, INCORRECT_STATE, ALREADY_IN_TARGET_STATE = 0, 1, 3, 101
STOPPED, PLAYING, PAUSED, QUITTING, NO_WORLD = 0, 1, 2, 3, 4
SCOPE_DEFAULT, SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED = 0, 1, 2, 4


def expected_views(tokens: list) -> list[dict]:
    """`sorting_line trace` for the seed and these actions ('r' = a new episode), as state views
    (the first entry, the initial reset, left out)."""
    views = []
    for entry in h.run_trace(SETUP, VARIANT, SEED, tokens)[1:]:
        views.append(("reset", h.trace_reset_view(entry)) if "reset" in entry else ("step", h.trace_step_view(entry)))
    return views


def state_views(states: list) -> list:
    return [("reset", h.state_reset_view(s)) if s.step == 0 else ("step", h.state_step_view(s)) for s in states]


def assert_trajectory(states: list, tokens: list, what: str) -> None:
    got, want = state_views(states), expected_views(tokens)
    for i, (g, w) in enumerate(zip(got, want, strict=False)):
        assert g == w, f"{what}: tick {i + 1} differs from `sorting_line trace --seed {SEED}`:\nnode  {g}\ntrace {w}"
    assert len(got) == len(want), (len(got), len(want))


@pytest.fixture
def simulator(ros, start_node, namespace):
    ns = namespace("simif")
    proc = start_node(
        "--setup",
        SETUP,
        "--variant",
        VARIANT,
        "--seed",
        str(SEED),
        "--rate",
        str(RATE),
        "--ros-args",
        "-r",
        f"__ns:={ns}",
    )
    sim = Simulator(ros, ns, proc)
    yield sim
    sim.destroy()


def wait_diag(sim, hardware_id: str, want: dict[str, str]) -> dict[str, str]:
    """The first /diagnostics status of `hardware_id` (1 Hz) with the values `want`."""

    def matches(array):
        values = h.diagnostic_values(array, hardware_id)
        return values is not None and all(values.get(k) == v for k, v in want.items())

    array = sim.diag.wait_for(
        matches, 5.0, f"{hardware_id} with {want}", lambda: str(h.diagnostic_values(sim.diag.msgs[-1], hardware_id))
    )
    return h.diagnostic_values(array, hardware_id)


def check_stepping_and_state_resets(sim, held: int) -> None:
    """Features, PAUSED at start, StepSimulation over an episode's end, reset of the state only,
    and an unsupported scope."""
    assert sim.call("get_simulator_features").features.features.tolist() == FEATURES
    assert sim.state() == PAUSED, "--mode lockstep starts PAUSED"
    code, message = sim.set_state(PAUSED)
    assert (code, message) == (ALREADY_IN_TARGET_STATE, "the simulation is already PAUSED")

    # Step 50: a whole episode on the held command, replied to once the 50 ticks are done.
    # The line waits at tick 0 (its start-up state went out before we matched).
    sim.ros.spin_until(lambda: sim.states.sub.get_publisher_count() >= 1, 10.0, "state to match", sim.context)
    t0 = 0
    assert sim.result("step_simulation", steps=50) == (OK, "")
    first = sim.states_after(t0, 50)
    assert_trajectory(first, [held] * 50, "step 50")
    assert first[-1].truncated
    # At its time limit the line starts a new episode, as it does when PLAYING (trace's 'r').
    assert sim.result("step_simulation", steps=3) == (OK, "")
    assert_trajectory(sim.states_after(t0, 53), [held] * 50 + ["r", held, held], "step 50, step 3")

    # SCOPE_STATE: the line as it was built (episode 0, the seed's streams), time runs on.
    t1 = sim.last_stamp()
    assert sim.result("reset_simulation", scope=SCOPE_STATE) == (OK, "")
    [restart] = sim.states_after(t1, 1)
    assert (restart.episode, restart.step, restart.seed) == (0, 0, SEED)
    assert sim.result("step_simulation", steps=50) == (OK, "")
    assert_trajectory(sim.states_after(stamp_ns(restart.header.stamp), 50), [held] * 50, "reset STATE, step 50")

    # An unsupported scope changes nothing.
    code, message = sim.result("reset_simulation", scope=SCOPE_SPAWNED)
    assert code == FEATURE_UNSUPPORTED and "SPAWNED" in message, message


def check_full_reset_and_playing(sim, held: int) -> None:
    """A reset of state and time (the stamps start at 0 again), then PLAYING in realtime with
    StepSimulation refused, and PAUSED stops the ticks."""
    # SCOPE_DEFAULT (= ALL): state and time; the stamps start again at 0.
    count = len(sim.states.msgs)
    assert sim.result("reset_simulation", scope=SCOPE_DEFAULT) == (OK, "")
    sim.ros.spin_until(lambda: len(sim.states.msgs) > count, 5.0, "the state after the reset", sim.context)
    rewound = sim.states.msgs[count]
    assert (stamp_ns(rewound.header.stamp), rewound.episode, rewound.step) == (0, 0, 0)

    # PLAYING: realtime at --rate on the held command; StepSimulation is refused meanwhile.
    assert sim.set_state(PLAYING) == (OK, "")
    assert sim.state() == PLAYING
    code, message = sim.result("step_simulation", steps=1)
    assert code == INCORRECT_STATE and "PLAYING" in message, message
    sim.ros.spin_until(lambda: len(sim.states.msgs) >= count + 15, 10.0, "15 realtime ticks", sim.context)
    assert sim.set_state(PAUSED) == (OK, "")
    sim.ros.spin_for(0.3)  # ticks published before the pause may still be on their way
    played = sim.states.msgs[count + 1 :]
    sim.ros.spin_for(3 / RATE + 0.2)
    assert len(sim.states.msgs) == count + 1 + len(played), "ticks after PAUSED"
    tokens = [held] * len(played) if len(played) <= 50 else [held] * 50 + ["r"] + [held] * (len(played) - 51)
    assert_trajectory(played, tokens, f"{len(played)} ticks PLAYING")
    assert [stamp_ns(s.header.stamp) for s in played] == [k * h.NS_PER_S for k in range(1, len(played) + 1)]


def check_stopped(sim) -> None:
    """STOPPED: reset (time and state), no ticks, commands rejected and counted; PAUSED starts it again."""
    count = len(sim.states.msgs)
    assert sim.set_state(STOPPED) == (OK, "")
    assert sim.state() == STOPPED
    sim.ros.spin_until(lambda: len(sim.states.msgs) > count, 5.0, "the state after stopping", sim.context)
    stopped = sim.states.msgs[count]
    assert (stamp_ns(stopped.header.stamp), stopped.episode, stopped.step) == (0, 0, 0)
    code, message = sim.result("step_simulation", steps=1)
    assert code == INCORRECT_STATE and "STOPPED" in message, message
    sim.ros.spin_until(lambda: sim.speed_pub.get_subscription_count() >= 1, 5.0, "cmd/speed to match", sim.context)
    sim.speed_pub.publish(sim.SpeedCommand(speed=0.3))  # stamp 0: the stopped line's tick
    wait_diag(sim, sim.ns, {"rejected_stopped": "1"})
    assert sim.set_state(PAUSED) == (OK, "") and sim.state() == PAUSED
    assert len(sim.states.msgs) == count + 1, "a stopped line does not tick"


def check_refused_while_stepping(sim) -> None:
    """A step in progress: every other change is refused until it has replied."""
    from simulation_interfaces.msg import SimulationState

    big = sim.clients["step_simulation"].call_async(sim.types["step_simulation"].Request(steps=5000))
    busy_step = sim.clients["step_simulation"].call_async(sim.types["step_simulation"].Request(steps=1))
    busy_play = sim.clients["set_simulation_state"].call_async(
        sim.types["set_simulation_state"].Request(state=SimulationState(state=PLAYING))
    )
    for future, what in ((busy_step, "step"), (busy_play, "play")):
        reply = sim.ros.wait_future(future, 10.0, f"the {what} during a step", sim.context, abort=sim.gone)
        assert reply.result.result == INCORRECT_STATE, reply
        assert "StepSimulation of 5000 steps is in progress" in reply.result.error_message, reply
    assert sim.ros.wait_future(big, 30.0, "5000 steps", sim.context, abort=sim.gone).result.result == OK


def test_standard_services_drive_the_line_as_trace_does(simulator):
    sim = simulator
    held = START_SPEED_INDEX
    check_stepping_and_state_resets(sim, held)
    check_full_reset_and_playing(sim, held)
    check_stopped(sim)

    # Unknown or unsupported states.
    for target in (NO_WORLD, 9):
        code, message = sim.set_state(target)
        assert code == FEATURE_UNSUPPORTED and message.startswith(f"state {target} "), message
    assert sim.result("step_simulation", steps=0) == (OK, "")

    check_refused_while_stepping(sim)

    # /diagnostics counts the refusals per result code, and the stopped line's rejected command.
    refused = dict(refused_incorrect_state="4", refused_feature_unsupported="3", refused_already_in_target_state="1")
    done = dict(requests_refused="8", step_in_progress="none", steps_stepped=str(50 + 3 + 50 + 5000))
    wait_diag(sim, sim.fqn, {"simulation_state": "PAUSED", **refused, **done})
    wait_diag(sim, sim.ns, {"rejected_stopped": "1", "mode": "lockstep", "commands_rejected": "1"})

    # QUITTING: replies, then the node leaves as on SIGINT (exit code 0).
    assert sim.set_state(QUITTING) == (OK, "")
    sim.proc.proc.wait(timeout=10)
    assert sim.proc.proc.returncode == 0, sim.proc.describe()
    sim.proc.stopped_by_test = True
    assert "simulation QUITTING" in sim.proc.log()
    assert "QUITTING reply may be lost" not in sim.proc.log(), "our reader acknowledges at once"


# A second client of set_simulation_state, in a process of its own: asks for PAUSED (already there)
# until answered, which proves that the node's reply writer has matched its reader, then idles.
SECOND_CLIENT = """
import sys, time
import rclpy
from simulation_interfaces.msg import SimulationState
from simulation_interfaces.srv import SetSimulationState
rclpy.init()
node = rclpy.create_node("second_simif_client")
client = node.create_client(SetSimulationState, sys.argv[1])
client.wait_for_service(timeout_sec=30)
for attempt in range(10):
    future = client.call_async(SetSimulationState.Request(state=SimulationState(state=2)))
    rclpy.spin_until_future_complete(node, future, timeout_sec=3)
    if future.done():
        print("answered", future.result().result.result, flush=True)
        break
time.sleep(600)  # idles as a reader of the reply, not a wait: the test stops it (SIGSTOP) and kills it
"""


def test_quitting_waits_for_every_reader_of_its_reply_then_leaves_anyway(simulator, tmp_path):
    """QUITTING leaves once every reader of its reply has acknowledged it (a reply still in flight
    would be lost with the participant), or after 2 s without: a second client, stopped (SIGSTOP),
    never acknowledges, so the node says so in its log and still leaves with 0."""
    sim = simulator
    log = tmp_path / "second_client.log"
    with open(log, "wb") as out:
        second = subprocess.Popen(
            with_parent_death_signal([sys.executable, "-c", SECOND_CLIENT, f"{sim.fqn}/set_simulation_state"]),
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        answered = f"answered {ALREADY_IN_TARGET_STATE}"
        sim.ros.spin_until(
            lambda: answered in log.read_text(), 60.0, f"the second client's reply ({log})", lambda: log.read_text()
        )
        second.send_signal(signal.SIGSTOP)
        assert sim.set_state(QUITTING) == (OK, "")
        sim.proc.proc.wait(timeout=20)
    finally:
        second.kill()
        second.wait(timeout=10)
    assert sim.proc.proc.returncode == 0, sim.proc.describe()
    sim.proc.stopped_by_test = True
    assert "the QUITTING reply may be lost: not acknowledged within 2 s" in sim.proc.log(), sim.proc.describe()


def matched_simulate_steps_client(sim):
    """An action client of the node's simulate_steps, once the node has matched it: the server is
    ready, a /diagnostics array came after the client's endpoints existed (the node was discovering
    them meanwhile: a reply written before it matched our reader would be lost, ros_harness), and
    the volatile feedback has a reader before the first goal."""
    from rclpy.action import ActionClient
    from simulation_interfaces.action import SimulateSteps

    client = ActionClient(sim.node, SimulateSteps, f"{sim.fqn}/simulate_steps")
    created = len(sim.diag.msgs)
    sim.ros.spin_until(client.server_is_ready, 10.0, "the simulate_steps action server", sim.context, abort=sim.gone)
    sim.ros.spin_until(lambda: sim.states.sub.get_publisher_count() >= 1, 10.0, "state to match", sim.context)
    sim.ros.spin_until(
        lambda: len(sim.diag.msgs) > created + 1,
        10.0,
        "/diagnostics after the action client",
        sim.context,
        abort=sim.gone,
    )
    feedback_topic = f"{sim.fqn}/simulate_steps/_action/feedback"
    sim.ros.spin_until(lambda: sim.node.count_publishers(feedback_topic) >= 1, 10.0, feedback_topic, sim.context)
    return client


def test_simulate_steps_action_feedback_refusal_and_cancel(simulator):
    """SimulateSteps: N steps with feedback, the same trajectory as StepSimulation; refused (aborted,
    the reason in the result) while PLAYING; canceled after the step in progress."""
    from action_msgs.msg import GoalStatus
    from simulation_interfaces.action import SimulateSteps

    sim = simulator
    client = matched_simulate_steps_client(sim)

    def run(steps: int, feedback: list, timeout: float = 10.0):
        goal = sim.ros.wait_future(
            client.send_goal_async(SimulateSteps.Goal(steps=steps), feedback_callback=feedback.append),
            timeout,
            f"the goal of {steps} steps accepted",
            sim.context,
            abort=sim.gone,
        )
        assert goal.accepted, "a goal is accepted, and ends with the reason if refused"
        return goal

    feedback: list = []
    goal = run(20, feedback)
    done = sim.ros.wait_future(goal.get_result_async(), 10.0, "the result of 20 steps", sim.context, abort=sim.gone)
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.result.result == OK, done
    assert_trajectory(sim.states_after(0, 20), [START_SPEED_INDEX] * 20, "SimulateSteps 20")
    # Feedback is throttled (at most one per 10 ms); rclpy keeps the last 10 of a burst and drops a goal's feedback
    # once its result is in, so only what arrived is checked here: each one consistent, in order
    # (the long goal below waits for its feedback).
    got = [(f.feedback.completed_steps, f.feedback.remaining_steps) for f in feedback]
    assert all(c + r == 20 and 1 <= c <= 20 for c, r in got), got
    assert [c for c, _ in got] == sorted(set(c for c, _ in got)), got

    assert sim.set_state(PLAYING) == (OK, "")
    refused = sim.ros.wait_future(run(5, []).get_result_async(), 10.0, "the refused goal's result", sim.context)
    assert refused.status == GoalStatus.STATUS_ABORTED, refused
    assert refused.result.result.result == INCORRECT_STATE and "PLAYING" in refused.result.result.error_message
    assert sim.set_state(PAUSED) == (OK, "")

    feedback = []
    goal = run(10**9, feedback)
    sim.ros.spin_until(lambda: len(feedback) >= 3, 10.0, "feedback of the long goal", sim.context)
    got = [(f.feedback.completed_steps, f.feedback.remaining_steps) for f in feedback]
    assert all(c + r == 10**9 for c, r in got) and [c for c, _ in got] == sorted(set(c for c, _ in got)), got
    sim.ros.wait_future(goal.cancel_goal_async(), 10.0, "the cancel's answer", sim.context, abort=sim.gone)
    canceled = sim.ros.wait_future(goal.get_result_async(), 10.0, "the canceled goal's result", sim.context)
    assert canceled.status == GoalStatus.STATUS_CANCELED, canceled
    assert re.fullmatch(r"canceled after \d+ of 1000000000 steps", canceled.result.result.error_message), canceled
    assert sim.state() == PAUSED and sim.result("step_simulation", steps=1) == (OK, ""), "the job has ended"
    client.destroy()


def test_ros2_cli_lists_and_calls_the_standard_services(ros2_daemon, start_node, namespace):
    """`ros2 service list -t` and `ros2 action list -t` show the standard types; `ros2 service call`
    works on them, QUITTING (the node leaves) last."""
    ros2 = ros2_daemon
    ns = namespace("simif_cli")
    node = start_node("--setup", SETUP, "--seed", str(SEED), "--ros-args", "-r", f"__ns:={ns}")
    fqn = h.join_ns(ns, "sorting_line")
    want = {f"{fqn}/{name}": f"[{t}]" for name, t in SERVICES.items()}
    last = {"out": ""}

    def services_listed() -> bool:
        last["out"] = out = ros2.run("service", "list", "-t", timeout=20, check=False).stdout
        listed = dict(line.split(" ", 1) for line in out.splitlines() if " " in line)
        return all(listed.get(k) == v for k, v in want.items())

    wait_until(
        services_listed,
        20,
        "`ros2 service list -t` to show the standard services with their types",
        poll=0.5,
        context=lambda: f"want {want}\nlast answer:\n{last['out']}",
    )
    actions = ros2.run("action", "list", "-t", timeout=20).stdout
    assert f"{fqn}/simulate_steps [simulation_interfaces/action/SimulateSteps]" in actions.splitlines(), actions

    def call(name: str, request: str = "{}") -> str:
        return ros2.run("service", "call", f"{fqn}/{name}", SERVICES[name], request, timeout=40).stdout

    assert re.search(
        r"SimulationState\(state=2\), result=simulation_interfaces\.msg\.Result\(result=1,",
        call("get_simulation_state"),
    ), "PAUSED"
    assert "result=simulation_interfaces.msg.Result(result=1, error_message='')" in call(
        "step_simulation", "{steps: 5}"
    )
    out = call("reset_simulation", "{scope: 4}")
    assert "result=0, error_message='scope 4 is not supported" in out, out

    # QUITTING from a client that is not ours: the CLI gets its reply, then the node leaves as on
    # SIGINT, without the warning that the reply may be lost (the CLI's reader acknowledged it).
    out = call("set_simulation_state", f"{{state: {{state: {QUITTING}}}}}")
    assert "result=simulation_interfaces.msg.Result(result=1, error_message='')" in out, out
    node.proc.wait(timeout=10)  # on its own: a SIGINT here would hide a node that did not quit
    node.stopped_by_test = True
    assert node.proc.returncode == 0, node.describe()
    assert "simulation QUITTING" in node.log(), node.describe()
    assert "QUITTING reply may be lost" not in node.log(), node.describe()
