"""docs/deploying-a-policy.md runs as written: its commands are taken from the page and run.

The `deploy` block (after `<!-- doc-test: deploy -->`): train (the budget cut to one 256-step PPO
rollout), export, a realtime node in the background and the controller with the exported policy,
which must decide on the line; then the page's `sorting-line-bag check` commands against the golden
bag, open and closed loop. Each in this test's ROS domain; about 60 s.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

from support import ros_harness as h
from support.waits import wait_until

DOC = h.ROOT / "docs" / "deploying-a-policy.md"
#: The training budget of the doc (4096 steps) cut for CI: one PPO rollout of 256 steps.
CUT = ("--timesteps 4096", "--timesteps 256 --hp n_steps=256 --hp batch_size=64")


def deploy_block() -> list[str]:
    match = re.search(r"<!-- doc-test: deploy -->\n```sh\n(.*?)\n```", DOC.read_text(), re.S)
    assert match, f"{DOC} has no sh block after <!-- doc-test: deploy -->"
    return match.group(1).splitlines()


def check_commands() -> list[list[str]]:
    """The page's `sorting-line-bag check` commands (continuation lines joined)."""
    text = DOC.read_text().replace("\\\n", " ")
    return [shlex.split(line) for line in text.splitlines() if line.startswith("sorting-line-bag check")]


def environment() -> dict[str, str]:
    bin_dir = str(Path(sys.executable).parent)
    env = dict(os.environ, **h.ros_environment(), SORTING_LINE_BIN=str(h.node_binary()))
    env["PATH"] = f"{bin_dir}:{Path(h.node_binary()).parent}:{env['PATH']}"
    return env


def test_the_pages_commands_train_export_and_drive_a_line(tmp_path, namespace):
    train, export, node, controller = deploy_block()
    env = environment()
    for line in (train.replace(*CUT), export):
        r = subprocess.run(line, shell=True, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, f"{line}\n{r.stdout}\n{r.stderr}"
    assert (tmp_path / "policy.onnx").is_file()
    ns = namespace("plant")
    node_argv = shlex.split(node.rstrip("&").replace("/plant", ns))
    controller_argv = shlex.split(controller.replace("/plant", ns))
    with open(tmp_path / "node.log", "wb") as node_log, open(tmp_path / "controller.log", "wb") as ctl_log:
        node_proc = subprocess.Popen(node_argv, cwd=tmp_path, env=env, stdout=node_log, stderr=subprocess.STDOUT)
        ctl = subprocess.Popen(controller_argv, cwd=tmp_path, env=env, stdout=ctl_log, stderr=subprocess.STDOUT)
    try:
        wait_until(
            lambda: "first decision" in (tmp_path / "controller.log").read_text(),
            60,
            "the controller's first decision",
            poll=0.5,
            context=lambda: (tmp_path / "controller.log").read_text(),
            abort=lambda: None if ctl.poll() is None else f"the controller exited with {ctl.returncode}",
        )
    finally:
        for p in (ctl, node_proc):
            p.send_signal(2)
            p.wait(timeout=15)
    log = (tmp_path / "controller.log").read_text()
    assert "first decision" in log and f"(parameters of {ns}/sorting_line)" in log, log
    assert ctl.returncode == 0, log


def test_the_pages_bag_checks_pass(namespace):
    commands = check_commands()
    assert len(commands) == 2 and any("--closed-loop" in c for c in commands), commands
    for argv in commands:
        r = subprocess.run(
            [*argv, "--namespace", namespace("check")],
            cwd=h.ROOT,
            env=environment(),
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert r.returncode == 0, f"{shlex.join(argv)}\n{r.stdout}\n{r.stderr}"
