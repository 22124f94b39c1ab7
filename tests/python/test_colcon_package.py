"""The node as a ROS 2 package (docs/ros-package.md), as a ROS user builds and runs it: a colcon workspace
with this repository under src/, built by a plain `colcon build` from PyPI's colcon with .venv as the
underlay (tests/python/support/colcon_ws.py; launch_scripts/test.sh builds it before the tests), then, after
`source install/setup.bash`, the real `ros2` CLI: `ros2 pkg`, `ros2 interface`, `ros2 run` of the
node and of the bridge's entries, and `ros2 launch sorting_line sorting_line.launch.py`.

Graph queries go through a ros2 daemon started in this module's environment and are repeated until
the answer appears or their time is up (discovery is asynchronous); checks on the answers are exact.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from support import colcon_ws, ros2_cli
from support import ros_harness as h
from support.ros2_output import poll, yaml_docs
from support.ros_harness import LINE_TYPES
from support.waits import wait_until

# The workspace installs Python modules for the project venv's version (this interpreter's).
PYTHON_DIR = f"python{sys.version_info.major}.{sys.version_info.minor}"
EXECUTABLES = {"sorting_line", "sorting-line-bridge", "sorting-line-controller", "sorting-line-bag"}


@pytest.fixture(scope="module")
def workspace() -> Path:
    """The built workspace; fails with the build's log if the build failed."""
    ws = colcon_ws.workspace_dir()
    result = colcon_ws.load_result(ws)
    if result is None:
        build = "python tests/python/support/colcon_ws.py --build"
        why = f"no colcon workspace in {ws}: build it with `{build}` (test.sh does)"
        if os.environ.get("SORTING_LINE_COLCON_WS"):  # test.sh built it: then a missing result is a failure
            pytest.fail(why, pytrace=False)
        pytest.skip(why)
    if result.get("returncode") != 0:
        log = Path(result["log"])
        tail = "\n".join(log.read_text(errors="replace").splitlines()[-40:]) if log.is_file() else ""
        pytest.fail(
            f"`{result['command']}` in {ws} failed: {result.get('error') or result.get('returncode')}\n{log}:\n{tail}",
            pytrace=False,
        )
    print(f"colcon workspace {ws}: venv {result['venv_seconds']} s, `{result['command']}` {result['build_seconds']} s")
    return ws


@pytest.fixture(scope="module")
def ros2(workspace, tmp_path_factory):
    """The ros2 CLI after `source install/setup.bash`, over the underlay: the CLI's own ROS packages and
    .venv's simulation_interfaces (the workspace built none: .venv has it). `python3` is .venv's, as
    after `source launch_scripts/env.sh`: the bridge's entries run with it. Runs its own daemon."""
    base = tmp_path_factory.mktemp("colcon_ros2")
    cli, origin = ros2_cli.locate(base / "underlay", base / "log", interfaces=("simulation_interfaces",))
    if cli is None:
        pytest.skip(origin)
    sourced = subprocess.run(
        ["bash", "-c", 'source "$1/install/setup.bash" && env -0', "bash", str(workspace)],
        env=cli.env,
        capture_output=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
        check=False,
    )
    assert sourced.returncode == 0, f"source install/setup.bash failed:\n{sourced.stderr.decode(errors='replace')}"
    env = dict(item.split("=", 1) for item in sourced.stdout.decode().split("\0") if "=" in item)
    env["PATH"] = os.pathsep.join([str(colcon_ws.PROJECT_VENV / "bin"), env["PATH"]])
    cli = ros2_cli.Ros2Cli(cli.executable, env, origin)
    cli.run("daemon", "stop", timeout=30, check=False)  # another module's daemon has another environment
    cli.run("daemon", "start", timeout=30)
    yield cli
    cli.run("daemon", "stop", timeout=30)


class Started:
    """A `ros2 run` / `ros2 launch` in a session of its own (SIGINT reaches what it started)."""

    def __init__(self, ros2, args: list[str], log: Path):
        self.log = log
        with open(log, "wb") as out:
            self.proc = subprocess.Popen(
                ["setsid", "env", "--default-signal=INT", *ros2.argv(*args)],
                stdout=out,
                stderr=subprocess.STDOUT,
                env=ros2.env,
                stdin=subprocess.DEVNULL,
            )

    def executables(self) -> set[str]:
        """The executables of the processes of its session (setsid: session id = its pid)."""
        found = set()
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
                if int(fields[3]) == self.proc.pid:  # field 6 of stat: session
                    found.add(os.readlink(stat.parent / "exe"))
            except (OSError, ValueError, IndexError):
                continue
        return found

    def stop(self) -> str:
        """SIGINT to the session; returns the output after checking the exit code is 0."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
        try:
            code = self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(timeout=5)
            code = "killed after 20 s"
        out = self.log.read_text(errors="replace")
        assert code == 0, f"exited with {code} after SIGINT:\n{out}"
        return out


def installed(workspace: Path, package: str, *rel: str) -> Path:
    return workspace / "install" / package / Path(*rel)


def ros2_run_node(ns: str, *args: str) -> list[str]:
    """`ros2 run` arguments of the installed node: a realtime line at 10 Hz (steps enough to outlast
    the test) in namespace `ns`, with the node options `args` besides."""
    node = ["--mode", "realtime", "--rate", "10", "--max-steps", "1000000"]
    return ["run", "sorting_line", "sorting_line", "node", *args, *node, "--ros-args", "-r", f"__ns:={ns}"]


def test_plain_colcon_build_found_and_installed_all_three_packages(workspace):
    venv = colcon_ws.venv_dir()
    listed = subprocess.run(
        [str(venv / "bin" / "colcon"), "list", "--names-only"],
        cwd=workspace,
        capture_output=True,
        text=True,
        timeout=60,
        env=colcon_ws.build_environment(venv),
        check=False,
    )
    assert sorted(listed.stdout.split()) == sorted(colcon_ws.PACKAGES), listed.stdout + listed.stderr
    for package in colcon_ws.PACKAGES:
        assert installed(workspace, package, "share", "colcon-core", "packages", package).is_file(), package
    lib = installed(workspace, "sorting_line", "lib", "sorting_line")
    assert {p.name for p in lib.iterdir()} == EXECUTABLES and all(os.access(p, os.X_OK) for p in lib.iterdir())
    # The release build of the sources (setup.sh's, reused through the shared target/).
    assert (lib / "sorting_line").read_bytes() == (h.ROOT / "target" / "release" / "sorting_line").read_bytes()
    share = installed(workspace, "sorting_line", "share", "sorting_line")
    for name in ["sorting_line.launch.py", "sorting_line.yaml", "package.xml"]:
        assert (share / name).read_bytes() == (
            h.ROOT / "launch_scripts" / name if name != "package.xml" else h.ROOT / name
        ).read_bytes(), name
    python = installed(
        workspace, "sorting_line_interfaces", "lib", PYTHON_DIR, "site-packages", "sorting_line_interfaces"
    )
    assert (python / "msg" / "_line_state.py").is_file() and (python / "srv" / "_reset_line.py").is_file()
    # .venv provides simulation_interfaces: our copy builds and installs nothing, so it shadows nothing.
    log = (workspace / "log" / "latest_build" / "simulation_interfaces" / "stdout.log").read_text()
    assert f"simulation_interfaces: installed in {colcon_ws.PROJECT_VENV.resolve()}" in log, log
    assert not installed(workspace, "simulation_interfaces", "share", "ament_index").exists()


def test_ros2_pkg_and_interface_see_the_installed_packages(ros2, workspace):
    out = ros2.run("pkg", "executables", "sorting_line", timeout=30).stdout
    assert sorted(out.splitlines()) == sorted(f"sorting_line {name}" for name in EXECUTABLES), out
    for package in ["sorting_line", "sorting_line_interfaces"]:
        prefix = ros2.run("pkg", "prefix", package, timeout=30).stdout.strip()
        assert prefix == str(installed(workspace, package)), (package, prefix)
    listed = ros2.run("interface", "list", timeout=30).stdout.split()
    ours = [
        f"sorting_line_interfaces/{kind}/{f.stem}" for kind in ["msg", "srv"] for f in (h.ROOT / "msg" / kind).iterdir()
    ]
    standard = [
        f"simulation_interfaces/{kind}/{f.stem}"
        for kind in ["msg", "srv", "action"]
        for f in (h.ROOT / "msg" / "simulation_interfaces" / kind).iterdir()
    ]
    assert not set(ours + standard) - set(listed), sorted(set(ours + standard) - set(listed))
    package = ros2.run("interface", "package", "sorting_line_interfaces", timeout=30).stdout.split()
    assert sorted(package) == sorted(ours), package


def test_ros2_run_the_node(ros2, workspace, namespace, tmp_path):
    """`ros2 run sorting_line sorting_line node ...`: the installed binary, its topics with their types."""
    ns = namespace("run")
    node = Started(ros2, ros2_run_node(ns, "--variant", "advanced", "--seed", "3"), tmp_path / "run.log")
    try:
        want = {h.join_ns(ns, rel): f"[{t}]" for rel, t in LINE_TYPES.items()}

        def listed(out):
            return dict(line.split(" ", 1) for line in out.splitlines() if " " in line)

        out = poll(
            ros2,
            ["topic", "list", "-t"],
            lambda out: want.items() <= listed(out).items(),
            "every line topic",
            timeout=30,
        )
        assert str(installed(workspace, "sorting_line", "lib", "sorting_line", "sorting_line")) in node.executables()
        state = yaml_docs(ros2.run("topic", "echo", "--once", h.join_ns(ns, "state"), timeout=30).stdout)[0]
        assert state["seed"] == 3 and state["speed"] == 0.6 and state["step"] >= 0, state
        assert "/clock [rosgraph_msgs/msg/Clock]" in out, out
    finally:
        node.stop()


def test_ros2_launch_sorting_line(ros2, workspace, namespace, tmp_path):
    """`ros2 launch sorting_line sorting_line.launch.py namespace:=... lines:=4` with the installed
    default parameter file: the launch file starts the installed binary, which takes every value of
    the file (the node's defaults) and lines:=4 over it."""
    ns = namespace("plant")
    params = installed(workspace, "sorting_line", "share", "sorting_line", "sorting_line.yaml")
    launch = Started(
        ros2,
        ["launch", "sorting_line", "sorting_line.launch.py", f"namespace:={ns}", "lines:=4", f"params_file:={params}"],
        tmp_path / "launch.log",
    )
    fqn = f"{ns}/sorting_line"
    try:
        poll(ros2, ["node", "list"], lambda out: fqn in out.split(), f"node {fqn}", timeout=30)
        assert str(installed(workspace, "sorting_line", "lib", "sorting_line", "sorting_line")) in launch.executables()
        dump = yaml.safe_load(ros2.run("param", "dump", fqn, timeout=20).stdout)[fqn]["ros__parameters"]
        defaults = yaml.safe_load(params.read_text())["/**"]["ros__parameters"]
        assert dump == {**defaults, "lines": 4, "use_sim_time": False}, dump
        poll(
            ros2,
            ["topic", "list"],
            lambda out: all(f"{ns}/line_{k}/state" in out.split() for k in range(4)),
            "the four lines' topics",
        )
    finally:
        log = launch.stop()
    assert "process has finished cleanly" in log, log


def test_ros2_run_the_bridge_entries(ros2, namespace, tmp_path):
    """`ros2 run sorting_line sorting-line-{bag,bridge,controller}`; the controller drives a realtime
    line of a node started with `ros2 run` (its decision log fills)."""
    for name in ["sorting-line-bag", "sorting-line-bridge"]:
        out = ros2.run("run", "sorting_line", name, "--help", timeout=60).stdout
        assert out.startswith(f"usage: {name}"), out
    ns = namespace("controller")
    node = Started(ros2, ros2_run_node(ns), tmp_path / "node.log")
    decisions = tmp_path / "decisions.jsonl"
    controller = Started(
        ros2,
        [
            "run",
            "sorting_line",
            "sorting-line-controller",
            "--setup",
            "A",
            "--namespace",
            ns,
            "--decision-log",
            str(decisions),
        ],
        tmp_path / "controller.log",
    )
    try:
        wait_until(
            lambda: decisions.is_file() and len(decisions.read_text().splitlines()) >= 5,
            60,
            "5 decisions in the controller's decision log",
            poll=0.5,
            context=lambda: controller.log.read_text(errors="replace"),
        )
    finally:
        controller.stop()
        node.stop()


def test_the_launch_file_takes_the_installed_binary_or_the_clones(ros2):
    """Without `sorting_line_bin`, the installed launch file starts the package's executable (the
    ament index's, as the launch test above sees) and the clone's starts the clone's release build."""

    def default_binary(launch_file: str, *package: str) -> str:
        out = ros2.run("launch", *package, launch_file, "--show-args", timeout=60).stdout
        block = out.split("'sorting_line_bin':", 1)[1].split("\n\n", 1)[0]
        return block.split("(default: '", 1)[1].split("')", 1)[0]

    assert default_binary("sorting_line.launch.py", "sorting_line") == ""
    clone = default_binary(str(h.ROOT / "launch_scripts" / "sorting_line.launch.py"))
    assert clone == str(h.ROOT / "target" / "release" / "sorting_line")
