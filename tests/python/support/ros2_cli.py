"""The real ROS 2 Jazzy command line (`ros2 ...`, `ros2 launch`, `launch_test`) for the tests, as a user brings it.

Where it comes from, in order:
1. `ros2` on PATH (a machine with ROS 2 Jazzy installed and sourced, or launch_scripts/ros2cli.sh's env.sh
   sourced);
2. else the venv launch_scripts/ros2cli.sh builds (the upstream ros2cli, launch and launch_ros sources on the
   pinned ros-jazzy-* wheels), cached in `${SORTING_LINE_ROS2CLI_CACHE:-~/.cache/sorting_line}/ros2cli-<key>`
   (the key: the script's stamp key, so worktrees with the same pins share it; the script's stamp and lock make
   a rebuild happen once). It is built `--from` the folder of source archives that CI keeps beside the clone:
   shared/tools/ros2cli/tarballs, shared/ found through SORTING_LINE_SHARED, else beside the repository
   (`<repo>/../shared`), else beside the main checkout of a git worktree. Never downloaded here: the tests
   run without network;
3. else the repository's own .venv-ros2cli, when `bash launch_scripts/ros2cli.sh` has built it;
4. else nothing: the CLI tests are skipped with the reason.

Building needs PyPI, and the tests run in a network namespace without it, so launch_scripts/test.sh
builds the venv before it enters the namespace (`python tests/python/support/ros2_cli.py --build`); inside
the namespace the tests only look the venv up.

The project's interfaces (sorting_line_interfaces and simulation_interfaces, compiled into .venv by setup.sh) are
made visible to the CLI through the script's overlay prefix of links to exactly the files of their install
manifests: the rest of .venv (torch, a second rclpy) stays out of the CLI's interpreter.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def _load_recipe():
    """launch_scripts/ros2cli.py as a module (a name of its own: `ros2cli` is also the upstream package)."""
    spec = importlib.util.spec_from_file_location("sorting_line_ros2cli", ROOT / "launch_scripts" / "ros2cli.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


recipe = _load_recipe()
# The project venv whose interfaces the CLI sees: the one running the tests (main's, when a worktree without
# a .venv of its own runs them), else the checkout's.
PROJECT_VENV = Path(sys.prefix) if (Path(sys.prefix) / ".sorting_line").is_dir() else (ROOT / ".venv").resolve()
INTERFACES = recipe.INTERFACES
BUILD_TIMEOUT = 2700.0  # s: the script's own steps are bounded; this bounds the whole (8 min at load 20, 2 cores)


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
        if (c / "tools" / "ros2cli" / "tarballs").is_dir():
            return c.resolve()
    return None


def archive_dir() -> Path | None:
    """The folder of the source archives of launch_scripts/ros2cli-sources.txt beside the clone, if any."""
    shared = shared_dir()
    return shared / "tools" / "ros2cli" / "tarballs" if shared else None


def venv_dir() -> tuple[Path, str]:
    """The cache location of the venv, and its stamp key (a new key, a new venv, when the pins change)."""
    key = recipe.stamp_key(sys.executable)
    base = Path(os.environ.get("SORTING_LINE_ROS2CLI_CACHE") or Path.home() / ".cache" / "sorting_line")
    return base / f"ros2cli-{key}", key


def built_venv() -> Path | None:
    """The cached venv when built, else the repository's .venv-ros2cli when built."""
    venv, key = venv_dir()
    if recipe.is_current(venv, key):
        return venv
    return recipe.DEFAULT_VENV if recipe.is_current(recipe.DEFAULT_VENV, key) else None


def build(archives: Path, log=sys.stdout) -> Path:
    """Runs launch_scripts/ros2cli.sh --from ARCHIVES into the cache (instant when current); raises on failure."""
    venv, _ = venv_dir()
    print(f"ros2 CLI: launch_scripts/ros2cli.sh --from {archives} --venv {venv}", file=log, flush=True)
    # Nothing of the project's environment may leak into the build (it makes a venv of its own).
    env = recipe.clean_environment(dict(os.environ))
    argv = ["bash", str(ROOT / "launch_scripts" / "ros2cli.sh"), "--from", str(archives), "--venv", str(venv)]
    argv += ["--interfaces-from", str(PROJECT_VENV)]
    try:
        code = subprocess.run(argv, env=env, stdout=log, stderr=subprocess.STDOUT, timeout=BUILD_TIMEOUT).returncode
    except subprocess.TimeoutExpired:
        code = f"no end within {BUILD_TIMEOUT:.0f} s"
    if code != 0:
        raise RuntimeError(f"building the ros2 CLI venv failed ({code}): the lines above say why")
    return venv


def interfaces_overlay(dest: Path, packages=INTERFACES) -> Path:
    """The script's overlay prefix of the interface packages of the project venv (see the module doc)."""
    try:
        return recipe.interfaces_overlay(dest, packages, PROJECT_VENV)
    except recipe.Failure as e:
        raise RuntimeError(str(e)) from None


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


def locate(overlay_dir: Path, log_dir: Path, interfaces=INTERFACES) -> tuple[Ros2Cli | None, str]:
    """(the CLI, where it came from) or (None, why there is none). Never builds: see build().
    `interfaces`: the packages of .venv the CLI sees (the colcon test brings its own build of one)."""
    overlay = interfaces_overlay(overlay_dir, interfaces)
    on_path = _ros2_on_path()
    if on_path:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(
            filter(None, [*map(str, sorted(overlay.glob("lib/python3*/site-packages"))), env.get("PYTHONPATH")])
        )
        env["AMENT_PREFIX_PATH"] = os.pathsep.join(filter(None, [str(overlay), env.get("AMENT_PREFIX_PATH")]))
        env["LD_LIBRARY_PATH"] = os.pathsep.join(filter(None, [str(overlay / "lib"), env.get("LD_LIBRARY_PATH")]))
        cli = Ros2Cli(on_path, env, f"ros2 on PATH ({on_path})")
    else:
        venv = built_venv()
        if venv is None:
            return None, f"no ROS 2 CLI: {describe()}"
        env = recipe.cli_environment(venv, overlay, recipe.clean_environment(dict(os.environ)))
        cli = Ros2Cli(str(venv / "bin" / "ros2"), env, f"venv {venv} (launch_scripts/ros2cli.sh)")
    cli.env["ROS_LOG_DIR"] = str(log_dir)
    return cli, cli.origin


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
    venv = built_venv()
    if venv is not None:
        return f"venv {venv}"
    if archive_dir() is None:
        return (
            "none: `ros2` is not on PATH, no folder of source archives beside the repository (looked in "
            f"$SORTING_LINE_SHARED, {ROOT.parent / 'shared'}) and no {recipe.DEFAULT_VENV.name} built by "
            "`bash launch_scripts/ros2cli.sh` (CLI tests skipped)"
        )
    return (
        f"none: {venv_dir()[0]} not built (CLI tests skipped); build it outside the test network namespace "
        f"with `python {Path(__file__).relative_to(ROOT)} --build` (launch_scripts/test.sh does)"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", action="store_true", help="build the cached venv unless ros2 is on PATH")
    args = parser.parse_args()
    if not args.build:
        parser.print_help()
        return 2
    if _ros2_on_path():
        print(f"ros2 CLI: using {_ros2_on_path()} from PATH")
        return 0
    archives = archive_dir()
    if archives is None:
        print(f"ros2 CLI: {describe()}")
        return 0
    try:
        build(archives)
    except RuntimeError as e:
        print(e, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
