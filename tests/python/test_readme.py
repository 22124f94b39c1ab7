"""The README's first screen runs as written: its quickstart snippets are taken from the README itself and run.

Each snippet is the fenced block right after a `<!-- readme-test: NAME -->` marker: `ros-shell` (the node's command
and `ros2 topic echo`), `ros-controller` (a user's rclpy controller, run against that node), `gymnasium` (an
episode) and `ppo` (SB3 PPO, its budget cut to four rollouts of 64 steps). Everything runs in a ROS domain of its
own, derived from the test's, because the quickstart uses the root namespace. About 25 s in all on a quiet machine
(at load 14 on 2 cores: 60 s), mostly importing torch and SB3. Also: every relative link of README.md, CONTRIBUTING.md,
docs/ (docs/results/ included) and vendor/'s pages resolves, and the docs' indexes list every page.
"""

from __future__ import annotations

import dataclasses
import os
import re
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from support import ros2_cli
from support.training_stack import needs_training

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
FIRST_SCREEN = 60
MARKERS = ("ros-shell", "ros-controller", "gymnasium", "ppo")


def snippet(name: str) -> str:
    """The fenced block right after `<!-- readme-test: NAME -->`."""
    match = re.search(rf"<!-- readme-test: {re.escape(name)} -->\n```\w*\n(.*?)\n```", README.read_text(), re.S)
    assert match, f"README.md has no fenced block after <!-- readme-test: {name} -->"
    return match.group(1)


def quickstart_domain() -> str:
    """A domain id of its own (within 100..199), derived from the test's."""
    base = int(os.environ.get("ROS_DOMAIN_ID", "100"))
    return str(100 + (base - 100 + 37) % 100)


def shell_command(program: str) -> list[str]:
    """The argv of the ros-shell snippet's line that runs `program` (its comment dropped)."""
    for line in snippet("ros-shell").splitlines():
        argv = shlex.split(line, comments=True)
        if argv and argv[0] == program:
            return argv
    raise AssertionError(f"the README's ros-shell snippet has no `{program}` line")


def run_python(code: str, tmp_path: Path, name: str, timeout: float) -> subprocess.CompletedProcess:
    script = tmp_path / name
    script.write_text(code)
    env = dict(os.environ, ROS_DOMAIN_ID=quickstart_domain())
    try:
        done = subprocess.run(
            [sys.executable, script.name], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired as e:
        why = f"{name} (from the README) did not finish within {timeout} s\n{e.stdout}\n{e.stderr}"
        raise AssertionError(why) from None
    assert done.returncode == 0, f"{name} (from the README) exited with {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done


def test_first_screen_holds_prerequisites_commands_and_quickstarts():
    first = "\n".join(README.read_text().splitlines()[:FIRST_SCREEN])
    for needed in ("Prerequisites", "launch_scripts/run.sh", "launch_scripts/test.sh", "Python 3.11", "root"):
        assert needed in first, f"the README's first {FIRST_SCREEN} lines do not mention {needed!r}"
    rust = tomllib.loads((ROOT / "Cargo.toml").read_text())["package"]["rust-version"]
    assert f"Rust >= {rust}" in first, f"the README's first screen must state Cargo.toml's rust-version {rust}"
    for name in MARKERS:
        assert snippet(name) in first, f"the {name} quickstart is not within the README's first {FIRST_SCREEN} lines"


@pytest.fixture
def quickstart_node(start_node):
    argv = shell_command("sorting_line")
    assert argv[1] == "node", argv
    return start_node(*argv[2:], env={"ROS_DOMAIN_ID": quickstart_domain()})


def test_ros_controller_drives_the_node(quickstart_node, tmp_path):
    done = run_python(snippet("ros-controller"), tmp_path, "my_controller.py", timeout=90.0)
    steps = re.findall(r"step +\d+ speed (\d\.\d) accuracy [\d.]+ reward [+-][\d.]+", done.stdout)
    assert len(steps) == 20, done.stdout
    # The node starts at speed 0.6 and holds it without valid commands: other speeds are the controller's.
    assert len(set(steps)) > 1, f"the speed never changed: the controller's commands had no effect\n{done.stdout}"
    assert quickstart_node.running(), quickstart_node.describe()


def test_ros2_topic_echo_shows_rewards(quickstart_node, ros2):
    argv = shell_command("ros2")
    cli = dataclasses.replace(ros2, env=dict(ros2.env, ROS_DOMAIN_ID=quickstart_domain()))
    try:
        out = cli.run(*argv[1:], "--once", timeout=60.0).stdout
    finally:  # the echo started a daemon in this domain: it would outlive the suite
        cli.run("daemon", "stop", timeout=30, check=False)
    assert re.search(r"^-?\d+\.\d+$", out, re.M), f"`{' '.join(argv)} --once` printed no reward:\n{out}"


def test_the_cli_line_makes_an_env_script_that_runs_ros2(quickstart_node, ros2):
    """The README's line that builds the ros2 CLI and sources its env.sh, run as written but on the CLI venv the
    tests use (current, so the build is instant), then its `ros2 topic echo` in that shell: the second terminal."""
    lines = [line for line in snippet("ros-shell").splitlines() if "launch_scripts/ros2cli.sh" in line]
    assert len(lines) == 1, (
        "the README's ros-shell snippet needs one line that builds the CLI: launch_scripts/ros2cli.sh"
    )
    venv = ros2_cli.built_venv()
    if ros2.origin.startswith("ros2 on PATH") or venv is None:
        pytest.skip(f"the CLI is not one launch_scripts/ros2cli.sh built: {ros2.origin}")
    command = lines[0].split("#")[0].strip()
    default = ros2_cli.recipe.DEFAULT_VENV.relative_to(ROOT)
    assert f"source {default}/env.sh" in command, f"the README's CLI line must source {default}/env.sh: {command}"
    own = f"launch_scripts/ros2cli.sh --venv {venv} --interfaces-from {ros2_cli.PROJECT_VENV}"
    command = command.replace("launch_scripts/ros2cli.sh", own).replace(f"{default}/env.sh", f"{venv}/env.sh")
    echo = shlex.join([*shell_command("ros2"), "--once"])
    env = dict(os.environ, ROS_DOMAIN_ID=quickstart_domain(), ROS_LOG_DIR=ros2.env["ROS_LOG_DIR"])
    # The echo starts a daemon in its domain: it would outlive the suite.
    script = f"set -e; {command}; set +e; {echo}; status=$?; ros2 daemon stop >/dev/null 2>&1; exit $status"
    try:
        done = subprocess.run(["bash", "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired as e:
        raise AssertionError(f"the README's CLI lines did not finish within 120 s\n{e.stdout}\n{e.stderr}") from None
    assert done.returncode == 0, f"`{script}` exited with {done.returncode}\n{done.stdout}\n{done.stderr}"
    assert "is up to date" in done.stdout, done.stdout
    assert re.search(r"^-?\d+\.\d+$", done.stdout, re.M), f"`{echo}` printed no reward:\n{done.stdout}"


def test_gymnasium_episode(tmp_path):
    done = run_python(snippet("gymnasium"), tmp_path, "episode.py", timeout=120.0)
    assert re.search(r"episode reward -?\d+\.\d\d, purity \d\.\d{3}", done.stdout), done.stdout


@needs_training
def test_ppo(tmp_path):
    # A tiny budget: 4 rollouts of 64 steps instead of the snippet's 20,000 steps in rollouts of 2,048.
    code, budget = re.subn(r"total_timesteps=[\d_]+", "total_timesteps=256", snippet("ppo"))
    code, rollout = re.subn(r'PPO\("MlpPolicy", env, ', 'PPO("MlpPolicy", env, n_steps=64, batch_size=64, ', code)
    assert (budget, rollout) == (1, 1), 'the README\'s PPO snippet must make PPO("MlpPolicy", env, ...) and learn()'
    done = run_python(code, tmp_path, "ppo.py", timeout=300.0)
    assert "total_timesteps" in done.stdout, f"SB3 reported no training progress\n{done.stdout}\n{done.stderr}"


def _slug(heading: str) -> str:
    """A heading's anchor as GitHub makes it."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(text: str) -> set[str]:
    return {_slug(h) for h in re.findall(r"^#+ (.*)$", text, re.M)}


#: Each command the README gives (every line of its sh blocks, and the commands it names in running text: set-up,
#: env.sh, pip), with where it runs: a file and the text in it that runs that command. A command added to the
#: README needs a line here, and so something that runs it; one that cannot run in CI says why in the README.
RUN_BY = {
    "launch_scripts/run.sh": [("tests/python/test_run_sh.py", 'RUN = ROOT / "launch_scripts" / "run.sh"')],
    "launch_scripts/test.sh": [(".ci/run", "exec bash launch_scripts/test.sh")],
    "launch_scripts/setup.sh": [("launch_scripts/test.sh", "bash launch_scripts/setup.sh --no-cargo")],
    "launch_scripts/setup.sh --train": [("launch_scripts/test.sh", "bash launch_scripts/setup.sh --train")],
    "source launch_scripts/env.sh": [("launch_scripts/test.sh", "source launch_scripts/env.sh")],
    "pip install ./bridge": [("tests/python/test_wheel.py", '"wheel", "--no-deps", "--no-build-isolation"')],
    # The deploy lines are the first steps of docs/deploying-a-policy.md's deploy block, which its test runs.
    "sorting-line-export models/ppo_B_advanced_seed42.zip --out policy.onnx": [
        ("docs/deploying-a-policy.md", "\nsorting-line-export models/ppo_B_advanced_seed42.zip --out policy.onnx\n"),
        ("tests/python/test_deploying_a_policy.py", "train, export, node, controller = deploy_block()"),
    ],
    "sorting-line-controller --policy policy.onnx --ros-args -r __ns:=/plant": [
        ("docs/deploying-a-policy.md", "\nsorting-line-controller --policy policy.onnx --ros-args -r __ns:=/plant\n"),
        ("tests/python/test_deploying_a_policy.py", "controller_argv = shlex.split(controller"),
    ],
    "sorting_line node --setup A --mode realtime --rate 10": [
        ("tests/python/test_readme.py", 'shell_command("sorting_line")')
    ],
    "bash launch_scripts/ros2cli.sh && source .venv-ros2cli/env.sh": [
        ("tests/python/test_readme.py", '"launch_scripts/ros2cli.sh" in line]')
    ],
    "ros2 topic echo /state --field reward": [("tests/python/test_readme.py", 'argv = shell_command("ros2")')],
    "python my_controller.py": [
        ("tests/python/test_readme.py", 'snippet("ros-controller"), tmp_path, "my_controller.py"')
    ],
    # Hours long: CI runs its tests at a reduced size, which the README says.
    "launch_scripts/reliability.sh": [("README.md", "CI runs them reduced")],
}


def readme_commands() -> list[str]:
    """The commands of README.md: each line of its sh blocks (comment dropped), then those in running text."""
    text = README.read_text()
    commands = [
        " ".join(shlex.split(line, comments=True))
        for block in re.findall(r"```sh\n(.*?)\n```", text, re.S)
        for line in block.splitlines()
        if shlex.split(line, comments=True)
    ]
    return commands + re.findall(r"`(launch_scripts/[\w.-]+\.sh[^`]*|source [^`]+|pip install [^`]+)`", text)


def test_every_readme_command_is_run_by_a_test():
    commands = readme_commands()
    assert "launch_scripts/run.sh" in commands and "python my_controller.py" in commands, commands
    missing = sorted(set(commands) - set(RUN_BY))
    assert not missing, f"README commands nothing runs (add each to RUN_BY with the test that runs it): {missing}"
    assert not set(RUN_BY) - set(commands), (
        f"RUN_BY names commands the README no longer has: {set(RUN_BY) - set(commands)}"
    )
    for command, places in RUN_BY.items():
        for path, evidence in places:
            assert evidence in (ROOT / path).read_text(), f"{path} no longer runs `{command}` (no {evidence!r} in it)"


def test_links_in_readme_and_docs_resolve():
    """Every relative link of README.md, CONTRIBUTING.md, docs/'s pages (docs/results/'s too) and vendor/'s pages (the
    patches and their upstream reports) names a file that exists (and a heading that exists)."""
    broken = []
    vendor = [ROOT / "vendor" / "README.md", *sorted((ROOT / "vendor" / "upstream-reports").glob("*.md"))]
    for page in [README, ROOT / "CONTRIBUTING.md", *sorted((ROOT / "docs").rglob("*.md")), *vendor]:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if target.startswith(("http://", "https://", "mailto:")):
                continue
            path, _, anchor = target.partition("#")
            linked = (page.parent / path) if path else page
            if not linked.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and linked.suffix == ".md":
                linked_text = re.sub(r"```.*?```", "", linked.read_text(), flags=re.S)
                if anchor not in _anchors(linked_text):
                    broken.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert not broken, "broken links:\n" + "\n".join(broken)


def _linked_pages(index: Path) -> set[Path]:
    """The pages (.md) an index page links, resolved."""
    targets = re.findall(r"\]\(([^)#\s]+\.md)(?:#[^)]*)?\)", index.read_text())
    return {(index.parent / target).resolve() for target in targets}


def test_the_docs_index_lists_every_doc():
    """docs/README.md (the index: where each user starts, every file by subject) links every page of docs/ and the
    results' index; docs/results/README.md (what each results page measured, the command that reproduces it) links
    every page of docs/results/."""
    results_index = ROOT / "docs" / "results" / "README.md"
    for index in (ROOT / "docs" / "README.md", results_index):
        pages = {p.resolve() for p in index.parent.glob("*.md")} - {index.resolve()}
        missing = sorted(str(p.relative_to(ROOT)) for p in pages - _linked_pages(index))
        assert not missing, f"{index.relative_to(ROOT)} does not list: {missing}"
    assert results_index.resolve() in _linked_pages(ROOT / "docs" / "README.md"), (
        "docs/README.md does not link the results' index, results/README.md"
    )


def _keyword_table() -> dict[str, str]:
    """The README's table of the Gymnasium ids' keyword arguments: each keyword its row names (the
    backticked names before any parenthesis) -> that row's default cell."""
    table = README.read_text().split("| kwarg | default | allowed |", 1)[1].split("\n\n", 1)[0]
    rows = {}
    for line in table.strip().splitlines()[1:]:
        names, default = line.strip("|").split("|")[:2]
        for name in re.findall(r"`(\w+)`", re.sub(r"\(.*?\)", "", names)):
            rows[name] = default
    return rows


def test_keyword_table_is_the_envs_keywords():
    """The README's keyword table names exactly the keywords the Gymnasium ids take (the faces'
    ``keywords.Keywords`` and the entry points' ``backend``), each with its defaults."""
    import inspect

    from sorting_line_gym.envs import backends, env, evolving

    faces = [env.KEYWORDS, evolving.KEYWORDS]
    defaults: dict[str, set[object]] = {"backend": {inspect.signature(backends.line_env).parameters["backend"].default}}
    for face in faces:
        for name in face.allowed:
            own = face.own.get(name)
            defaults.setdefault(name, set()).add(own.default if own else face.defaults[name])
    table = _keyword_table()
    assert sorted(table) == sorted(defaults), "README.md's keyword table and the envs' keywords differ"
    for name, values in defaults.items():
        for value in values - {None}:
            shown = f'`"{value}"`' if isinstance(value, str) else str(value)
            assert shown in table[name], f"README.md's default of {name} ({table[name].strip()}) lacks {shown}"
