"""The golden bags (tests/data/bags/) and how they are made: with the tool itself.

    bash tests/data/bags/record_golden.sh      # re-records the bags (in a loopback-only netns)
    bash tests/data/bags/record_golden.sh ppo_advanced_b   # one of them

For each bag a lock-step node (a seasonal setup, --max-steps 50), `sorting-line-bag record` on its
namespace, `sorting-line-controller` driving the line (rule-based: it switches speeds, and on the
advanced line sort modes; ``ppo_advanced_b``: a learned policy, the ONNX file of
tests/data/policies/, which make_policies.sh trains and exports), and this module resetting it:
a plan of seeded and unseeded resets (the same seed twice in a row, and continuing streams, on
purpose), each episode run until the node reports `truncated`. About 255 ticks per bag.

`BagProcess` runs the `sorting-line-bag` console script as a user would (also used by test_bags).
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from sorting_line_gym.line.topics import SORT_MODE_CMD, SPEED_CMD, STATE
from sorting_line_gym.workarounds.late_matching import repeated_while_unanswered
from support import ros_harness as h
from support.line_client import LineClient
from support.waits import wait_until

DATA = h.ROOT / "tests" / "data" / "bags"
MAX_STEPS = 50
#: name -> the line, the controller's agent and the reset plan (None: a reset without a seed).
GOLDEN = {
    "basic_d": {"variant": "basic", "setup": "D", "seed": 5, "agent": "rba", "plan": [None, 12, None, 12, 7]},
    "advanced_b": {
        "variant": "advanced",
        "setup": "B",
        "seed": 9,
        "agent": "rba-hold",
        "plan": [11, None, 11, 5, None],
    },
    "ppo_advanced_b": {
        "variant": "advanced",
        "setup": "B",
        "seed": 9,
        "policy": str(h.ROOT / "tests" / "data" / "policies" / "ppo_B_advanced_seed42.onnx"),
        "plan": [11, None, 11, 5, None],
    },
}


def agent_flags(spec: dict) -> list[str]:
    """The controller's flags for a golden bag's agent: a rule-based one or a learned policy."""
    if "policy" in spec:
        return ["--policy", spec["policy"]]
    return ["--setup", spec["setup"], "--variant", spec["variant"], "--agent", spec["agent"]]


class BagProcess(h.ScriptProcess):
    """`sorting-line-bag ARGS` as a subprocess, stdout and stderr into `log_path`."""

    def __init__(self, args: list, log_path: Path):
        super().__init__("sorting-line-bag", args, log_path)

    def wait_for_output(self, text: str, timeout: float, session: h.RosSession | None = None) -> None:
        """Waits until the log shows `text` (spinning `session` meanwhile, if given)."""
        what = f"{text!r} in the log of {self.label}"

        def printed() -> bool:
            return text in self.log()

        def exited() -> str | None:
            return None if self.running() else f"exited before printing {text!r}"

        if session is not None:
            session.spin_until(printed, timeout, what, self.describe, step=0.05, abort=exited)
        else:
            wait_until(printed, timeout, what, context=self.describe, abort=exited)


def wait_for_command_writers(
    session: h.RosSession, recorder: BagProcess, namespace: str, variant: str, context=lambda: "", writers: int = 2
) -> None:
    """Waits until the recorder records and has matched ``writers`` writers on each command topic
    (by default two: the LineClient's and the controller's). Discovery between two rclpy
    processes can take seconds, and a command sent before it is not in the bag."""
    recorder.wait_for_output("recording", 20.0, session)
    for rel in [SPEED_CMD] + ([SORT_MODE_CMD] if variant == "advanced" else []):
        session.spin_until(
            lambda: f"matched {namespace}/{rel}: {writers} publisher(s)" in recorder.log(),
            20.0,
            f"the recorder to match {writers} writer(s) of {rel}",
            context,
        )


def drive(session: h.RosSession, client: LineClient, plan: list, context=lambda: "") -> None:
    """Resets the line as `plan` says and waits, each time, until the controller has driven the
    episode to its end. The controller's first answer can be lost while endpoints still match:
    then nothing moves and the reset is repeated (the bag records both; replay does the same)."""
    for seed in plan:

        def attempt(_k: int, seed=seed) -> tuple[int, bool]:
            episode = client.reset(seed).episode
            try:
                session.spin_until(
                    lambda: any(s.episode == episode and s.step >= 1 for s in client.msgs[STATE]),
                    3.0,
                    f"{client.ns}: the controller's first step",
                    context,
                )
                return episode, True
            except h.WaitTimeout:
                return episode, False

        def again(_result) -> None:
            print("nobody answered the tick of the reset; resetting again", file=sys.stderr)

        episode, answered = repeated_while_unanswered(attempt, lambda r: not r[1], 3, before_repeat=again)
        if not answered:
            raise AssertionError(f"the controller never answered a reset's tick\n{context()}")
        session.spin_until(
            lambda: any(s.episode == episode and s.truncated for s in client.msgs[STATE]),
            30.0,
            f"{client.ns}: episode {episode} driven to its end",
            context,
        )
    session.spin_for(0.3)  # the controller's answer to the last (truncated) tick


def record_golden(name: str, out: Path, session: h.RosSession, workdir: Path, namespace: str) -> str:
    """Records golden bag `name` into `out` (which must not exist); returns the recorder's summary."""
    from support.controller_process import ControllerProcess  # the controller as the controller tests run it

    spec = GOLDEN[name]
    node = h.NodeProcess(
        [
            *h.SETUP_FLAGS[spec["setup"]],
            "--variant",
            spec["variant"],
            "--seed",
            spec["seed"],
            "--max-steps",
            MAX_STEPS,
            "--ros-args",
            "-r",
            f"__ns:={namespace}",
        ],
        workdir / f"node_{name}.log",
    )
    recorder = controller = None
    client = LineClient(session, namespace, spec["variant"], node_proc=node)
    try:
        client.wait_connected()
        controller = ControllerProcess(
            workdir,
            name,
            ["--namespace", namespace, *agent_flags(spec)],
        )
        recorder = BagProcess(["record", "--namespace", namespace, "-o", out], workdir / f"record_{name}.log")

        def context():
            return f"{client.context()}\n{controller.describe()}\n{recorder.describe()}"

        session.spin_until(lambda: "connected:" in controller.log(), 30.0, "the controller to connect", context)
        wait_for_command_writers(session, recorder, namespace, spec["variant"], context)
        drive(session, client, spec["plan"], context)
        assert controller.stop() == 0, controller.describe()
        controller = None
        assert recorder.stop() == 0, recorder.describe()
        summary = recorder.log().strip().splitlines()[-1]
        recorder = None
        return summary
    finally:
        if controller is not None:
            controller.stop()
        if recorder is not None and recorder.running():
            recorder.stop()
        client.destroy()
        node.stop()


def main() -> int:
    h.check_isolated_network()
    h.ros_environment()
    import tempfile

    session = h.RosSession()
    try:
        with tempfile.TemporaryDirectory(prefix="golden_bags_") as tmp:
            for name in sys.argv[1:] or GOLDEN:
                out = DATA / name
                if out.exists():
                    shutil.rmtree(out)
                print(record_golden(name, out, session, Path(tmp), f"/golden_{name}"))
    finally:
        session.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
