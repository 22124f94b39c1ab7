"""A colcon workspace with this repository under src/, built by colcon from PyPI with the project's
.venv (its ROS 2 Jazzy wheels and compiled interfaces) as the underlay: the build that
tests/python/test_colcon_package.py checks, done the way docs/ros-package.md tells users to.

- colcon and its extensions (launch_scripts/requirements-colcon.txt, which says why not in .venv) live
  in a venv of their own, cached in `${SORTING_LINE_COLCON_CACHE:-~/.cache/sorting_line}/colcon-<key>`
  (key: the requirements and the interpreter) and built at most once (a lock serialises concurrent
  runs). Building it needs PyPI.
- The workspace is made anew by every build, in `$SORTING_LINE_COLCON_WS` (default: a folder in the
  temporary directory named after this checkout): `src/sorting_line` is a link to this repository and
  `build/sorting_line`, the package's cargo target directory (colcon-ros-cargo passes `--target-dir
  build/<package>`), a link to the repository's `target/`. So cargo finds setup.sh's release build
  of the same sources up to date instead of compiling the node and its dependencies again.
- Then a plain `colcon build --cargo-args --release --locked` (no --base-paths, no --paths: colcon
  must find all three packages itself), with .venv's python and cmake first on PATH and .venv as
  AMENT_PREFIX_PATH and CMAKE_PREFIX_PATH.

launch_scripts/test.sh runs `python tests/python/support/colcon_ws.py --build` in the background beside the
Rust tests, outside the tests' network namespace (PyPI); the test reads `result.json` in the
workspace. A failed build does not stop test.sh: it is recorded there, and the test fails with the log.
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
PROJECT_VENV = ROOT / ".venv"
REQUIREMENTS = ROOT / "launch_scripts" / "requirements-colcon.txt"
# The exact command the test stands for; --release and --locked as setup.sh's build, whose target/ it reuses.
COLCON_BUILD = ["colcon", "build", "--cargo-args", "--release", "--locked"]
PACKAGES = ("simulation_interfaces", "sorting_line", "sorting_line_interfaces")
TIMEOUT = 1800.0  # s, for each of the venv and the build (a busy 2-core machine; ~2 min of CPU in all)
# Variables of a ROS environment the caller may have: the build sees the underlay only.
ROS_VARIABLES = [
    "PYTHONPATH",
    "PYTHONHOME",
    "VIRTUAL_ENV",
    "AMENT_PREFIX_PATH",
    "CMAKE_PREFIX_PATH",
    "COLCON_PREFIX_PATH",
    "LD_LIBRARY_PATH",
    "_ROS_WHEELS_BOOTSTRAP_COMPLETE",
    "ROS_DISTRO",
    "ROS_VERSION",
    "ROS_PYTHON_VERSION",
    "CARGO_TARGET_DIR",
]


def workspace_dir() -> Path:
    if os.environ.get("SORTING_LINE_COLCON_WS"):
        return Path(os.environ["SORTING_LINE_COLCON_WS"])
    tag = hashlib.sha256(str(ROOT).encode()).hexdigest()[:12]
    return Path(tempfile.gettempdir()) / f"sorting_line_colcon_ws-{tag}"


def venv_dir() -> Path:
    digest = hashlib.sha256(REQUIREMENTS.read_bytes() + sys.version.encode()).hexdigest()[:16]
    base = Path(os.environ.get("SORTING_LINE_COLCON_CACHE") or Path.home() / ".cache" / "sorting_line")
    return base / f"colcon-{digest}"


def build_venv(log) -> Path:
    """The cached colcon venv, built unless it is there; raises naming its log on failure."""
    venv = venv_dir()
    venv.parent.mkdir(parents=True, exist_ok=True)
    with open(venv.parent / (venv.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if (venv / ".complete").is_file():
            print(f"colcon: cached venv {venv}", file=log, flush=True)
            return venv
        shutil.rmtree(venv, ignore_errors=True)
        build_log = venv.parent / (venv.name + ".build.log")
        t0 = time.monotonic()
        # The project venv's version (this script runs in it): the workspace builds against that venv.
        python = getattr(sys, "_base_executable", sys.executable)
        env = {k: v for k, v in os.environ.items() if k not in ROS_VARIABLES}
        with open(build_log, "wb") as out:
            for argv in (
                [python, "-m", "venv", str(venv)],
                [
                    str(venv / "bin" / "python"),
                    "-m",
                    "pip",
                    "install",
                    "--no-input",
                    "-q",
                    "--disable-pip-version-check",
                    "-r",
                    str(REQUIREMENTS),
                ],
            ):
                code = subprocess.run(
                    argv, stdout=out, stderr=subprocess.STDOUT, env=env, timeout=TIMEOUT, check=False
                ).returncode
                if code != 0:
                    tail = "\n".join(build_log.read_text(errors="replace").splitlines()[-20:])
                    raise RuntimeError(
                        f"making the colcon venv failed ({' '.join(argv)}: {code}); log {build_log}:\n{tail}"
                    )
        (venv / ".complete").write_text(f"built in {time.monotonic() - t0:.0f} s\n")
        print(f"colcon: venv {venv} built in {time.monotonic() - t0:.0f} s", file=log, flush=True)
        return venv


def build_environment(venv: Path) -> dict[str, str]:
    """The build's environment: .venv as the underlay, colcon and cargo-ament-build from `venv`."""
    env = {k: v for k, v in os.environ.items() if k not in ROS_VARIABLES}
    path = [p for p in env.get("PATH", "").split(os.pathsep) if p and not p.startswith(str(PROJECT_VENV))]
    env["PATH"] = os.pathsep.join([str(PROJECT_VENV / "bin"), str(venv / "bin"), *path])
    env["VIRTUAL_ENV"] = str(PROJECT_VENV)  # CMake's FindPython3 takes the venv's interpreter
    env["AMENT_PREFIX_PATH"] = env["CMAKE_PREFIX_PATH"] = str(PROJECT_VENV)
    return env


def make_workspace(ws: Path) -> None:
    """A new workspace: src/sorting_line -> this repository, build/sorting_line -> its target/."""
    shutil.rmtree(ws, ignore_errors=True)
    (ws / "src").mkdir(parents=True)
    (ws / "build").mkdir()
    (ws / "src" / "sorting_line").symlink_to(ROOT)
    (ROOT / "target").mkdir(exist_ok=True)
    (ws / "build" / "sorting_line").symlink_to(ROOT / "target")


def build(log=sys.stdout) -> dict:
    """Builds the workspace (and the colcon venv if needed); returns and records the result."""
    ws = workspace_dir()
    result: dict = {"workspace": str(ws), "command": " ".join(COLCON_BUILD), "log": str(ws / "build.log")}
    t0 = time.monotonic()
    try:
        venv = build_venv(log)
        result["venv_seconds"] = round(time.monotonic() - t0, 1)
        make_workspace(ws)
        t1 = time.monotonic()
        with open(ws / "build.log", "wb") as out:
            code = subprocess.run(
                [str(venv / "bin" / "colcon"), *COLCON_BUILD[1:]],
                cwd=ws,
                stdout=out,
                stderr=subprocess.STDOUT,
                env=build_environment(venv),
                timeout=TIMEOUT,
                stdin=subprocess.DEVNULL,
                check=False,
            ).returncode
        result.update(returncode=code, build_seconds=round(time.monotonic() - t1, 1))
    except (RuntimeError, OSError, subprocess.TimeoutExpired) as e:
        result.update(returncode=None, error=str(e))
    ws.mkdir(parents=True, exist_ok=True)
    (ws / "result.json").write_text(json.dumps(result, indent=1) + "\n")
    verdict = "built" if result.get("returncode") == 0 else "FAILED (tests/python/test_colcon_package.py shows why)"
    print(
        f"colcon workspace {ws}: {verdict}; venv {result.get('venv_seconds', '-')} s, "
        f"`{result['command']}` {result.get('build_seconds', '-')} s",
        file=log,
        flush=True,
    )
    return result


def load_result(ws: Path) -> dict | None:
    try:
        return json.loads((ws / "result.json").read_text())
    except (OSError, ValueError):
        return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", action="store_true", help="build the colcon venv (if needed) and the workspace")
    args = parser.parse_args()
    if not args.build:
        parser.print_help()
        return 2
    build()
    return 0


if __name__ == "__main__":
    sys.exit(main())
