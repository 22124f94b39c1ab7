"""launch_scripts/run.sh, the README's first command, run as a newcomer runs it.

From the checkout, with none of the project's variables in the environment (no venv activated, env.sh not
sourced, no ROS_DOMAIN_ID: a login shell's PATH and HOME, and cargo), at a reduced budget through run.sh's own
flags and into an ``--out`` folder of the test's. Each run goes through run.sh's set-up step (setup.sh --train,
current here, so it only checks its stamps and cargo's) and, as root, its own loopback-only network namespace
inside the test's. Checked: the default job (24 baseline rows, the PPO row, the figures it names), ``--smoke``,
``--backend native``, a failing step (exit 1 naming the step and its log, no summary) and bad arguments (exit 2
naming the value and what is allowed, before anything runs).

About 5 minutes in all on a 2-core machine (2026-12-03, beside the suite's background checks), most of it the
default job's cells through ROS.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from support.training_stack import needs_training

ROOT = Path(__file__).resolve().parents[2]
RUN = ROOT / "launch_scripts" / "run.sh"
LINES = [(setup, env) for setup in "ABCD" for env in ("Basic", "Adv")]
BASELINES = ("random", "rba", "rba-hold")
#: A reward as the tables print it: 27.56, **27.56**, -3.10, each followed by "+- std".
REWARD = re.compile(r"^\**(-?\d+\.\d+)\**( \+- \d+\.\d+)?$")
PNG = b"\x89PNG\r\n\x1a\n"
#: The budget of the runs below: minutes under CI's load, not hours; on a quiet machine a run takes 1-3 min.
TIMEOUT_S = 1500
#: The default job's held-out seeds here (run.sh's default is 100): of its 24 baseline cells' 110 episodes
#: each through ROS, 100 were held-out ones, and the test took 160-300 s of the suite; with 10 it checks the
#: same steps, tables and figures.
REDUCED = ("--quick-steps", "256", "--heldout-episodes", "10")


def newcomer_environment() -> dict[str, str]:
    """What a fresh login shell has: the system PATH plus the Rust toolchain, HOME, a locale. Nothing of this
    project (no VIRTUAL_ENV, no .venv/bin on PATH, no SORTING_LINE_*, no ROS_* variables)."""
    cargo = shutil.which("cargo")
    assert cargo, "cargo is not on PATH: run.sh's set-up needs the Rust toolchain"
    path = f"{Path(cargo).parent}:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
    return {"PATH": path, "HOME": os.environ.get("HOME", "/root"), "LANG": "C.UTF-8"}


def run_sh(*args: str, cwd: Path, log: Path, timeout: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    """run.sh with ``args``, its output (stdout and stderr apart) kept in ``log`` and in the result."""
    try:
        done = subprocess.run(
            ["bash", str(RUN), *args],
            cwd=cwd,
            env=newcomer_environment(),
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired as e:
        raise AssertionError(
            f"run.sh {' '.join(args)} did not end within {timeout} s\n{e.stdout}\n{e.stderr}"
        ) from None
    log.write_text(f"$ run.sh {' '.join(args)}\n--- stdout\n{done.stdout}\n--- stderr\n{done.stderr}")
    return done


def explain(done: subprocess.CompletedProcess) -> str:
    return f"exit {done.returncode}\n--- stdout (end)\n{done.stdout[-4000:]}\n--- stderr (end)\n{done.stderr[-6000:]}"


def table_rows(markdown: str) -> list[dict[str, str]]:
    """The rows of every Table 1 in ``markdown`` (the tables with `setup`, `env`, `agent` and reward columns; not
    the statistics after them), keyed by their header's names."""
    rows, header = [], None
    for line in markdown.splitlines():
        if not line.startswith("|"):
            header = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
        elif not set("".join(cells)) <= set("-: "):
            rows.append(dict(zip(header, cells, strict=False)))
    return [r for r in rows if {"setup", "env", "agent", "seeds 42..51: reward"} <= r.keys()]


def reward_of(row: dict[str, str]) -> float:
    value = row["seeds 42..51: reward"]
    match = REWARD.match(value)
    assert match, f"no reward in the row {row}"
    return float(match.group(1))


def check_default_job(out: Path, backend: str) -> None:
    """summary.md: the 24 baseline rows and the PPO row, with numbers; each figure it names is a PNG."""
    summary = (out / "summary.md").read_text()
    baselines, quick = summary.split("## A quick PPO")
    rows = {(r["setup"], r["env"], r["agent"]): r for r in table_rows(baselines)}
    for setup, env in LINES:
        for agent in BASELINES:
            assert (setup, env, agent) in rows, f"summary.md has no {agent} row for {setup} {env}:\n{baselines}"
            reward_of(rows[(setup, env, agent)])
    ppo = [r for r in table_rows(quick) if r["agent"] == "ppo"]
    assert len(ppo) == 1 and (ppo[0]["setup"], ppo[0]["env"]) == ("B", "Adv"), f"one PPO row on B Adv:\n{quick}"
    reward_of(ppo[0])
    assert f"backend {backend}" in summary, summary
    named = re.search(r"^Figures: (.*)\.$", summary, re.M)
    assert named, f"summary.md names no figures:\n{summary}"
    for figure in named.group(1).split(", "):
        data = (out / figure).read_bytes()
        assert data.startswith(PNG) and len(data) > 10_000, f"{figure} is not a PNG with a picture in it"
    for step in ("setup", "baselines", "quick_ppo"):
        assert (out / "logs" / f"{step}.log").stat().st_size > 0, f"logs/{step}.log is empty"
    assert "Held-out: 10 seeds from 10000" in summary, f"run.sh did not pass --heldout-episodes on:\n{summary}"


@needs_training
def test_the_default_job_writes_both_tables_and_the_figures(tmp_path):
    done = run_sh(*REDUCED, "--out", "results", cwd=tmp_path, log=tmp_path / "run.log")
    assert done.returncode == 0, explain(done)
    check_default_job(tmp_path / "results", "ros")
    assert "1/2" in done.stderr and "2/2" in done.stderr, "run.sh did not show its steps"
    dashboards = list((tmp_path / "results" / "baselines" / "dashboards").glob("*.png"))
    assert len(dashboards) == 24, f"{len(dashboards)} episode dashboards, not one per baseline cell"


@needs_training
def test_the_default_job_on_the_native_backend(tmp_path):
    out = tmp_path / "native results"  # a space in the path, as a home folder may have
    done = run_sh("--backend", "native", *REDUCED, "--out", str(out), cwd=ROOT, log=tmp_path / "run.log")
    assert done.returncode == 0, explain(done)
    check_default_job(out, "native")


@needs_training
def test_the_smoke_study(tmp_path):
    done = run_sh("--smoke", "--out", "results", cwd=tmp_path, log=tmp_path / "run.log")
    assert done.returncode == 0, explain(done)
    table = (tmp_path / "results" / "smoke" / "table.md").read_text()
    rows = {r["agent"]: r for r in table_rows(table) if (r["setup"], r["env"]) == ("B", "Adv")}
    for agent in ("random", "rba-hold", "ppo"):
        assert agent in rows, f"the smoke table has no {agent} row:\n{table}"
        reward_of(rows[agent])
    assert rows["ppo"]["runs"] == "2", f"PPO ran {rows['ppo']['runs']} training seeds, not --smoke's 2"
    for figure in ("figure7.png", "figure3.png"):
        assert (tmp_path / "results" / "smoke" / figure).read_bytes().startswith(PNG), figure
    assert "# Benchmark" in done.stdout, "run.sh --smoke did not print the study's table"


@needs_training
def test_a_failing_step_ends_run_sh_naming_the_step(tmp_path):
    """Step 1 cannot write its results (a file stands where its folder goes): run.sh stops there, exit 1, names
    the step and its log, and writes no summary over a missing table."""
    out = tmp_path / "results"
    out.mkdir()
    (out / "baselines").write_text("a file where the step's folder goes\n")
    done = run_sh("--backend", "native", *REDUCED, "--out", str(out), cwd=tmp_path, log=tmp_path / "run.log")
    assert done.returncode == 1, explain(done)
    log = out / "logs" / "baselines.log"
    assert "step baselines (1/2: random, rba, rba-hold on the 8 setups, backend native) failed" in done.stderr, explain(
        done
    )
    assert f"its log: {log}" in done.stderr, explain(done)
    assert log.read_text().strip(), "the failed step's log is empty"
    assert not (out / "summary.md").exists(), "run.sh wrote a summary although a step failed"
    assert "== 2/2" not in done.stderr, "run.sh went on after a failed step"
    assert "cannot be written" in log.read_text(), "the benchmark did not say why it could not run"


BAD_ARGUMENTS = [
    (["--bogus"], "unknown argument '--bogus' (allowed: --quick-steps N"),
    (["--quick-steps"], "--quick-steps needs a value"),
    (["--quick-steps", "many"], "--quick-steps 'many' is not valid: allowed a whole number from 1"),
    (["--quick-steps", "0"], "--quick-steps '0' is not valid: allowed a whole number from 1"),
    (["--smoke", "--jobs", "-1"], "--jobs '-1' is not valid: allowed a whole number from 1"),
    (["--full", "--smoke"], "--full and --smoke exclude each other"),
    (["--backend", "gpu"], "--backend 'gpu' is not valid: allowed ros, native"),
    (["--lines-mapping", "x"], "--lines-mapping 'x' is not valid: allowed same-rollout, same-line-rollout"),
    (["--smoke", "--train-seeds", "42", "x7"], "--train-seeds 'x7' is not valid: allowed a whole number from 0"),
    (["--out", "/dev/null/results"], "--out '/dev/null/results' cannot be written"),
]


@pytest.mark.parametrize(("args", "message"), BAD_ARGUMENTS, ids=[" ".join(a) for a, _ in BAD_ARGUMENTS])
def test_bad_arguments_exit_2_naming_the_value(tmp_path, args, message):
    done = run_sh(*args, cwd=tmp_path, log=tmp_path / "run.log", timeout=60)
    assert done.returncode == 2, explain(done)
    assert f"run.sh: {message}" in done.stderr, explain(done)
    assert "set-up" not in done.stderr, "run.sh began its set-up before refusing its arguments"


def test_help_prints_the_usage(tmp_path):
    done = run_sh("--help", cwd=tmp_path, log=tmp_path / "run.log", timeout=60)
    assert done.returncode == 0 and done.stdout.startswith("The main job on a fresh machine"), explain(done)
    for flag in ("--quick-steps", "--full", "--smoke", "--backend", "--out"):
        assert flag in done.stdout, f"--help does not describe {flag}"
