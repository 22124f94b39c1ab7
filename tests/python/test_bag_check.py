"""`sorting-line-bag check`: a controller tested against the golden bags (tests/data/bags), with the
real `sorting-line-controller` (and a small scripted controller, scripted_controller.py, that
answers as a bag recorded except where told to misbehave) over real rclpy and DDS.

Runs inside the loopback-only network namespace that launch_scripts/test.sh makes. Cost: about
60 s on a busy 2-core machine (each check starts a controller process, ~2-4 s; closed loop a node too).

What is checked:
- `sorting-line-controller` passes against both golden bags, open loop (the command line: exit 0,
  a JUnit file that parses) and closed loop;
- a changed controller fails, the message naming tick and field: rba instead of rba-hold, and a
  script that sends one wrong speed at a known tick;
- missing answers (reported per tick, the run goes on), a wrong stamp and an out-of-range speed
  (differences with the node's reason), a controller that crashes (exit 3, its code and stderr),
  no controller at all (exit 3 after --wait), and bad bags (exit 2, each with its message).
"""

from __future__ import annotations

import json
import shlex
import shutil
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from sorting_line_gym.bag import open_bag
from sorting_line_gym.bag.check.checker import check_controller
from sorting_line_gym.bag.format.description import META_KEY
from sorting_line_gym.bag.storage.schema import typestore
from sorting_line_gym.bag.storage.writer import BagWriter
from support.bag_golden import DATA, GOLDEN, BagProcess

SCRIPT = Path(__file__).parent / "support" / "scripted_controller.py"


pytestmark = pytest.mark.usefixtures("same_binary")  # conftest: the tools start the tests' binary


def our_controller(name: str, agent: str | None = None) -> str:
    spec = GOLDEN[name]
    script = Path(sys.executable).parent / "sorting-line-controller"
    return shlex.join(
        [str(script), "--setup", spec["setup"], "--variant", spec["variant"], "--agent", agent or spec["agent"]]
    )


def scripted(name: str, *misbehaviour: str) -> list[str]:
    return [sys.executable, str(SCRIPT), "--bag", str(DATA / name), *misbehaviour]


# --------------------------------------------------------------------------------------------
# Passing


def test_our_controller_passes_open_loop_on_the_command_line(namespace, tmp_path):
    """basic_d through the console script: exit 0, the summary, JSON and a JUnit file that parses.
    The controller is told another namespace: the remap the check appends wins, as for any ROS node."""
    cmd = our_controller("basic_d") + " --namespace /somewhere_else"
    tool = BagProcess(
        [
            "check",
            DATA / "basic_d",
            "--namespace",
            namespace("cli"),
            "--controller",
            cmd,
            "--json",
            tmp_path / "v.json",
            "--junit",
            tmp_path / "v.xml",
        ],
        tmp_path / "check.log",
    )
    assert tool.wait(120) == 0, tool.describe()
    assert "255 matching, 0 differing, 0 missing" in tool.log() and "PASSED" in tool.log(), tool.log()
    data = json.loads((tmp_path / "v.json").read_text())
    assert data["passed"] and data["answers"]["matching"] == 255 and data["latency_ms"]["count"] == 255
    suite = ET.parse(tmp_path / "v.xml").getroot().find("testsuite")
    names = [c.get("name") for c in suite.findall("testcase")]
    assert names == [f"episode {k}" for k in range(1, 6)] + ["missing or late answers"], names
    assert suite.get("failures") == "0" and suite.get("errors") == "0"


def test_our_controller_already_running_passes_open_and_closed_loop_on_the_advanced_line(namespace, tmp_path):
    """Without --controller: one controller, started as a user would, checked open loop and then
    closed loop in its namespace (it starts over when the closed loop's fresh node begins)."""
    from support.controller_process import ControllerProcess

    spec, ns = GOLDEN["advanced_b"], namespace("adv")
    controller = ControllerProcess(
        tmp_path,
        "adv",
        ["--setup", spec["setup"], "--variant", spec["variant"], "--agent", spec["agent"], "--namespace", ns],
    )
    try:
        verdict = check_controller(DATA / "advanced_b", namespace=ns, wait=30)
        assert verdict.passed, verdict.summary()
        # both commands of every tick: a sort mode and a speed
        assert verdict.count("matching") == 510 and verdict.exit_code == 0, verdict.summary()
        assert ET.fromstring(verdict.to_junit()).find("testsuite").get("tests") == "6"
        closed = check_controller(DATA / "advanced_b", namespace=ns, closed_loop=True)
        assert closed.passed and len(closed.episodes) == 5, closed.summary()
        assert all(e.parted is None for e in closed.episodes), closed.summary()
    finally:
        assert controller.stop() == 0, controller.describe()


# --------------------------------------------------------------------------------------------
# A changed controller


def test_rba_instead_of_rba_hold_fails_naming_tick_and_field_open_and_closed_loop(namespace, tmp_path):
    """One controller running rba where the bag was recorded with rba-hold, checked both ways."""
    from support.controller_process import ControllerProcess

    spec, ns = GOLDEN["advanced_b"], namespace("rba")
    controller = ControllerProcess(
        tmp_path, "rba", ["--setup", spec["setup"], "--variant", spec["variant"], "--agent", "rba", "--namespace", ns]
    )
    try:
        verdict = check_controller(DATA / "advanced_b", namespace=ns, wait=30)
        closed = check_controller(DATA / "advanced_b", namespace=ns, closed_loop=True)
    finally:
        assert controller.stop() == 0, controller.describe()
    assert verdict.exit_code == 1, verdict.summary()
    first = verdict.first_difference
    assert (first.tick, first.topic, first.field) == (3, "cmd/speed", "speed"), verdict.summary()
    assert (
        "first difference: cmd/speed at tick 3 (stamp 3.000000000 s, episode 1 step 2), field speed: bag 0.8, "
        "controller 0.9" in verdict.summary()
    ), verdict.summary()
    junit = ET.fromstring(verdict.to_junit()).find("testsuite")
    assert junit.find("testcase[@name='episode 1']/failure") is not None

    assert closed.exit_code == 1, closed.summary()
    episode = closed.episodes[0]
    assert episode.parted.startswith("tick 4 (stamp 4.000000000 s, step 3), field speed: bag 0.8, run 0.9"), (
        episode.parted
    )
    assert episode.run.reward < episode.bag.reward and "reward" in episode.failures[0], closed.summary()
    # The tolerances decide: the same episodes pass within loose ones (rba loses up to ~30% here).
    from sorting_line_gym.bag.check.verdict import Tolerance

    loose = {
        "reward": Tolerance.parse("35%", "r"),
        "accuracy": Tolerance.parse("0.01", "a"),
        "purity": Tolerance.parse("1%", "p"),
    }
    for e in closed.episodes:
        e.failures.clear()
        e.judge(loose)
    assert all(e.passed for e in closed.episodes), [e.describe() for e in closed.episodes]


def test_one_wrong_speed_at_a_known_tick(namespace):
    verdict = check_controller(
        DATA / "basic_d", namespace=namespace("one"), controller=scripted("basic_d", "--speed-at", "60=0.2")
    )
    assert verdict.exit_code == 1, verdict.summary()
    assert [(d.tick, d.field, d.recorded, d.answered) for d in verdict.differences] == [(60, "speed", 0.8, 0.2)], (
        verdict.summary()
    )
    assert verdict.count("matching") == 254 and verdict.count("missing") == 0, verdict.summary()
    assert (
        "cmd/speed at tick 60 (stamp 60.000000000 s, episode 2 step 8), field speed: bag 0.8, controller 0.2"
        in verdict.summary()
    )


# --------------------------------------------------------------------------------------------
# Answers the node would refuse, missing answers, a crash, no controller


def test_missing_answers_wrong_stamp_and_bad_speed_are_reported_and_the_run_goes_on(namespace):
    """A controller answering on batch/cmd (entry 0), as a vectorised one would."""
    verdict = check_controller(
        DATA / "basic_d",
        namespace=namespace("bad"),
        answer_timeout=0.5,
        controller=scripted(
            "basic_d", "--batch", "--skip", "10", "--skip", "11", "--stamp-shift-at", "30=0.5", "--speed-at", "40=1.5"
        ),
    )
    assert verdict.exit_code == 1, verdict.summary()
    missing = [a.tick for a in verdict.answers if a.status == "missing"]
    assert missing == [10, 11], verdict.summary()
    by_tick = {d.tick: d for d in verdict.differences}
    assert set(by_tick) == {30, 40}, verdict.summary()
    assert by_tick[30].field == "header.stamp" and by_tick[30].reason.startswith("unknown_tick"), str(by_tick[30])
    assert by_tick[40].answered == 1.5 and by_tick[40].reason.startswith("invalid_speed"), str(by_tick[40])
    assert (by_tick[40].topic, by_tick[40].field) == ("batch/cmd", "speeds[0]"), str(by_tick[40])
    assert verdict.count("matching") == 251, verdict.summary()  # everything after the misbehaviour still checked
    text = verdict.summary()
    assert "no answer in time (2): ticks 10, 11" in text and "the node refuses it: invalid_speed" in text, text
    case = ET.fromstring(verdict.to_junit()).find("testsuite/testcase[@name='missing or late answers']/failure")
    assert case is not None and "tick 10" in case.text


def test_a_controller_that_crashes_fails_the_run_with_its_code_and_output(namespace):
    verdict = check_controller(
        DATA / "basic_d", namespace=namespace("crash"), controller=scripted("basic_d", "--exit-at", "100=7")
    )
    assert verdict.exit_code == 3, verdict.summary()
    assert "exited with code 7" in verdict.error and "exiting with 7 at tick 100, as told" in verdict.error, (
        verdict.error
    )
    assert ET.fromstring(verdict.to_junit()).find("testsuite/testcase[@name='run']/error") is not None


def test_no_controller_fails_the_run_after_the_wait(namespace):
    verdict = check_controller(DATA / "basic_d", namespace=namespace("none"), wait=1.0)
    assert verdict.exit_code == 3, verdict.summary()
    assert "no controller answers in" in verdict.error and "--controller" in verdict.error, verdict.error


# --------------------------------------------------------------------------------------------
# Closed loop


def test_our_controller_passes_closed_loop_and_the_recorded_run_replays(namespace, tmp_path):
    from sorting_line_gym.bag.transport.replay import replay

    out = tmp_path / "run"
    verdict = check_controller(
        DATA / "basic_d",
        namespace=namespace("closed"),
        controller=our_controller("basic_d"),
        closed_loop=True,
        record=out,
    )
    assert verdict.passed, verdict.summary()
    assert [e.episode for e in verdict.episodes] == [1, 2, 3, 4, 5] and verdict.ticks == 255, verdict.summary()
    assert all(e.parted is None and e.run == e.bag for e in verdict.episodes), verdict.summary()
    suite = ET.fromstring(verdict.to_junit()).find("testsuite")
    assert (suite.get("tests"), suite.get("failures")) == ("6", "0")
    # The recording of the run is a bag like the golden one: it replays exactly.
    result = replay(out)
    assert result.identical and result.resets == 5, result.report()


def test_closed_loop_names_the_nodes_reason_for_a_refused_answer(namespace):
    """An out-of-range speed at tick 60: the node refuses it, the episode stalls there. Before
    that, no answer to the first tick (as when a first answer is lost while endpoints match): the
    bag's first reset has no seed, so the check starts a fresh node and begins again."""
    verdict = check_controller(
        DATA / "basic_d",
        namespace=namespace("closed_bad"),
        closed_loop=True,
        answer_timeout=1.0,
        controller=scripted("basic_d", "--skip-once", "1", "--speed-at", "60=1.5"),
    )
    assert verdict.exit_code == 1, verdict.summary()
    assert "the node was restarted and the run began again" in verdict.summary()
    assert verdict.episodes[0].passed and not verdict.episodes[1].passed, verdict.summary()
    stall = verdict.answers[0]
    assert (stall.tick, stall.episode, stall.step, stall.status) == (60, 2, 8, "missing"), verdict.summary()
    assert "rejected speed 1.5 for stamp 60.000000000" in stall.reason and "[invalid_speed]" in stall.reason
    assert "the run stopped at step 8 of 50" in verdict.summary()


# --------------------------------------------------------------------------------------------
# Bad input (no ROS needed: each is refused before anything starts)


def _copy_without(src: Path, dst: Path, drop) -> Path:
    bag = open_bag(src)
    writer = BagWriter(dst, bag.custom)
    try:
        for topic, msgtype in bag.types.items():
            if not drop(topic):
                writer.add_topic(topic, msgtype)
        for m in bag.messages:
            if not drop(m.topic):
                writer.write(m.topic, m.log_time, m.data)
    finally:
        writer.close()
    return dst


def test_bad_input_exits_with_2_and_says_why(tmp_path, capsys):
    from sorting_line_gym.bag.cli import main

    truncated = tmp_path / "truncated"
    shutil.copytree(DATA / "basic_d", truncated)
    mcap_file = next(truncated.glob("*.mcap"))
    mcap_file.write_bytes(mcap_file.read_bytes()[:20000])
    no_commands = _copy_without(DATA / "basic_d", tmp_path / "no_commands", lambda t: "/cmd/" in t)
    empty = BagWriter(tmp_path / "empty", {META_KEY: open_bag(DATA / "basic_d").custom[META_KEY]})
    empty.add_topic("/golden_basic_d/state", "sorting_line_interfaces/msg/LineState")
    empty.close()
    other = BagWriter(tmp_path / "other")
    other.add_topic("/chatter", "std_msgs/msg/String")
    store = typestore()
    String = store.types["std_msgs/msg/String"]
    other.write("/chatter", 1, store.serialize_cdr(String(data="hello"), "std_msgs/msg/String"))
    other.close()
    cases = [
        ((no_commands,), "the bag has no commands"),
        ((truncated,), "cannot read the bag"),
        ((tmp_path / "empty",), "the bag is empty"),
        ((tmp_path / "other",), "not a bag of a sorting line"),
        ((tmp_path / "missing",), "no such bag"),
        ((DATA / "basic_d", "--max-reward-drop", "lots", "--closed-loop"), "--max-reward-drop 'lots': expected"),
        ((DATA / "basic_d", "--controller", "no-such-controller-program"), "is not a program on PATH"),
        ((DATA / "basic_d", "--namespace", "/a-b"), "--namespace '/a-b' is not a valid ROS namespace"),
        ((DATA / "basic_d", "--record", tmp_path / "out"), "--record records the closed-loop run"),
    ]
    for args, message in cases:
        code = main(["check", *[str(a) for a in args], "--wait", "1"])
        out = capsys.readouterr().out
        assert (code, message in out) == (2, True), f"{args}: exit {code}, output {out!r}"
