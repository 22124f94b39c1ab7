"""`sorting-line-controller --policy`: a learned policy (tests/data/policies: PPO on setup B,
advanced line, exported with `sorting-line-export`) as a controller node on real lines.

What must hold:
- parity: driving a lock-step line for seeds 42..51 (50 steps each), the ONNX controller makes
  exactly the decisions, and gets exactly the episode rewards, that `sorting-line-eval --agent
  ppo:MODEL.zip` makes and reports (its own episode loop, ``evaluate.run_episode``, on the env);
- the controller process never imports torch (nor SB3) for an ONNX policy;
- a policy trained for another setup is refused at start, naming both (read from the line node's
  parameters); ``--allow-mismatch`` runs it;
- a policy whose runtime fails on a tick: with ``--fallback rba-hold`` rba-hold answers (each
  fallback logged and counted on /diagnostics), without it the controller says why and exits 1;
- bad input fails with exit code 2 and a message, no traceback.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from support import ros_harness as h
from support.controller_process import ControllerProcess, line_recorders, reset_until_answered, watch
from support.ros_harness import ns_args
from support.training_stack import needs_training
from support.waits import wait_until

POLICIES = h.ROOT / "tests" / "data" / "policies"
PPO_ZIP = POLICIES / "ppo_B_advanced_seed42.zip"
PPO_ONNX = POLICIES / "ppo_B_advanced_seed42.onnx"
SEEDS = range(42, 52)
#: Runs the controller's command line, then reports which heavy packages its process imported.
REPORTING_CONTROLLER = """\
import json, sys
from sorting_line_gym.agents.controller_cli import main
code = main()
heavy = sorted(m for m in ("torch", "stable_baselines3", "sb3_contrib") if m in sys.modules)
print("HEAVY MODULES " + json.dumps(heavy), flush=True)
sys.exit(code)
"""


pytestmark = pytest.mark.usefixtures("same_binary")  # conftest: the tools start the tests' binary


def reporting_controller(tmp_path: Path, tag: str, args: list) -> ControllerProcess:
    """The controller's command line in a script of its own that reports its imports at exit."""
    script = tmp_path / f"controller_{tag}"
    script.write_text(f"#!{sys.executable}\n{REPORTING_CONTROLLER}")
    script.chmod(0o755)
    process = ControllerProcess.__new__(ControllerProcess)
    process.decision_path = tmp_path / f"decisions_{tag}.jsonl"
    h.ScriptProcess.__init__(
        process, str(script), [*args, "--decision-log", process.decision_path], tmp_path / f"{tag}.log", "controller"
    )
    return process


def drive_episodes(ros, client, rec, controller, seeds) -> dict[int, list]:
    """Resets the line with each seed and waits until the controller has driven the episode to its
    end; the states of each episode, in step order."""
    context, abort = watch(client, controller)
    ros.spin_until(lambda: "connected:" in controller.log(), 60.0, "the controller to connect", context, abort=abort)
    episodes = {}
    for seed in seeds:
        episode = reset_until_answered(ros, client, rec, seed, context, abort)

        def states(episode=episode):
            return sorted((s for _, s in rec["state"].items if s.episode == episode), key=lambda s: s.step)

        ros.spin_until(lambda: any(s.truncated for s in states()), 30.0, f"episode {episode}", context, abort=abort)
        episodes[seed] = states()
    return episodes


def eval_decisions(seeds) -> dict[int, tuple[float, list]]:
    """What `sorting-line-eval --agent ppo:MODEL.zip` does, per seed: its episode reward and actions."""
    from sorting_line_gym.envs.env import SortingLineEnv
    from sorting_line_gym.studies.evaluate import run_episode
    from sorting_line_gym.training.trained_agent import make_agent

    agent = make_agent(f"ppo:{PPO_ZIP}", "B", "advanced")
    actions: list[int] = []
    predict = agent.predict
    agent.predict = lambda obs, current: actions.append(predict(obs, current)) or actions[-1]
    env = SortingLineEnv(setup="B", variant="advanced", max_episode_steps=50, node="spawn")
    out = {}
    try:
        for seed in seeds:
            actions.clear()
            out[seed] = (run_episode(env, agent, seed).reward, list(actions))
    finally:
        env.close()
    return out


@needs_training
def test_the_onnx_controller_decides_and_scores_as_eval_and_never_imports_torch(
    ros, start_node, client_factory, probe, namespace, tmp_path
):
    ns = namespace("parity")
    node = start_node("--variant", "advanced", *h.SETUP_FLAGS["B"], "--max-steps", "50", *ns_args(ns))
    rec = line_recorders(probe, ns)
    client = client_factory(ns, "advanced", node_proc=node)
    client.wait_connected()
    controller = reporting_controller(tmp_path, "onnx", ["--namespace", ns, "--policy", PPO_ONNX])
    try:
        episodes = drive_episodes(ros, client, rec, controller, SEEDS)
    finally:
        code = controller.stop()
    assert code == 0, controller.describe()
    assert "HEAVY MODULES []" in controller.log(), controller.describe()
    assert "policy: PPO for setup B advanced (seed 42, 4096 steps)" in controller.log(), controller.log()

    want = eval_decisions(SEEDS)
    for seed, states in episodes.items():
        assert [s.step for s in states] == list(range(51)), seed
        actions = [s.speed_index * 3 + s.mode for s in states[1:]]
        reward = 0.0
        for s in states[1:]:
            reward += s.reward  # summed as the eval sums its steps' rewards
        assert actions == want[seed][1], f"seed {seed}: the controller's decisions differ from eval's"
        assert reward == want[seed][0], f"seed {seed}: episode reward {reward}, eval {want[seed][0]}"
    assert len({tuple(w[1]) for w in want.values()}) > 1, "every episode the same: the comparison is weak"


def test_a_policy_for_another_setup_is_refused_naming_both(ros, start_node, namespace, tmp_path):
    ns = namespace("mismatch")
    start_node("--variant", "advanced", *h.SETUP_FLAGS["A"], *ns_args(ns))
    refused = ControllerProcess(tmp_path, "refused", ["--namespace", ns, "--policy", PPO_ONNX, "--line-timeout", "20"])
    assert refused.wait(60) == 2, refused.describe()
    log = refused.log()
    assert "trained for PPO for setup B advanced" in log and "the line is setup A advanced" in log, log
    assert f"parameters of {ns}/sorting_line" in log and "--allow-mismatch" in log and "Traceback" not in log, log
    allowed = ControllerProcess(
        tmp_path, "allowed", ["--namespace", ns, "--policy", PPO_ONNX, "--allow-mismatch", "--line-timeout", "20"]
    )
    try:
        ros.spin_until(lambda: "connected:" in allowed.log(), 60.0, "the controller to connect", allowed.describe)
    finally:
        assert allowed.stop() == 0, allowed.describe()
    assert "setup B vs A" in allowed.log() and "(--allow-mismatch)" in allowed.log(), allowed.log()


def failing_policy(path: Path) -> Path:
    """An ONNX policy with our metadata whose runtime fails on most ticks: its action indexes a
    30-entry table with round(quantity * 100), out of range above a reading of 0.3."""
    import onnx
    from onnx import TensorProto, helper

    from sorting_line_gym.line.policy_card import PolicyCard

    nodes = [
        helper.make_node("Slice", ["observation", "zero", "one", "one"], ["q"]),
        helper.make_node("Mul", ["q", "hundred"], ["scaled"]),
        helper.make_node("Cast", ["scaled"], ["index"], to=TensorProto.INT64),
        helper.make_node("Squeeze", ["index", "one"], ["flat"]),
        helper.make_node("Gather", ["table", "flat"], ["action"], axis=0),
    ]
    inits = [
        helper.make_tensor("zero", TensorProto.INT64, [1], [0]),
        helper.make_tensor("one", TensorProto.INT64, [1], [1]),
        helper.make_tensor("hundred", TensorProto.FLOAT, [1], [100.0]),
        helper.make_tensor("table", TensorProto.INT64, [30], list(range(30))),
    ]
    graph = helper.make_graph(
        nodes,
        "failing",
        [helper.make_tensor_value_info("observation", TensorProto.FLOAT, ["batch", 2])],
        [helper.make_tensor_value_info("action", TensorProto.INT64, ["batch"])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    for key, value in PolicyCard(setup="B", variant="advanced", algorithm="ppo").to_metadata().items():
        model.metadata_props.add(key=key, value=value)
    onnx.save(model, str(path))
    return path


@needs_training
def test_a_failing_policy_falls_back_to_rba_hold_or_stops(ros, start_node, client_factory, probe, namespace, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray

    policy = failing_policy(tmp_path / "failing.onnx")
    ns = namespace("fallback")
    node = start_node("--variant", "advanced", *h.SETUP_FLAGS["B"], "--max-steps", "50", *ns_args(ns))
    rec = line_recorders(probe, ns)
    statuses = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", lambda m: statuses.extend(m.status), 50)
    client = client_factory(ns, "advanced", node_proc=node)
    client.wait_connected()
    ctl = ControllerProcess(tmp_path, "fallback", ["--namespace", ns, "--policy", policy, "--fallback", "rba-hold"])
    try:
        states = drive_episodes(ros, client, rec, ctl, [42])[42]

        def counted():
            mine = [s for s in statuses if s.name.startswith(f"{ns}/sorting_line_controller")]
            return mine and int({v.key: v.value for v in mine[-1].values}["fallbacks"]) > 0

        ros.spin_until(counted, 10.0, "/diagnostics to count the fallbacks", ctl.describe)
        mine = [s for s in statuses if s.name.startswith(f"{ns}/sorting_line_controller")]
        said = {v.key: int(v.value) for v in mine[-1].values if v.key.endswith("_readers")}
        # How many readers its command writers matched (the node's at least): what recorders wait for.
        assert said["cmd_speed_readers"] >= 1 and said["cmd_sort_mode_readers"] >= 1, said
    finally:
        assert ctl.stop() == 0, ctl.describe()
    assert len(states) == 51 and "rba-hold answers it (fallback 1)" in ctl.log(), ctl.log()

    stopping = ControllerProcess(tmp_path, "stopping", ["--namespace", ns, "--policy", policy])
    ros.spin_until(lambda: "connected:" in stopping.log(), 60.0, "the controller to connect", stopping.describe)
    for _ in range(3):
        client.reset(42)
        if not stopping.running():
            break
        ros.spin_for(1.0)
    assert stopping.wait(20) == 1, stopping.describe()
    assert "the policy could not answer the tick" in stopping.log() and "--fallback rba-hold" in stopping.log()


def controller_cli(args: list, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(Path(sys.executable).parent / "sorting-line-controller"), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        env=env or dict(os.environ, **h.ros_environment()),
        stdin=subprocess.DEVNULL,
    )


@needs_training
def test_bad_policy_files_fail_with_a_message_and_exit_code_2(tmp_path, namespace):
    import onnx
    import torch

    text = tmp_path / "policy.onnx"
    text.write_text("not a model")
    bare = onnx.load(str(PPO_ONNX))
    del bare.metadata_props[:]
    onnx.save(bare, str(tmp_path / "bare.onnx"))
    torch.onnx.export(torch.nn.Linear(3, 5), (torch.zeros(1, 3),), str(tmp_path / "shapes.onnx"), dynamo=False)
    ns = namespace("bad")
    quick = ["--namespace", ns, "--line-timeout", "0"]
    cases = [
        (["--policy", text], "not an ONNX model onnxruntime can load"),
        (["--policy", tmp_path / "missing.onnx"], "no such file"),
        (["--policy", tmp_path / "shapes.onnx"], "no line has those"),
        ([*quick, "--policy", tmp_path / "bare.onnx"], "no sorting_line metadata"),
        ([*quick, "--policy", PPO_ONNX, "--variant", "basic"], "its shapes are the advanced line's"),
        (["--agent", "rba", "--fallback", "rba-hold", "--setup", "B"], "--fallback goes with --policy"),
    ]
    for args, message in cases:
        r = controller_cli(args)
        assert r.returncode == 2 and message in r.stderr, (args, r.returncode, r.stderr)
        assert "Traceback" not in r.stderr, r.stderr
    # A ROS_DOMAIN_ID DDS cannot use: named, before rclpy starts (rmw_fastrtps would end the process silently).
    beyond = {**os.environ, **h.ros_environment(), "ROS_DOMAIN_ID": "233"}
    r = controller_cli(["--agent", "rba", "--setup", "B"], env=beyond)
    assert r.returncode == 2 and "ROS_DOMAIN_ID = '233' is out of range" in r.stderr, (r.returncode, r.stderr)
    # Without onnxruntime: the install command.
    code = (
        "import sys; sys.modules['onnxruntime'] = None\n"
        "from sorting_line_gym.agents.controller_cli import main\n"
        f"sys.exit(main(['--policy', {str(PPO_ONNX)!r}]))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "needs onnxruntime: pip install -r launch_scripts/requirements-bridge.txt" in r.stderr
    # Without metadata, --allow-mismatch runs it where its shapes fit (no line here: it waits for one).
    args = [*quick, "--policy", tmp_path / "bare.onnx", "--allow-mismatch", "--variant", "advanced"]
    running = ControllerProcess(tmp_path, "bare", args)
    try:
        wait_until(
            lambda: "policy: a policy without sorting_line metadata" in running.log(),
            60,
            "the controller to say it runs a policy without metadata",
            poll=0.2,
            context=running.describe,
            abort=lambda: None if running.running() else "the controller exited",
        )
    finally:
        stopped = running.stop()
    assert stopped == 0, running.describe()
    assert "policy: a policy without sorting_line metadata" in running.log(), running.describe()


def test_a_model_zip_without_the_training_stack_fails_naming_setup_train():
    """A core install (setup.sh without --train) has no SB3 nor torch: `--policy MODEL.zip` fails at start
    with exit code 2 naming the install command and the ONNX way, no traceback. (SB3 and torch are hidden
    from the process, so this holds with the training stack installed too.)"""
    code = (
        "import sys; sys.modules['stable_baselines3'] = sys.modules['torch'] = None\n"
        "from sorting_line_gym.agents.controller_cli import main\n"
        f"sys.exit(main(['--policy', {str(PPO_ZIP)!r}]))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "needs stable-baselines3 and torch" in r.stderr, r.stderr
    assert "bash launch_scripts/setup.sh --train" in r.stderr, r.stderr
    assert "sorting-line-export" in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_a_learned_agent_builds_the_env_observation_and_mask():
    from sorting_line_gym.agents.learned_policy import LearnedAgent, load_learned_policy
    from sorting_line_gym.line.vocabulary import CATEGORY_UNKNOWN_CODE, action_mask, observations

    agent = LearnedAgent(load_learned_policy(PPO_ONNX))
    assert agent.observation(0.42, CATEGORY_UNKNOWN_CODE).tolist() == observations("advanced", 0.42, 3).tolist()
    assert agent.observation(0.42, CATEGORY_UNKNOWN_CODE)[1] == np.float32(0.5)
    assert action_mask("advanced", sort_modes=False).sum() == 10 and action_mask("basic").all()
    with pytest.raises(ValueError, match="not a number"):
        agent.act(float("nan"), 0, 5)
    assert json.dumps(agent.act(0.5, 1, 5))


def test_on_an_evolving_line_without_ratio_sensor_the_category_reads_unknown(
    ros, start_node, client_factory, probe, namespace, tmp_path
):
    """The upgrade schedule's first episodes have no ratio sensor: ticks need no `sensors/ratio`, and
    the policy sees the category as the env shows it, unknown (0.5). A policy for the fixed line is a
    mismatch (evolution none vs upgrade) that --allow-mismatch runs."""
    from sorting_line_gym.agents.learned_policy import load_learned_policy
    from sorting_line_gym.envs.evolving import schedule_file
    from sorting_line_gym.line.vocabulary import CATEGORY_UNKNOWN_CODE, observations

    ns = namespace("evolving")
    schedule = schedule_file("upgrade")
    node = start_node("--evolution", schedule, *h.SETUP_FLAGS["B"], "--max-steps", "50", *ns_args(ns))
    rec = line_recorders(probe, ns)
    client = client_factory(ns, "basic", node_proc=node)  # the line starts without sensor and sort modes
    client.wait_connected()
    args = ["--namespace", ns, "--policy", PPO_ONNX, "--allow-mismatch", "--line-timeout", "20"]
    ctl = ControllerProcess(tmp_path, "evolving", args)
    try:
        states = drive_episodes(ros, client, rec, ctl, [42])[42]
    finally:
        assert ctl.stop() == 0, ctl.describe()
    assert "evolution none vs upgrade" in ctl.log(), ctl.log()
    assert len(states) == 51
    policy = load_learned_policy(PPO_ONNX)
    decisions = ctl.decisions()
    assert decisions and all(d["category"] is None for d in decisions.values()), list(decisions.values())[:3]
    for d in decisions.values():
        want = policy.act(observations("advanced", d["quantity"], CATEGORY_UNKNOWN_CODE), None)
        assert (d["speed_index"], d["mode"]) == want, d
