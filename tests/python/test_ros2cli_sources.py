"""The pinned sources of the ros2 CLI (launch_scripts/ros2cli-sources.txt) and launch_scripts/ros2cli.sh's checks
of them: a corrupted or a missing archive stops it, naming the file; the archives beside the clone pass; an archive
as GitHub makes it (the same files under a top folder NAME-VERSION/) passes as a download by its contents, and a
changed file in it does not. No ROS, no network, no build (the CLI tests use the built CLI): a few seconds.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tarfile
from pathlib import Path

import pytest

from support import ros2_cli

recipe = ros2_cli.recipe
SCRIPT = ros2_cli.ROOT / "launch_scripts" / "ros2cli.sh"


def verify_only(folder: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(SCRIPT), "--verify-only", "--from", str(folder)], capture_output=True, text=True, timeout=120
    )


def archives() -> Path:
    folder = ros2_cli.archive_dir()
    if folder is None:
        pytest.skip(f"no folder of the source archives beside the repository: {ros2_cli.describe()}")
    return folder


def test_the_manifest_pins_every_source_the_script_installs():
    sources = recipe.read_manifest()
    for s in sources:
        assert re.fullmatch(r"[0-9a-f]{40}", s.commit), s
        assert re.fullmatch(r"[0-9a-f]{64}", s.sha256) and re.fullmatch(r"[0-9a-f]{64}", s.files_sha256), s
        assert s.url == f"https://github.com/ros2/{s.name}/archive/refs/tags/{s.version}.tar.gz", s
    assert sorted(s.name for s in sources) == sorted([*recipe.PACKAGES, recipe.COMPILED[0]])


def test_the_archives_beside_the_clone_match_the_manifest():
    done = verify_only(archives())
    assert done.returncode == 0, done.stderr
    assert "match ros2cli-sources.txt" in done.stdout


def test_a_corrupted_and_a_missing_archive_are_named(tmp_path):
    folder = tmp_path / "archives"
    shutil.copytree(archives(), folder)
    corrupted, missing = folder / "launch-3.4.3.tar.gz", folder / "rosidl_runtime_py-0.13.1.tar.gz"
    data = bytearray(corrupted.read_bytes())
    data[len(data) // 2] ^= 0xFF
    corrupted.write_bytes(bytes(data))
    missing.unlink()
    done = verify_only(folder)
    assert done.returncode == 1, done
    assert f"{corrupted}: SHA-256 " in done.stderr and f"{missing}: missing" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
    named = re.findall(r"^  (\S+?):", done.stderr, re.M)
    assert sorted(named) == sorted([str(corrupted), str(missing)]), done.stderr


def repack(archive: Path, dest: Path, top: str, change: str | None = None) -> Path:
    """`archive` with its top folder renamed to `top` (as GitHub names it), optionally one file's text changed."""
    with tarfile.open(archive) as tar:
        tar.extractall(dest / "x", filter="data")
    root = next((dest / "x").iterdir())
    if change:
        (root / change).write_text((root / change).read_text() + "# changed\n")
    out = dest / archive.name
    with tarfile.open(out, "w:gz") as tar:
        tar.add(root, arcname=top)
    return out


def test_a_download_with_githubs_top_folder_passes_by_its_contents_only(tmp_path):
    source = next(s for s in recipe.read_manifest() if s.name == "rosidl_runtime_py")
    top = f"{source.name}-{source.version}"
    same = repack(archives() / source.filename, tmp_path / "same", top)
    assert recipe.verify(same.parent, [source], downloaded=True) == [same]
    with pytest.raises(recipe.Failure, match=re.escape(f"{same}: SHA-256")):
        recipe.verify(same.parent, [source])  # a --from folder must hold the pinned bytes
    changed = repack(archives() / source.filename, tmp_path / "changed", top, change="setup.py")
    with pytest.raises(recipe.Failure, match=re.escape(f"{changed}: SHA-256") + ".*contents"):
        recipe.verify(changed.parent, [source], downloaded=True)
