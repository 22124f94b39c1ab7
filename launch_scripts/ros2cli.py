"""Builds the ROS 2 Jazzy command line (`ros2 ...`, `ros2 launch`, `launch_test`) into a venv of its own.

Run it through launch_scripts/ros2cli.sh (which picks the interpreter); `--help` lists the options.

No wheel has ros2cli, launch, launch_ros, launch_testing or rosidl_runtime_py for Jazzy, so this installs them
from their upstream source archives (launch_scripts/ros2cli-sources.txt: version, commit and SHA-256 of each)
on top of the project's pinned ROS wheels (launch_scripts/requirements-ros2cli.txt), and compiles
composition_interfaces (from rcl_interfaces; `import launch_ros.actions` needs it) with CMake, as setup.sh
compiles the project's interfaces. The archives come from a folder (`--from DIR`) or are downloaded; either way
each is checked against its SHA-256 before anything is unpacked.

The venv gets an `env.sh` to source: the CLI on PATH, its ament prefix and libraries, and the project's
interfaces of .venv (sorting_line_interfaces, simulation_interfaces) through an overlay prefix of links to
exactly the files of their install manifests, so the rest of .venv (torch, a second rclpy) stays out.

A stamp keyed on the manifest, the requirements, the recipe and the interpreter makes a rerun instant; a lock
serialises concurrent runs. tests/python/support/ros2_cli.py imports this module: one implementation for both.
Python rather than bash because of that, and for readable checks and error messages without a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "launch_scripts" / "ros2cli-sources.txt"
REQUIREMENTS = ROOT / "launch_scripts" / "requirements-ros2cli.txt"
DEFAULT_VENV = ROOT / ".venv-ros2cli"
PROJECT_VENV = ROOT / ".venv"
# What launch_scripts/setup.sh compiles into .venv, made visible to the CLI.
INTERFACES = ("sorting_line_interfaces", "simulation_interfaces")
STAMP = ".ros2cli.stamp"
OVERLAY = "project-interfaces"
# The source folders installed with pip, relative to each archive's top folder.
PACKAGES = {
    "rosidl_runtime_py": ["."],
    "ros2cli": [
        "ros2cli",
        "ros2topic",
        "ros2node",
        "ros2param",
        "ros2service",
        "ros2interface",
        "ros2pkg",
        "ros2run",
        "ros2action",
        "ros2lifecycle",
        "ros2multicast",
    ],
    "launch": ["launch", "launch_xml", "launch_yaml", "launch_testing", "launch_pytest"],
    "launch_ros": ["launch_ros", "ros2launch", "launch_testing_ros"],
}
# Bump when the build below changes in a way that needs existing venvs rebuilt.
RECIPE = 1
COMPILED = ("rcl_interfaces", "composition_interfaces")  # archive, package folder built with CMake
PIP_TIMEOUT = 1800.0  # s: a cold pip cache on a loaded machine
CMAKE_TIMEOUT = 1200.0  # s: composition_interfaces, 2.5 to 3 min at load 17 to 21 on 2 cores
DOWNLOAD_TIMEOUT = 120.0  # s per archive


class Failure(Exception):
    """A problem the user can act on: printed as one message, exit code 1, no traceback."""


@dataclass(frozen=True)
class Source:
    """One upstream archive of the manifest."""

    name: str
    version: str
    commit: str
    sha256: str
    files_sha256: str
    url: str

    @property
    def filename(self) -> str:
        return f"{self.name}-{self.version}.tar.gz"


def read_manifest(path: Path = MANIFEST) -> list[Source]:
    sources = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) != 6:
            raise Failure(f"{path}:{number}: expected NAME VERSION COMMIT SHA256 FILES_SHA256 URL, got {line!r}")
        sources.append(Source(*fields))
    return sources


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def archive_commit(path: Path) -> str:
    """The commit an archive of `git archive` (GitHub's too) says it holds, from its pax header."""
    try:
        with tarfile.open(path) as archive:
            return archive.pax_headers.get("comment", "none recorded")
    except (tarfile.TarError, OSError) as e:
        return f"unreadable ({e})"


def files_sha256(path: Path) -> str:
    """The digest of an archive's contents, independent of its top folder's name and of its compression:
    every file's path below the top folder, executable bit and SHA-256 (links: path and target), sorted."""
    entries = []
    with tarfile.open(path) as archive:
        for member in archive:
            relative = member.name.partition("/")[2].rstrip("/")
            if not relative:
                continue  # the top folder itself, or the pax header
            if member.isfile():
                content = hashlib.sha256(archive.extractfile(member).read()).hexdigest()
                entries.append((relative, "x" if member.mode & 0o111 else "f", content))
            elif member.issym():
                entries.append((relative, "l", member.linkname))
    digest = hashlib.sha256()
    for entry in sorted(entries):
        digest.update(("\0".join(entry) + "\n").encode())
    return digest.hexdigest()


def archive_problem(path: Path, source: Source, downloaded: bool) -> str | None:
    """Why `path` is not the pinned archive of `source`, or None. A download may also match by its contents."""
    if not path.is_file():
        return f"{path}: missing"
    actual = sha256_of(path)
    if actual == source.sha256:
        return None
    files = "unreadable"
    if downloaded:
        try:
            files = files_sha256(path)
        except (tarfile.TarError, OSError) as e:
            files = f"unreadable ({e})"
        if files == source.files_sha256:
            return None
    problem = f"{path}: SHA-256 {actual}, the manifest says {source.sha256}"
    if downloaded:
        problem += f"; contents {files}, the manifest says {source.files_sha256}"
    return problem + (
        f" (the archive says it holds commit {archive_commit(path)}; "
        f"{source.name} {source.version} is commit {source.commit})"
    )


def verify(folder: Path, sources: list[Source], downloaded: bool = False) -> list[Path]:
    """The archives of `folder`, each checked against the manifest; raises naming every missing or wrong one.
    A folder's archives must be the pinned ones byte for byte; a download (`downloaded`) may instead hold the
    same files under another top folder (GitHub's NAME-VERSION/)."""
    problems = [archive_problem(folder / s.filename, s, downloaded) for s in sources]
    problems = [p for p in problems if p]
    if problems:
        raise Failure(f"source archives do not match {MANIFEST.name}:\n  " + "\n  ".join(problems))
    return [folder / s.filename for s in sources]


def download(sources: list[Source], folder: Path, say) -> None:
    for source in sources:
        say(f"downloading {source.url}")
        try:
            with urllib.request.urlopen(source.url, timeout=DOWNLOAD_TIMEOUT) as response:
                (folder / source.filename).write_bytes(response.read())
        except OSError as e:
            raise Failure(
                f"downloading {source.filename} from {source.url} failed ({e}); "
                "without network, give a folder of the archives with --from DIR"
            ) from None


def stamp_key(python: str) -> str:
    """What the venv is built from: a change of any of it builds the venv again."""
    digest = hashlib.sha256(f"recipe={RECIPE}\n".encode())
    for source in read_manifest():  # the pins, not the comments
        digest.update(f"{source.name} {source.version} {source.files_sha256}\n".encode())
    for path in (REQUIREMENTS, ROOT / "launch_scripts" / "requirements-ros.txt"):
        digest.update(path.read_bytes())
    version = subprocess.run(
        [python, "-c", "import sys; print(sys.version)"], capture_output=True, text=True, timeout=60
    ).stdout
    digest.update(version.encode())
    return digest.hexdigest()[:16]


def is_current(venv: Path, key: str | None = None) -> bool:
    """Whether `venv` holds a complete build (of `key`, when given)."""
    stamp = venv / STAMP
    if not stamp.is_file() or not (venv / "bin" / "ros2").is_file():
        return False
    return key is None or stamp.read_text().split()[:1] == [key]


def clean_environment(base: dict[str, str]) -> dict[str, str]:
    """`base` without any Python or ROS environment (the checkout's .venv off PATH), for the build and the CLI."""
    env = dict(base)
    project_bin = (PROJECT_VENV / "bin").resolve()
    for name in [
        "VIRTUAL_ENV",
        "PYTHONHOME",
        "PYTHONPATH",
        "AMENT_PREFIX_PATH",
        "CMAKE_PREFIX_PATH",
        "COLCON_PREFIX_PATH",
        "LD_LIBRARY_PATH",
        "_ROS_WHEELS_BOOTSTRAP_COMPLETE",
    ]:
        env.pop(name, None)
    env["PATH"] = os.pathsep.join(
        p for p in env.get("PATH", "").split(os.pathsep) if p and Path(p).resolve() != project_bin
    )
    return env


def cli_variables(venv: Path, overlay: Path | None) -> list[tuple[str, str, bool]]:
    """The variables the CLI needs: (name, value, prepended to the caller's value)."""
    libs = [str(venv / "lib")] + sorted(str(d) for d in venv.glob("lib/python3*/site-packages/ros_*.libs"))
    prefixes = [str(venv)]
    pythonpath = []
    if overlay is not None:
        prefixes.insert(0, str(overlay))
        libs.insert(0, str(overlay / "lib"))
        # The overlay mirrors the project venv: lib/pythonX.Y of its version (the CLI venv's, checked).
        pythonpath += [str(d) for d in sorted(overlay.glob("lib/python3*/site-packages"))]
    variables = [
        ("VIRTUAL_ENV", str(venv), False),
        ("PATH", str(venv / "bin"), True),
        ("AMENT_PREFIX_PATH", os.pathsep.join(prefixes), True),
        ("LD_LIBRARY_PATH", os.pathsep.join(libs), True),
        # The wheels' .pth re-executes every Python once to set LD_LIBRARY_PATH: done above already.
        ("_ROS_WHEELS_BOOTSTRAP_COMPLETE", "1", False),
        ("ROS_DISTRO", "jazzy", False),
        ("ROS_VERSION", "2", False),
        ("ROS_PYTHON_VERSION", "3", False),
        ("PYTHONUNBUFFERED", "1", False),
    ]
    if pythonpath:
        variables.append(("PYTHONPATH", os.pathsep.join(pythonpath), True))
    return variables


def cli_environment(venv: Path, overlay: Path | None, base: dict[str, str]) -> dict[str, str]:
    """`base` as the env script leaves it (after clean_environment: nothing to prepend to but PATH)."""
    env = dict(base)
    for name, value, prepend in cli_variables(venv, overlay):
        env[name] = os.pathsep.join(filter(None, [value, env.get(name)])) if prepend else value
    return env


def env_script(venv: Path, overlay: Path | None) -> str:
    lines = [
        "# shellcheck shell=bash",
        "# Source me (bash or zsh): the ros2 CLI built by launch_scripts/ros2cli.sh, with the project's interfaces.",
        "# RMW and discovery as launch_scripts/env.sh sets them, unless the caller set them; ROS_DOMAIN_ID left alone.",
    ]
    for name, value, prepend in cli_variables(venv, overlay):
        quoted = value.replace('"', '\\"')
        if prepend:
            lines.append(f'export {name}="{quoted}${{{name}:+:${name}}}"')
        else:
            lines.append(f'export {name}="{quoted}"')
    lines.append('export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"')
    lines.append('export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"')
    return "\n".join(lines) + "\n"


def interfaces_overlay(dest: Path, packages=INTERFACES, project_venv: Path = PROJECT_VENV) -> Path:
    """A prefix of links to the installed files of the interface packages of .venv (see the module doc)."""
    project_venv = project_venv.resolve()  # a symbolic link in a git worktree
    manifests = [project_venv / ".sorting_line" / f"{package}_install_manifest.txt" for package in packages]
    missing = [m for m in manifests if not m.is_file()]
    if missing:
        raise Failure(f"{', '.join(map(str, missing))} missing: run launch_scripts/setup.sh first")
    for line in (line.strip() for m in manifests for line in m.read_text().splitlines()):
        src = Path(line)
        if not line or not src.exists():
            continue
        link = dest / src.relative_to(project_venv)
        link.parent.mkdir(parents=True, exist_ok=True)
        if not link.is_symlink():
            link.symlink_to(src)
    return dest


class Builder:
    """One build of the venv, with progress lines (`[ros2cli  12s] ...`) and logged commands."""

    def __init__(self, venv: Path, python: str, work: Path):
        self.venv, self.python, self.work = venv, python, work
        self.t0 = time.monotonic()
        self.env = clean_environment(dict(os.environ))

    def say(self, message: str) -> None:
        print(f"[ros2cli {time.monotonic() - self.t0:4.0f}s] {message}", flush=True)

    def run(self, step: str, argv: list, timeout: float, env: dict[str, str] | None = None) -> None:
        """Runs a command logged to work/STEP.log; fails showing the log's end."""
        log = self.work / f"{step}.log"
        with open(log, "wb") as out:
            try:
                code = subprocess.run(
                    [str(a) for a in argv], stdout=out, stderr=subprocess.STDOUT, env=env or self.env, timeout=timeout
                ).returncode
            except subprocess.TimeoutExpired:
                code = f"no end within {timeout:.0f} s"
        if code != 0:
            tail = "\n".join(log.read_text(errors="replace").splitlines()[-30:])
            kept = self.venv.parent / f"{self.venv.name}.{step}.log"
            shutil.copy(log, kept)
            raise Failure(f"{step} failed ({code}); log {kept}, its end:\n{tail}")

    def unpack(self, archives: list[Path], sources: list[Source]) -> dict[str, Path]:
        """Each archive into a folder of its own; its top folder (NAME/ or GitHub's NAME-VERSION/) by name."""
        roots = {}
        for archive, source in zip(archives, sources, strict=True):
            dest = self.work / "src" / source.name
            with tarfile.open(archive) as tar:
                tar.extractall(dest, filter="data")
            tops = [p for p in dest.iterdir() if p.is_dir()]
            if len(tops) != 1:
                raise Failure(f"{archive}: expected one top folder, found {[p.name for p in tops]}")
            roots[source.name] = tops[0]
        return roots

    def make_venv(self) -> None:
        if self.venv.exists():
            if not (self.venv / "pyvenv.cfg").is_file():
                raise Failure(f"{self.venv} exists and is not a venv: not replacing it (choose --venv)")
            shutil.rmtree(self.venv)
        self.say(f"creating the venv {self.venv} with {self.python}")
        self.run("venv", [self.python, "-m", "venv", self.venv], timeout=300)

    def install(self, roots: dict[str, Path]) -> None:
        pip = [self.venv / "bin" / "python", "-m", "pip", "--disable-pip-version-check", "--no-input"]
        self.say(f"pip: the pinned wheels of {REQUIREMENTS.name}")
        self.run("pip-wheels", [*pip, "install", "-q", "-r", REQUIREMENTS], timeout=PIP_TIMEOUT)
        # --no-deps: their metadata names `launch` (an unrelated PyPI project) and ament_index_python (here
        # ros-ament-index-python). As wheels they register their entry points (ros2cli.command, launch.frontend)
        # and put share/ament_index and share/<package>/package.xml under the venv's prefix.
        folders = [roots[name] / sub for name, subs in PACKAGES.items() for sub in subs]
        self.say(f"pip: {len(folders)} packages from the ros2cli, launch, launch_ros and rosidl_runtime_py sources")
        self.run(
            "pip-sources",
            [*pip, "install", "-q", "--no-deps", "--no-build-isolation", *folders],
            timeout=PIP_TIMEOUT,
        )

    def fix_wheel_cmake_paths(self) -> None:
        """The wheels' exported CMake files name the include dirs of the wheels' build machine (setup.sh too)."""
        python = self.venv / "bin" / "python"
        code = (
            "import sys, sysconfig, numpy; print(sysconfig.get_paths()['include']); print(numpy.get_include()); "
            "print('%d.%d' % sys.version_info[:2])"
        )
        py_inc, np_inc, version = subprocess.run(
            [python, "-c", code], capture_output=True, text=True, env=self.env, timeout=120, check=True
        ).stdout.split()
        tag = version.replace(".", "")
        build_python = f"/opt/python/cp{tag}-cp{tag}"  # where the cpXY wheels were built
        for path in (self.venv / "share").rglob("*.cmake"):
            text = path.read_text()
            if build_python in text:
                text = text.replace(f"{build_python}/lib/python{version}/site-packages/numpy/_core/include", np_inc)
                path.write_text(text.replace(f"{build_python}/include/python{version}", py_inc))

    def compile_interfaces(self, roots: dict[str, Path]) -> None:
        archive, package = COMPILED
        self.say(f"cmake: {package} (from {archive}) into the venv")
        self.fix_wheel_cmake_paths()
        venv, build = self.venv, self.work / "build"
        env = dict(self.env, PATH=f"{venv}/bin:{self.env['PATH']}", AMENT_PREFIX_PATH=str(venv))
        env.update(CMAKE_PREFIX_PATH=str(venv), CMAKE_BUILD_PARALLEL_LEVEL=str(os.cpu_count() or 2))
        configure = [venv / "bin" / "cmake", "-S", roots[archive] / package, "-B", build]
        configure += [f"-DCMAKE_INSTALL_PREFIX={venv}", "-DCMAKE_BUILD_TYPE=Release", "-DBUILD_TESTING=OFF"]
        configure += [f"-DPython3_EXECUTABLE={venv}/bin/python", "-DPython3_FIND_VIRTUALENV=ONLY"]
        self.run("cmake-configure", configure, timeout=CMAKE_TIMEOUT, env=env)
        self.run("cmake-build", [venv / "bin" / "cmake", "--build", build], timeout=CMAKE_TIMEOUT, env=env)
        self.run("cmake-install", [venv / "bin" / "cmake", "--install", build], timeout=CMAKE_TIMEOUT, env=env)

    def check(self) -> None:
        """The CLI starts and knows a message type; launch_ros.actions imports (needs composition_interfaces)."""
        self.say("checking: imports, `ros2 interface show std_msgs/msg/String`")
        env = cli_environment(self.venv, None, self.env)
        imports = (
            "import rclpy, launch, launch_ros.actions, launch_testing, rosidl_runtime_py, composition_interfaces.srv"
        )
        self.run("check-imports", [self.venv / "bin" / "python", "-c", imports], timeout=120, env=env)
        self.run("check-ros2", [self.venv / "bin" / "ros2", "interface", "show", "std_msgs/msg/String"], 120, env)


def archives_for(args, work: Path, sources: list[Source], say) -> list[Path]:
    if args.source_dir is not None:
        say(f"checking the archives of {args.source_dir} against {MANIFEST.name}")
        return verify(args.source_dir, sources)
    folder = work / "downloads"
    folder.mkdir()
    download(sources, folder, say)
    say(f"checking the downloads against {MANIFEST.name}")
    return verify(folder, sources, downloaded=True)


def build(args, key: str) -> None:
    with tempfile.TemporaryDirectory(prefix="sorting_line_ros2cli.") as scratch:
        builder = Builder(args.venv, args.python, Path(scratch))
        sources = read_manifest()
        archives = archives_for(args, Path(scratch), sources, builder.say)
        roots = builder.unpack(archives, sources)
        builder.make_venv()
        builder.install(roots)
        builder.compile_interfaces(roots)
        builder.check()
        (args.venv / STAMP).write_text(f"{key} built in {time.monotonic() - builder.t0:.0f} s\n")
        builder.say(f"built {args.venv}")


def finish(venv: Path, project_venv: Path) -> Path:
    """The overlay of the project's interfaces (when .venv has them) and env.sh; cheap, so on every run."""
    overlay_dir = venv / OVERLAY
    shutil.rmtree(overlay_dir, ignore_errors=True)  # a rebuild of .venv may have changed the files
    overlay = None
    try:
        overlay = interfaces_overlay(overlay_dir, INTERFACES, project_venv)
    except Failure as e:
        print(f"ros2cli: note: the project's interfaces are not visible to the CLI: {e}", flush=True)
    script = venv / "env.sh"
    script.write_text(env_script(venv, overlay))
    return script


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="ros2cli.sh", description=__doc__.split("\n\n")[0], epilog=f"Sources and checksums: {MANIFEST}"
    )
    parser.add_argument(
        "--from",
        dest="source_dir",
        type=Path,
        metavar="DIR",
        help="take the source archives from DIR (default: download them)",
    )
    parser.add_argument(
        "--venv", type=Path, default=DEFAULT_VENV, help=f"where to build the venv (default {DEFAULT_VENV})"
    )
    parser.add_argument(
        "--interfaces-from",
        type=Path,
        default=PROJECT_VENV,
        metavar="VENV",
        help=f"the project venv whose compiled interfaces the CLI sees (default {PROJECT_VENV})",
    )
    parser.add_argument("--verify-only", action="store_true", help="only check the archives of --from DIR")
    parser.add_argument("--force", action="store_true", help="build again even when the stamp matches")
    parser.add_argument(
        "--python",
        help="CPython 3.11 or 3.12 for the venv (default: the interpreter of the --interfaces-from venv)",
    )
    args = parser.parse_args(argv)
    if args.source_dir is not None and not args.source_dir.is_dir():
        parser.error(f"--from {args.source_dir}: not a folder")
    if args.verify_only and args.source_dir is None:
        parser.error("--verify-only needs --from DIR")
    args.venv = args.venv.absolute()
    return args


def python_of(python: str | Path) -> tuple[str, str]:
    """(the interpreter itself, not a venv's or a launcher's; its version X.Y)."""
    code = "import sys; print(getattr(sys, '_base_executable', sys.executable)); print('%d.%d' % sys.version_info[:2])"
    try:
        out = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=60, check=True).stdout
    except (OSError, subprocess.SubprocessError) as e:
        raise Failure(f"{python}: not a working Python ({e})") from None
    base, version = out.split()
    return base, version


def choose_python(python: str | None, project_venv: Path) -> str:
    """The interpreter to build with: `python`, else the project venv's. The CLI imports the project venv's
    compiled interfaces (the overlay), so both must be one Python version."""
    venv_python = project_venv / "bin" / "python"
    venv_base, venv_version = python_of(venv_python) if venv_python.exists() else (None, None)
    if python is None:
        if venv_base is None:
            raise Failure(
                f"{project_venv} missing: run launch_scripts/setup.sh first, "
                "or name an interpreter (SORTING_LINE_PYTHON)"
            )
        python = str(venv_python)
    base, version = (venv_base, venv_version) if python == str(venv_python) else python_of(python)
    if version not in ("3.11", "3.12"):
        raise Failure(f"{python} is Python {version}: the ros-jazzy-* wheels are for CPython 3.11 and 3.12")
    if venv_version is not None and version != venv_version:
        raise Failure(
            f"{python} is Python {version}, {project_venv} is Python {venv_version}: the CLI imports that venv's "
            f"compiled interfaces, so build it with {venv_version} (SORTING_LINE_PYTHON={venv_version})"
        )
    return base


@contextlib.contextmanager
def locked(venv: Path):
    venv.parent.mkdir(parents=True, exist_ok=True)
    with open(venv.parent / f"{venv.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        if args.verify_only:
            verify(args.source_dir, read_manifest())
            print(f"ros2cli: the archives of {args.source_dir} match {MANIFEST.name}")
            return 0
        args.python = choose_python(args.python, args.interfaces_from)
        key = stamp_key(args.python)
        with locked(args.venv):
            if args.force or not is_current(args.venv, key):
                build(args, key)
            else:
                print(f"ros2cli: {args.venv} is up to date ({MANIFEST.name}, {REQUIREMENTS.name} unchanged)")
            script = finish(args.venv, args.interfaces_from)
    except Failure as e:
        print(f"ros2cli: error: {e}", file=sys.stderr)
        return 1
    print(f"ros2cli: now `source {script}` (each shell), then e.g. `ros2 topic list`")
    return 0


if __name__ == "__main__":
    sys.exit(main())
