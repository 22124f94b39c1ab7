"""The repository explains itself: no tracked file sends the reader to the `shared/` folder beside the clone.

That folder (the reference material and the tools of the machines this project was built on) is not part of the
repository. Only the code that finds a tool's inputs in it may name it: tests/python/support/ros2_cli.py, which
hands the folder of the ros2 CLI's source archives to launch_scripts/ros2cli.sh. Everything else says what it
needs in its own words or links to docs/. No ROS, no network: about 0.1 s.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
PATTERN = re.compile(r"\.\./shared|(?<![\w.-])shared/(?:reference|platform|tools|hooks)|/work/shared|CONTRACT\.md")
# Files that find a tool's inputs in shared/ (and this test, which names the pattern).
ALLOWED = {
    "tests/python/support/ros2_cli.py",
    "tests/python/unit/test_self_contained.py",
}


def tracked_files() -> list[str]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return [f for f in out.decode().split("\0") if f and not f.startswith("vendor/")]


def test_no_tracked_file_refers_to_shared():
    found = []
    for name in tracked_files():
        if name in ALLOWED:
            continue
        try:
            text = (ROOT / name).read_text()
        except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
            continue  # binary files (figures, bags), or a file deleted in the work tree
        found += [f"{name}:{n}: {line.strip()}" for n, line in enumerate(text.splitlines(), 1) if PATTERN.search(line)]
    assert not found, "references to the shared/ folder outside the tools' build scripts:\n" + "\n".join(found)


def test_allowed_files_exist():
    """A renamed build script must be renamed here too, or the allow-list would hide nothing and say nothing."""
    missing = sorted(name for name in ALLOWED if not (ROOT / name).is_file())
    assert not missing, f"allow-listed files that no longer exist: {missing}"
