"""The commit-msg hook contributors install (.githooks/commit-msg, CONTRIBUTING.md) refuses what it should.

A subject line of 72 characters or more is refused, and so is a message without a subject; a subject of 71
passes, characters counted rather than bytes, comments and the diff below `git commit -v`'s scissors line not
taken for the subject. Then the hook as git runs it: a scratch repository with `core.hooksPath` set to the
repository's .githooks, as CONTRIBUTING.md says to install it, commits a good subject and refuses a long one.
No ROS, no network: about 1 s under load.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
HOOKS = ROOT / ".githooks"
HOOK = HOOKS / "commit-msg"
SCISSORS = "# ------------------------ >8 ------------------------"


def run_hook(message: str, tmp_path: Path) -> subprocess.CompletedProcess:
    path = tmp_path / "COMMIT_EDITMSG"
    path.write_text(message, encoding="utf-8")
    return subprocess.run([str(HOOK), str(path)], cwd=tmp_path, capture_output=True, text=True, timeout=30)


@pytest.mark.parametrize(
    "message",
    [
        "Short subject\n",
        "a" * 71 + "\n\n" + "a body line may be as long as it likes " * 5 + "\n",
        "é" * 71,  # 71 characters, 142 bytes
        "\n\n# Please enter the commit message\n   \nThe subject after blank and comment lines   \n",
        "Subject\n" + SCISSORS + "\n" + "-" * 100 + "\n",
    ],
    ids=["short", "71", "71-non-ascii", "after-comments", "above-scissors"],
)
def test_a_subject_under_72_characters_passes(message, tmp_path):
    done = run_hook(message, tmp_path)
    assert done.returncode == 0, f"refused {message!r}:\n{done.stderr}"


@pytest.mark.parametrize(
    "message,why",
    [
        ("a" * 72 + "\n", "has 72 characters"),
        ("é" * 72 + "\n", "has 72 characters"),
        ("# a comment\n" + "b" * 90 + "\n\nbody\n", "has 90 characters"),
        ("", "no subject line"),
        ("\n  \n# only comments\n", "no subject line"),
        ("# nothing above the scissors\n" + SCISSORS + "\ndiff --git a/x b/x\n", "no subject line"),
    ],
    ids=["72", "72-non-ascii", "90-after-comment", "empty", "only-comments", "only-diff"],
)
def test_a_long_or_missing_subject_is_refused(message, why, tmp_path):
    done = run_hook(message, tmp_path)
    assert done.returncode == 1, f"accepted {message!r}"
    assert why in done.stderr, done.stderr


def test_git_runs_it_once_installed_as_contributing_says(tmp_path):
    install = "git config core.hooksPath .githooks"
    assert install in (ROOT / "CONTRIBUTING.md").read_text(), "CONTRIBUTING.md no longer says how to install the hook"
    repo = tmp_path / "repo"
    env = dict(os.environ, GIT_CONFIG_NOSYSTEM="1", HOME=str(tmp_path), GIT_AUTHOR_NAME="t", GIT_AUTHOR_EMAIL="t@x")
    env.update(GIT_COMMITTER_NAME="t", GIT_COMMITTER_EMAIL="t@x")

    def git(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["git", *args], cwd=repo, env=env, capture_output=True, text=True, timeout=30)

    subprocess.run(["git", "init", "-q", str(repo)], env=env, check=True, timeout=30)
    # The clone's .githooks is the repository's own (absolute here: the scratch repository has no copy).
    assert git("config", "core.hooksPath", str(HOOKS)).returncode == 0
    good = git("commit", "--allow-empty", "-q", "-m", "A subject that fits", "-m", "why, in the body")
    assert good.returncode == 0, good.stderr
    long = git("commit", "--allow-empty", "-q", "-m", "x" * 72)
    assert long.returncode != 0 and "has 72 characters" in long.stderr, long.stderr
    assert git("log", "--format=%s").stdout.splitlines() == ["A subject that fits"]
