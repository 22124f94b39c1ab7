"""The real ROS 2 Jazzy command line (`ros2 ...`, `ros2 launch`) for the tests, as a user brings it.

Where it comes from, in order:
1. `ros2` on PATH (a machine with ROS 2 Jazzy installed and sourced);
2. else a venv built by shared/tools/ros2cli/make_ros2cli_venv.sh (the upstream ros2cli, launch and
   launch_ros sources on the pinned ros-jazzy-* wheels). shared/ is found through SORTING_LINE_SHARED,
   else beside the repository (`<repo>/../shared`, as in CI and in worktrees under /work), else beside
   the main checkout of a git worktree. The venv is cached in
   `${SORTING_LINE_ROS2CLI_CACHE:-~/.cache/sorting_line}/ros2cli-<key>`, keyed on the tool's files and
   the interpreter, and built at most once (a lock serialises concurrent runs);
3. else nothing: the CLI tests are skipped with the reason.

Building needs PyPI, and the tests run in a network namespace without it, so launch_scripts/test.sh
builds the venv before it enters the namespace (`python tests/python/ros2_cli.py --build`); inside
the namespace the tests only look the venv up.

The project's interfaces (sorting_line_interfaces and simulation_interfaces, compiled into .venv by setup.sh) are made
visible to the CLI through an overlay prefix of symbolic links to exactly the files of their install
manifest, put on PYTHONPATH / AMENT_PREFIX_PATH / LD_LIBRARY_PATH: the rest of .venv (torch, a second
rclpy) stays out of the CLI's interpreter.
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PROJECT_VENV = (ROOT / ".venv").resolve()  # (a symbolic link in a git worktree)
# What launch_scripts/setup.sh compiled into .venv (the standard's simulation_interfaces too: no wheel has it).
INTERFACES = ("sorting_line_interfaces", "simulation_interfaces")
BUILD_TIMEOUT = 900.0  # s; docs/ros-without-a-ros-install.md says ~45 s on a quiet machine


def shared_dir() -> Path | None:
    """The shared/ folder next to the repository (or named by SORTING_LINE_SHARED)."""
    candidates = []
    if os.environ.get("SORTING_LINE_SHARED"):
        candidates.append(Path(os.environ["SORTING_LINE_SHARED"]))
    candidates.append(ROOT.parent / "shared")
    try:  # a git worktree: shared/ sits beside the main checkout
        common = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--path-format=absolute", "--git-common-dir"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        if common:
            candidates.append(Path(common).parent.parent / "shared")
    except (OSError, subprocess.TimeoutExpired):
        pass
    for c in candidates:
        if (c / "tools" / "ros2cli" / "make_ros2cli_venv.sh").is_file():
            return c.resolve()
    return None


def tool_dir() -> Path | None:
    shared = shared_dir()
    return shared / "tools" / "ros2cli" if shared else None


def venv_dir(tools: Path) -> Path:
    """The cache location of the venv built from `tools` (a new key when the tool changes)."""
    digest = hashlib.sha256()
    for name in ["make_ros2cli_venv.sh", "ros2cli_env.sh", "tarballs/SHA256SUMS"]:
        digest.update((tools / name).read_bytes())
    digest.update(sys.version.encode())
    base = Path(os.environ.get("SORTING_LINE_ROS2CLI_CACHE") or Path.home() / ".cache" / "sorting_line")
    return base / f"ros2cli-{digest.hexdigest()[:16]}"


def built(venv: Path) -> bool:
    return (venv / ".complete").is_file() and (venv / "bin" / "ros2").is_file()


def build(tools: Path, log=sys.stdout) -> Path:
    """Builds the venv unless the cache has it; returns its path. Raises naming the log on failure."""
    venv = venv_dir(tools)
    venv.parent.mkdir(parents=True, exist_ok=True)
    with open(venv.parent / (venv.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if built(venv):
            print(f"ros2 CLI: cached venv {venv}", file=log, flush=True)
            return venv
        build_log = venv.parent / (venv.name + ".build.log")
        print(f"ros2 CLI: building {venv} with {tools}/make_ros2cli_venv.sh (log {build_log})", file=log, flush=True)
        t0 = time.monotonic()
        env = dict(os.environ, ROS2CLI_VENV=str(venv), PYTHON=shutil.which("python3.11") or sys.executable)
        # Nothing of the project's environment may leak into the build (it makes a venv of its own).
        for k in [
            "VIRTUAL_ENV",
            "PYTHONPATH",
            "AMENT_PREFIX_PATH",
            "CMAKE_PREFIX_PATH",
            "LD_LIBRARY_PATH",
            "_ROS_WHEELS_BOOTSTRAP_COMPLETE",
            "PYTHONHOME",
        ]:
            env.pop(k, None)
        env["PATH"] = os.pathsep.join(
            p for p in env.get("PATH", "").split(os.pathsep) if not p.startswith(str(PROJECT_VENV))
        )
        with open(build_log, "wb") as out:
            try:
                r = subprocess.run(
                    ["bash", str(tools / "make_ros2cli_venv.sh")],
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    env=env,
                    timeout=BUILD_TIMEOUT,
                )
                code = r.returncode
            except subprocess.TimeoutExpired:
                code = f"timeout after {BUILD_TIMEOUT:.0f} s"
        if code != 0:
            tail = "\n".join(build_log.read_text(errors="replace").splitlines()[-25:])
            raise RuntimeError(f"building the ros2 CLI venv failed ({code}); log {build_log}:\n{tail}")
        (venv / ".complete").write_text(f"built in {time.monotonic() - t0:.0f} s\n")
        print(f"ros2 CLI: built in {time.monotonic() - t0:.0f} s", file=log, flush=True)
        return venv


def interfaces_overlay(dest: Path, packages=INTERFACES) -> Path:
    """A prefix holding links to the interface packages' installed files only (see the module doc)."""
    manifests = [PROJECT_VENV / ".sorting_line" / f"{package}_install_manifest.txt" for package in packages]
    missing = [m for m in manifests if not m.is_file()]
    if missing:
        raise RuntimeError(f"{', '.join(map(str, missing))} missing: run launch_scripts/setup.sh first")
    for line in (line for m in manifests for line in m.read_text().splitlines()):
        src = Path(line.strip())
        if not line.strip() or not src.exists():
            continue
        rel = src.relative_to(PROJECT_VENV)
        link = dest / rel
        link.parent.mkdir(parents=True, exist_ok=True)
        if not link.is_symlink():
            link.symlink_to(src)
    return dest


@dataclass
class Ros2Cli:
    """How to run `ros2`: the executable and the environment it needs (a full copy of os.environ)."""

    executable: str
    env: dict[str, str] = field(repr=False)
    origin: str = ""

    def argv(self, *args: str) -> list[str]:
        return [self.executable, *[str(a) for a in args]]

    def run(
        self, *args: str, timeout: float = 30.0, check: bool = True, input: str | None = None
    ) -> subprocess.CompletedProcess:
        """Runs `ros2 ARGS` (bounded); with `check`, a non-zero exit fails naming the command and output."""
        argv = self.argv(*args)
        try:
            r = subprocess.run(
                argv,
                capture_output=True,
                text=True,
                env=self.env,
                timeout=timeout,
                input=input,
                stdin=None if input is not None else subprocess.DEVNULL,
            )
        except subprocess.TimeoutExpired as e:
            out = (e.stdout or b"").decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
            err = (e.stderr or b"").decode(errors="replace") if isinstance(e.stderr, bytes) else (e.stderr or "")
            raise AssertionError(
                f"`ros2 {' '.join(argv[1:])}` did not finish within {timeout} s\n"
                f"--- stdout ---\n{out}\n--- stderr ---\n{err}"
            ) from None
        if check and r.returncode != 0:
            raise AssertionError(
                f"`ros2 {' '.join(argv[1:])}` exited with {r.returncode}\n"
                f"--- stdout ---\n{r.stdout}\n--- stderr ---\n{r.stderr}"
            )
        return r


def _venv_env(venv: Path) -> dict[str, str]:
    """The variables ros2cli_env.sh sets, computed here (the project's .venv removed from PATH)."""
    env = dict(os.environ)
    for k in ["VIRTUAL_ENV", "PYTHONHOME", "PYTHONPATH", "AMENT_PREFIX_PATH", "LD_LIBRARY_PATH"]:
        env.pop(k, None)
    path = [p for p in env.get("PATH", "").split(os.pathsep) if p and not p.startswith(str(PROJECT_VENV))]
    env["PATH"] = os.pathsep.join([str(venv / "bin"), *path])
    env["VIRTUAL_ENV"] = str(venv)
    env["AMENT_PREFIX_PATH"] = str(venv)
    libs = [str(venv / "lib")] + sorted(
        str(d) for d in venv.glob("lib/python3*/site-packages/ros_*.libs") if d.is_dir()
    )
    env["LD_LIBRARY_PATH"] = os.pathsep.join(libs)
    env["_ROS_WHEELS_BOOTSTRAP_COMPLETE"] = "1"
    env.update(ROS_DISTRO="jazzy", ROS_VERSION="2", ROS_PYTHON_VERSION="3", PYTHONUNBUFFERED="1")
    return env


def locate(overlay_dir: Path, log_dir: Path, interfaces=INTERFACES) -> tuple[Ros2Cli | None, str]:
    """(the CLI, where it came from) or (None, why there is none). Never builds: see build().
    `interfaces`: the packages of .venv the CLI sees (the colcon test brings its own build of one)."""
    on_path = _ros2_on_path()
    if on_path:
        cli, origin = Ros2Cli(on_path, dict(os.environ)), f"ros2 on PATH ({on_path})"
    else:
        tools = tool_dir()
        if tools is None:
            return None, (
                "no ROS 2 CLI: `ros2` is not on PATH and shared/tools/ros2cli was not found "
                f"(looked in $SORTING_LINE_SHARED, {ROOT.parent / 'shared'})"
            )
        venv = venv_dir(tools)
        if not built(venv):
            return None, (
                f"no ROS 2 CLI: the venv {venv} from {tools} is not built; build it outside the test "
                f"network namespace with `python {Path(__file__).relative_to(ROOT)} --build` "
                "(launch_scripts/test.sh does)"
            )
        cli, origin = Ros2Cli(str(venv / "bin" / "ros2"), _venv_env(venv)), f"venv {venv} built from {tools}"
    overlay = interfaces_overlay(overlay_dir, interfaces)
    env = cli.env
    env["PYTHONPATH"] = os.pathsep.join(
        filter(None, [str(overlay / "lib/python3.11/site-packages"), env.get("PYTHONPATH")])
    )
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(filter(None, [str(overlay), env.get("AMENT_PREFIX_PATH")]))
    env["LD_LIBRARY_PATH"] = os.pathsep.join(filter(None, [str(overlay / "lib"), env.get("LD_LIBRARY_PATH")]))
    env["ROS_LOG_DIR"] = str(log_dir)
    return cli, origin


def _ros2_on_path() -> str | None:
    return shutil.which(
        "ros2",
        path=os.pathsep.join(
            p for p in os.environ.get("PATH", "").split(os.pathsep) if p and not p.startswith(str(PROJECT_VENV))
        ),
    )


def describe() -> str:
    """Where the CLI comes from, or why the CLI tests will be skipped (for the test report header)."""
    if _ros2_on_path():
        return f"ros2 on PATH ({_ros2_on_path()})"
    tools = tool_dir()
    if tools is None:
        return "none: not on PATH and no shared/tools/ros2cli beside the repository (CLI tests skipped)"
    venv = venv_dir(tools)
    return f"venv {venv}" if built(venv) else f"none: {venv} not built (CLI tests skipped; see ros2_cli.py --build)"


def run_cli(args: list[str]) -> int:
    """Runs `ros2 ARGS` in this terminal, as the tests run it (for users without a ROS install)."""
    import tempfile

    scratch = Path(tempfile.mkdtemp(prefix="sorting_line_ros2cli_"))
    cli, origin = locate(scratch / "overlay", scratch / "log")
    if cli is None:
        print(origin, file=sys.stderr)
        return 2
    try:
        return subprocess.run(cli.argv(*args), env=cli.env).returncode
    except KeyboardInterrupt:
        return 130


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", action="store_true", help="build the cached venv unless ros2 is on PATH")
    parser.add_argument(
        "--run",
        nargs=argparse.REMAINDER,
        metavar="ARGS",
        help="run `ros2 ARGS` with the project's interfaces (after --build), e.g. --run topic list",
    )
    args = parser.parse_args()
    if args.run is not None:
        return run_cli(args.run)
    if not args.build:
        parser.print_help()
        return 2
    if _ros2_on_path():
        print(f"ros2 CLI: using {_ros2_on_path()} from PATH")
        return 0
    tools = tool_dir()
    if tools is None:
        print("ros2 CLI: shared/tools/ros2cli not found beside the repository: the CLI tests will be skipped")
        return 0
    try:
        build(tools)
    except RuntimeError as e:
        print(e, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
