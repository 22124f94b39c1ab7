"""The installable wheel: `pip wheel ./bridge` builds ONE wheel holding the package, its data files
and the native extension (abi3); installed into a fresh venv without any ROS wheel,
``gymnasium.make(..., backend="native")`` runs, rclpy is never imported, and the ROS backend fails
naming what it lacks.

The tests run without a network: the wheel is installed with --no-deps from its file, and the
package's few runtime dependencies (numpy, gymnasium and theirs, PyYAML) come from this venv, their
top-level modules linked into a directory the fresh venv reads through a .pth file (nothing else of
this venv, no rclpy, is visible there). Cost: the wheel's cargo build reuses target/ of the editable
install, the venv is made without pip.
"""

from __future__ import annotations

import importlib.metadata
import os
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: What the package needs to run the native backend (its wheel is installed with --no-deps).
RUNTIME = ("numpy", "gymnasium", "cloudpickle", "Farama-Notifications", "typing_extensions", "PyYAML")

SCRIPT = """
import sys, gymnasium, sorting_line_gym
env = gymnasium.make("sorting_line_gym:SortingLine-v0", backend="native")
obs, info = env.reset(seed=42)
obs, reward, terminated, truncated, info = env.step(5)
assert info["step"] == 1 and info["seed"] == 42, info
evolving = gymnasium.make("sorting_line_gym:SortingLineEvolving-v0", backend="native")
evolving.reset(seed=1)
assert "rclpy" not in sys.modules
try:
    gymnasium.make("sorting_line_gym:SortingLine-v0").reset(seed=1)
except ImportError as e:
    print("ROS:", e)
else:
    raise SystemExit("the ROS backend ran without rclpy")
"""


def link_runtime(into: Path) -> None:
    """Links the top-level modules of RUNTIME's distributions (as installed here) into ``into``."""
    into.mkdir()
    for name in RUNTIME:
        dist = importlib.metadata.distribution(name)
        tops = {Path(str(f)).parts[0] for f in dist.files or []}
        for top in tops - {"..", "__pycache__"}:
            if not top.endswith((".dist-info", ".data")):
                (into / top).symlink_to(dist.locate_file(top))


def run(argv: list, **kwargs) -> subprocess.CompletedProcess:
    # maturin's build hooks run the `maturin` command: this interpreter's, first on PATH.
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    r = subprocess.run([str(a) for a in argv], capture_output=True, text=True, env=env, **kwargs)
    assert r.returncode == 0, f"`{' '.join(map(str, argv))}` failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
    return r


def test_the_wheel_installs_and_runs_without_ros(tmp_path):
    wheels = tmp_path / "wheels"
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "--no-input"]
    run([*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", wheels, ROOT / "bridge"], timeout=900)
    built = list(wheels.glob("*.whl"))
    assert len(built) == 1, built
    assert "abi3" in built[0].name, built[0].name
    names = zipfile.ZipFile(built[0]).namelist()
    for want in ("evolutions/upgrade.yaml", "training/hyperparams/ppo.yml", "envs/native.py", "_native.abi3.so"):
        assert any(n.endswith(want) for n in names), f"{want} is not in {built[0].name}"

    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", venv], timeout=120)
    python = venv / "bin" / "python"
    site = Path(run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"]).stdout.strip())
    link_runtime(tmp_path / "runtime")
    (site / "runtime.pth").write_text(f"{tmp_path / 'runtime'}\n")
    # This venv's pip installs the wheel into the fresh one (which has none of its own).
    run([*pip, "--python", python, "install", "-q", "--no-deps", "--no-index", built[0]], timeout=300)
    out = run([python, "-c", SCRIPT], timeout=120, cwd=tmp_path).stdout
    assert "backend='ros' needs the ROS 2 Python modules, and this environment lacks 'rclpy'" in out, out
    assert "backend='native'" in out
