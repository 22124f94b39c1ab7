"""The envs under the vectorizers users bring, at scale, against the REAL node.

- Gymnasium's AsyncVectorEnv with its default context (fork on Linux): the envs connect at their
  first reset, so the forked workers never inherit a live rclpy context; and a child forked from a
  process where rclpy IS live gets a clear error at once (cause and fix), not a futex;
- many envs per host through line servers (``node="shared"``): SyncVectorEnv of 64 envs in one
  process, SB3's SubprocVecEnv of 16 worker processes, two vector envs in two processes at once;
- every env's episode equals `sorting_line trace` for its seed, number for number;
- a process whose env is connected still dies of SIGTERM (Process.terminate()), with its node;
- action_masks() on every env, and sb3-contrib's MaskablePPO training on them;
- RL Baselines3 Zoo: rl_zoo3.train with our conf file, then rl_zoo3.enjoy on the model.

Workloads that fork or need a fresh interpreter run as scripts in subprocesses, each bounded by a
timeout. Episodes are short (10-30 steps; 200 for the fork test) to keep CI cost low.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium
import numpy as np
import pytest

import sorting_line_gym  # noqa: F401 - registers the Gymnasium ids
from sorting_line_gym import SortingLineSB3VecEnv, SortingLineVectorEnv
from support.env_trace import assert_obs, assert_step, fixed_actions, trace
from support.ros_harness import node_binary
from support.waits import wait_until

ROOT = Path(__file__).resolve().parents[2]
BASIC = "sorting_line_gym:SortingLine-v0"
ADVANCED = "sorting_line_gym:SortingLineAdvanced-v0"

# Records every env's episode as JSON lines: what the comparison with the trace needs.
RECORDER = r"""
import faulthandler
import json
import signal
import numpy as np

# On SIGUSR1 every process of the script (forked workers inherit the handler) prints the stacks of
# all its threads: run_script sends it before killing a hung script, so a hang names its place.
faulthandler.register(signal.SIGUSR1, all_threads=True)

KEYS = (
    "accuracy",
    "purity",
    "containers",
    "speed_changes",
    "occupancy",
    "cumulative_reward",
    "speed_index",
    "mode",
    "step",
)


def plain(value):
    if hasattr(value, "tolist"):
        return value.tolist()
    return list(value) if isinstance(value, tuple) else value


def record_step(episodes, obs, rewards, info_of):
    for k, episode in enumerate(episodes):
        episode["steps"].append({"obs": plain(obs[k]), "reward": float(rewards[k]),
                                 "info": {key: plain(info_of(k)[key]) for key in KEYS}})
"""


_script_domains = itertools.count()


def script_environment() -> dict[str, str]:
    """The environment of a workload script: the node binary, unbuffered output, and a
    ROS_DOMAIN_ID of its own (not the suite's, nor an earlier script's). What a script starts (its
    workers' participants, their nodes, line servers) then neither discovers nor is disturbed by
    what earlier tests left in the suite's domain: lingering participants, and Fast DDS's
    shared-memory ports derived from the domain id, which live in /dev/shm, where no network
    namespace separates them (rmw_fastrtps adds the shared-memory transport in LOCALHOST mode;
    its port 7000, which every participant opens whatever its domain, stays shared)."""
    suite = int(os.environ.get("ROS_DOMAIN_ID", "0"))
    domain = suite
    while domain == suite:
        domain = 1 + (suite + next(_script_domains)) % 99
    return dict(os.environ, SORTING_LINE_BIN=str(node_binary()), PYTHONUNBUFFERED="1", ROS_DOMAIN_ID=str(domain))


def start_script(path: Path, code: str, *args: str) -> subprocess.Popen:
    """``code`` as the script ``path``, started with ``args`` in the script environment; its
    stdin, stdout and stderr are pipes (text)."""
    path.write_text(code)
    pipes = dict(stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    return subprocess.Popen([sys.executable, str(path), *args], text=True, env=script_environment(), **pipes)


def run_script(tmp_path: Path, name: str, code: str, args=(), timeout: float = 240.0) -> dict:
    """Runs ``code`` (after RECORDER) as a script in a fresh interpreter, bounded by ``timeout``;
    returns the JSON object its last stdout line holds. A script still running at the timeout
    (a hang) is killed with all its session (workers and nodes too), after its processes' stacks
    were taken, so that the failure names where it hung (``_stacks_then_kill``)."""
    script = tmp_path / f"{name}.py"
    script.write_text(RECORDER + code)
    env = script_environment()
    p = subprocess.Popen(
        [sys.executable, str(script), *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
        start_new_session=True,
    )
    try:
        stdout, stderr = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        stdout, stderr, native = _stacks_then_kill(p)
        pytest.fail(
            f"{name} did not finish within {timeout:g} s (a hang); its last output:\n{stdout[-1000:]}\n"
            f"its stderr, ending with every process's Python stacks:\n{stderr[-8000:]}\n{native[-16000:]}"
        )
    assert p.returncode == 0, f"{name} failed ({p.returncode}):\n{stdout[-2000:]}\n{stderr[-4000:]}"
    return json.loads(stdout.strip().splitlines()[-1])


def _stacks_then_kill(p: subprocess.Popen) -> tuple[str, str, str]:
    """For a hung script: the native stacks of its Python processes (gdb, where installed: a hang
    inside rclpy or Fast DDS shows only as a C call in Python's stack), then SIGUSR1 to its
    session (faulthandler prints the Python stacks; a node, which has no handler, just ends), then
    SIGKILL to all of it; returns what the script wrote to stdout and stderr, and the native stacks."""
    native = []
    if shutil.which("gdb"):
        for pid in _session_members(p.pid):
            try:
                bt = subprocess.run(
                    ["gdb", "-p", str(pid), "-batch", "-ex", "thread apply all bt 25"],
                    capture_output=True,
                    text=True,
                    timeout=60,
                ).stdout
            except subprocess.TimeoutExpired:
                bt = "(gdb timed out)"
            # "#3 0x7f.. in func (args...) at file.c:12" -> "#3 func at file.c:12"
            frames = [
                re.sub(r"^(#\d+)\s+(?:0x[0-9a-f]+ in )?(\S+) \(.*\) (at|from) ", r"\1 \2 \3 ", line)
                for line in bt.splitlines()
                if line.startswith(("#", "Thread "))
            ]
            native.append(f"--- native stacks of pid {pid}:\n" + "\n".join(frames)[-6000:])
    for sig, pause in ((signal.SIGUSR1, 3.0), (signal.SIGKILL, 0.0)):
        try:
            os.killpg(p.pid, sig)
        except ProcessLookupError:
            pass
        # Not a synchronisation: a grace on the way out of a test that has already failed (a hang).
        # The stacks go into the stderr pipe, read only after the SIGKILL, so their end is not
        # observable from here; 3 s lets faulthandler write them, and nothing here decides a verdict.
        time.sleep(pause)
    stdout, stderr = p.communicate(timeout=30)
    return stdout, stderr, "\n".join(native)


def _session_members(session: int) -> list[int]:
    """The Python processes of a session (a script started with start_new_session=True)."""
    members = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            comm_end = (text := stat.read_text()).rindex(")")
            if int(text[comm_end + 2 :].split()[3]) == session and "python" in text[:comm_end]:
                members.append(int(stat.parent.name))
        except (OSError, ValueError, IndexError):
            continue
    return sorted(members)


def assert_matches_trace(
    episode: dict, setup: str, variant: str, seed: int, actions: list[int], max_steps: int, where: str
) -> None:
    want = trace(setup, variant, seed, actions, max_steps=max_steps)
    assert_obs(np.array(episode["obs"], dtype=np.float32), variant, want[0]["reset"]["observation"], f"{where} reset")
    assert len(episode["steps"]) == len(actions), f"{where}: {len(episode['steps'])} steps for {len(actions)} actions"
    for t, step in enumerate(episode["steps"]):
        obs = np.array(step["obs"], dtype=np.float32)
        assert_step(variant, obs, step["reward"], step["info"], want[t + 1], f"{where} step {t + 1}")


# --------------------------------------------------------------------------------------------
# fork


ASYNC_VECTOR_ENV = r"""
import sys
import time
import gymnasium as gym
from gymnasium.vector import AsyncVectorEnv
import sorting_line_gym

env_id, setup, seed, steps, n = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
actions = json.loads(sys.argv[6])
context = sys.argv[7] if len(sys.argv) > 7 else None


def make():
    return gym.make(env_id, setup=setup, max_episode_steps=steps)


if __name__ == "__main__":
    envs = AsyncVectorEnv([make] * n, context=context)  # None: fork on Linux; the dummy env starts nothing
    obs, _ = envs.reset(seed=[seed + k for k in range(n)])
    episodes = [{"obs": plain(obs[k]), "steps": []} for k in range(n)]
    for t in range(steps):
        obs, rewards, terminated, truncated, info = envs.step(np.array(actions[t]))
        record_step(episodes, obs, rewards, lambda k: {key: info[key][k] for key in KEYS})
    print(json.dumps({"episodes": episodes, "truncated": truncated.tolist()}))
    envs.close()
"""


def test_async_vector_env_with_the_default_fork_context_matches_the_library(tmp_path):
    """AsyncVectorEnv (fork) of 4 envs, each spawning its node in its worker: 200 steps, env k ==
    `trace --seed S+k`, the last step truncated by the TimeLimit."""
    n, steps, seed, variant = 4, 200, 4100, "basic"
    per_env = [fixed_actions(10, steps, seed + k) for k in range(n)]
    by_step = [[per_env[k][t] for k in range(n)] for t in range(steps)]
    out = run_script(tmp_path, "async_fork", ASYNC_VECTOR_ENV, [BASIC, "B", seed, steps, n, json.dumps(by_step)])
    assert out["truncated"] == [True] * n
    for k, episode in enumerate(out["episodes"]):
        assert_matches_trace(episode, "B", variant, seed + k, per_env[k], steps, f"worker {k}")


@pytest.mark.parametrize("context", ["forkserver", "spawn"])
def test_async_vector_env_with_the_forkserver_and_spawn_contexts_matches_the_library(tmp_path, context):
    """AsyncVectorEnv with the other two start methods (2 envs, 30 steps, env k == `trace --seed
    S+k`). With forkserver a worker's parent, for the kernel, is the fork server: the parent-death
    set-up once took that for a dead parent and killed every such worker at its first reset."""
    n, steps, seed, variant = 2, 30, 4200, "basic"
    per_env = [fixed_actions(10, steps, seed + k) for k in range(n)]
    by_step = [[per_env[k][t] for k in range(n)] for t in range(steps)]
    out = run_script(
        tmp_path,
        f"async_{context}",
        ASYNC_VECTOR_ENV,
        [BASIC, "B", seed, steps, n, json.dumps(by_step), context],
        timeout=120,
    )
    for k, episode in enumerate(out["episodes"]):
        assert_matches_trace(episode, "B", variant, seed + k, per_env[k], steps, f"{context} worker {k}")


FORK_WITH_LIVE_CONTEXT = r"""
import os, sys, time
import gymnasium as gym
import sorting_line_gym
from sorting_line_gym import BridgeError

env = gym.make(sys.argv[1], setup="A")
env.reset(seed=1)
env.step(0)  # rclpy is live in this process now
read_end, write_end = os.pipe()
child = os.fork()
if child == 0:
    os.close(read_end)
    out = {"pid": os.getpid()}
    started = time.monotonic()
    for what, use in (("inherited env", lambda: env.step(1)),
                      ("new env", lambda: gym.make(sys.argv[1], setup="A").reset(seed=2))):
        try:
            use()
            out[what] = "no error"
        except BridgeError as e:
            out[what] = str(e)
    out["seconds"] = time.monotonic() - started
    os.write(write_end, json.dumps(out).encode())
    os._exit(0)
os.close(write_end)
with os.fdopen(read_end) as f:
    child_out = json.loads(f.read())
os.waitpid(child, 0)
env.step(2)  # the parent's env is unharmed
env.close()
print(json.dumps({"parent": os.getpid(), **child_out}))
"""


def test_forked_child_with_an_inherited_live_context_gets_a_clear_error(tmp_path):
    """A process forked after its parent used an env: the inherited env and a new one both raise
    at once, naming the cause (rclpy/DDS not fork-safe, both pids) and the fix."""
    out = run_script(tmp_path, "fork_live", FORK_WITH_LIVE_CONTEXT, [BASIC], timeout=90)
    for what in ("inherited env", "new env"):
        message = out[what]
        assert "not fork-safe" in message, f"{what}: {message}"
        assert f"pid {out['parent']}" in message and f"pid {out['pid']}" in message, f"{what}: {message}"
        assert "'spawn'" in message and "'forkserver'" in message, f"{what}: {message}"


# --------------------------------------------------------------------------------------------
# many envs per host: line servers


LIVE_ENV_WAITING = r"""
import sys
import time
import gymnasium as gym
import sorting_line_gym  # noqa: F401
env = gym.make(sys.argv[1], setup="B", node=sys.argv[2])
env.reset(seed=1)
print("ready", flush=True)
sys.stdin.read()  # as a vectorizer's worker waits for its next command
"""


@pytest.mark.parametrize("node", ["spawn", "shared"])
def test_a_process_with_a_live_env_dies_of_sigterm(tmp_path, node):
    """Process.terminate() (multiprocessing's exit handler, SB3's and Gymnasium's vectorizers
    after a worker failed) must end a worker whose env is connected: the env does not install
    rclpy's signal handlers, under which SIGTERM only shut rclpy down and the worker lived on,
    blocked, with its parent waiting for it forever."""
    p = start_script(tmp_path / "live_env.py", LIVE_ENV_WAITING, BASIC, node)
    try:
        line = p.stdout.readline().strip()
        assert line == "ready", f"the env did not start: {line!r}\n{p.stderr.read() if p.poll() is not None else ''}"
        p.send_signal(signal.SIGTERM)
        try:
            code = p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            pytest.fail("a process with a connected env survived SIGTERM for 30 s")
        assert code == -signal.SIGTERM, f"exit code {code}, expected death by SIGTERM"
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


ORPHANED_WORKER = r"""
import multiprocessing, sys
import gymnasium as gym
import sorting_line_gym  # noqa: F401

def worker(env_id, pipe):
    env = gym.make(env_id, setup="B", node="shared")
    env.reset(seed=1)
    pipe.send("ready")
    pipe.recv()  # as SB3's and Gymnasium's workers wait for their next command

if __name__ == "__main__":
    context = multiprocessing.get_context(sys.argv[2])
    ours, theirs = context.Pipe()
    child = context.Process(target=worker, args=(sys.argv[1], theirs))
    child.start()
    assert ours.poll(120), "the worker's env did not connect within 120 s"
    ours.recv()
    print(child.pid, flush=True)
    sys.stdin.read()  # the test kills this process here
"""


@pytest.mark.parametrize("start", ["fork", "forkserver", "spawn"])
def test_a_worker_with_a_live_env_dies_with_its_parent(tmp_path, start):
    """A multiprocessing worker with a connected env, whose parent is killed with SIGKILL (a
    training script timed out, or killed by its user), must not live on: it held the parent's
    pipe, so nothing would ever wake it, and its leased line stayed leased. With forkserver the
    signal comes through the fork server, which exits when the parent is gone."""
    p = start_script(tmp_path / "orphan.py", ORPHANED_WORKER, BASIC, start)
    worker = None
    try:
        line = p.stdout.readline().strip()
        assert line.isdigit(), f"the worker did not start: {line!r}\n{p.stderr.read() if p.poll() is not None else ''}"
        worker = int(line)
        p.kill()
        p.wait()
        wait_until(
            lambda: not os.path.exists(f"/proc/{worker}") or _state(worker) == "Z",
            30,
            f"the worker (pid {worker}) to end with its killed parent",
            poll=0.1,
            context=lambda: f"the worker is in state {_state(worker)}",
        )
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        if worker is not None and os.path.exists(f"/proc/{worker}"):
            os.kill(worker, signal.SIGKILL)


def _state(pid: int) -> str:
    """A process's state letter from /proc (Z: a zombie, dead but not yet reaped by init)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, IndexError):
        return "gone"


def test_sync_vector_env_of_64_shared_envs_matches_the_library():
    """gymnasium.make_vec(sync) of 64 envs on line servers (4 node processes of 16 lines): env k ==
    `trace --seed S+k` for 10 steps."""
    n, steps, seed, variant = 64, 10, 6400, "advanced"
    envs = gymnasium.make_vec(ADVANCED, num_envs=n, vectorization_mode="sync", setup="C", node="shared")
    try:
        per_env = [fixed_actions(30, steps, seed + k) for k in range(n)]
        obs, _ = envs.reset(seed=seed)
        namespaces = [e.unwrapped.namespace for e in envs.envs]
        assert len(set(namespaces)) == n, f"two envs on one line: {namespaces}"
        episodes = [{"obs": obs[k].tolist(), "steps": []} for k in range(n)]
        for t in range(steps):
            obs, rewards, _, _, info = envs.step(np.array([per_env[k][t] for k in range(n)]))
            for k in range(n):
                step_info = {key: info[key][k] for key in info if not key.startswith("_")}
                episodes[k]["steps"].append({"obs": obs[k].tolist(), "reward": float(rewards[k]), "info": step_info})
    finally:
        envs.close()
    for k, episode in enumerate(episodes):
        assert_matches_trace(episode, "C", variant, seed + k, per_env[k], 1_000_000, f"env {k} ({namespaces[k]})")


SUBPROC_16 = r"""
import sys
import time
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv
import sorting_line_gym

env_id, setup, start = sys.argv[1], sys.argv[2], sys.argv[6]
seed, steps, n = int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
actions = json.loads(sys.argv[7])

if __name__ == "__main__":
    vec = make_vec_env(
        env_id,
        n_envs=n,
        seed=seed,
        vec_env_cls=SubprocVecEnv,
        env_kwargs={"setup": setup, "node": "shared"},
        vec_env_kwargs={"start_method": start},
    )
    obs = vec.reset()  # env k reset with seed + k
    namespaces = vec.get_attr("namespace")
    episodes = [{"obs": plain(obs[k]), "steps": []} for k in range(n)]
    for t in range(steps):
        obs, rewards, dones, infos = vec.step(np.array(actions[t]))
        record_step(episodes, obs, rewards, lambda k: infos[k])
    print(json.dumps({"episodes": episodes, "namespaces": namespaces}))
    vec.close()
"""


def test_sb3_subproc_vec_env_of_16_workers_matches_the_library(tmp_path):
    """SB3's SubprocVecEnv with 16 worker processes, each an rclpy participant leasing a line:
    env k == `trace --seed S+k` for 20 steps. (fork: the workers share the parent's imports, which
    keeps CI cost low; the envs connect inside the workers.)"""
    n, steps, seed, variant = 16, 20, 1600, "basic"
    per_env = [fixed_actions(10, steps, seed + k) for k in range(n)]
    by_step = [[per_env[k][t] for k in range(n)] for t in range(steps)]
    out = run_script(tmp_path, "subproc16", SUBPROC_16, [BASIC, "D", seed, steps, n, "fork", json.dumps(by_step)])
    assert len(set(out["namespaces"])) == n, out["namespaces"]
    for k, episode in enumerate(out["episodes"]):
        assert_matches_trace(episode, "D", variant, seed + k, per_env[k], 1_000_000, f"worker {k}")


SYNC_IN_A_PROCESS = r"""
import sys
import time
import gymnasium as gym
import sorting_line_gym

env_id, setup, seed, steps, n = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
actions = json.loads(sys.argv[6])
envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", setup=setup, node="shared")
obs, _ = envs.reset(seed=seed)
episodes = [{"obs": plain(obs[k]), "steps": []} for k in range(n)]
if len(sys.argv) > 7:  # a barrier: every process holds its leases before any steps or lets go
    import pathlib, time
    barrier, parties = pathlib.Path(sys.argv[7]), int(sys.argv[8])
    (barrier / f"leased_{seed}").touch()
    # (This script runs in a fresh interpreter without tests/python on its path: a loop of its own,
    # not support.waits; its deadline names what it waited for all the same.)
    deadline = time.monotonic() + 180
    while len(list(barrier.glob("leased_*"))) < parties:
        assert time.monotonic() < deadline, "the other processes did not lease their lines within 180 s"
        time.sleep(0.05)
for t in range(steps):
    obs, rewards, terminated, truncated, info = envs.step(np.array(actions[t]))
    record_step(episodes, obs, rewards, lambda k: {key: info[key][k] for key in KEYS})
print(json.dumps({"episodes": episodes, "namespaces": [e.unwrapped.namespace for e in envs.envs]}))
envs.close()
"""


def test_two_vector_envs_in_two_processes_at_once_do_not_disturb_each_other(tmp_path):
    """Two training scripts on one host at once, 8 envs each on the same line servers: distinct
    lines, and every env's episode == `trace --seed S+k` of its own script's seed."""
    n, steps, variant = 8, 30, "basic"
    seeds = (2000, 3000)
    per_env = {s: [fixed_actions(10, steps, s + k) for k in range(n)] for s in seeds}
    env = script_environment()
    procs = []
    for s in seeds:
        script = tmp_path / f"sync_{s}.py"
        script.write_text(RECORDER + SYNC_IN_A_PROCESS)
        by_step = [[per_env[s][k][t] for k in range(n)] for t in range(steps)]
        # The barrier makes "at once" certain: on a loaded machine one script could otherwise finish
        # (and free its lines) before the other leases any, and reusing freed lines is correct.
        procs.append(
            subprocess.Popen(
                [
                    sys.executable,
                    str(script),
                    BASIC,
                    "A",
                    str(s),
                    str(steps),
                    str(n),
                    json.dumps(by_step),
                    str(tmp_path),
                    str(len(seeds)),
                ],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=env,
            )
        )
    outs = []
    for p in procs:
        try:
            stdout, stderr = p.communicate(timeout=300)
        except subprocess.TimeoutExpired:
            for q in procs:
                q.kill()
            pytest.fail("a vector env process did not finish within 300 s (a hang)")
        assert p.returncode == 0, f"vector env process failed ({p.returncode}):\n{stderr[-4000:]}"
        outs.append(json.loads(stdout.strip().splitlines()[-1]))
    assert not set(outs[0]["namespaces"]) & set(outs[1]["namespaces"]), "both processes drove the same line"
    for s, out in zip(seeds, outs, strict=False):
        for k, episode in enumerate(out["episodes"]):
            assert_matches_trace(episode, "A", variant, s + k, per_env[s][k], 1_000_000, f"process seed {s} env {k}")


KEEPS_ITS_PARTICIPANT = r"""
import multiprocessing, sys
import gymnasium as gym
import rclpy
import sorting_line_gym  # noqa: F401
from sorting_line_gym.workarounds import participant_deletion_hang


def state():
    return {"rclpy_ok": rclpy.ok(), "anchor": participant_deletion_hang.keeps_participant()}


def worker(env_id, queue, exit_with):
    env = gym.make(env_id, setup="B")
    env.reset(seed=1)
    env.step(0)
    env.close()
    queue.put(state())
    if exit_with == "exception":
        raise RuntimeError("the worker ends on an exception")
    sys.exit(exit_with)


if __name__ == "__main__":
    context = multiprocessing.get_context(sys.argv[2])
    queue = context.Queue()
    children = {}
    for exit_with in (0, 3, "exception"):
        child = context.Process(target=worker, args=(sys.argv[1], queue, exit_with))
        child.start()
        in_child = queue.get(timeout=120)
        child.join(60)
        children[str(exit_with)] = {"after_close": in_child, "exit_code": child.exitcode}
    env = gym.make(sys.argv[1], setup="B")
    env.reset(seed=1)
    env.close()
    print(json.dumps({"workers": children, "parent_after_close": state()}))
"""


@pytest.mark.parametrize("start_method", ["fork", "forkserver", "spawn"])
def test_a_worker_keeps_its_participant_and_a_parent_shuts_rclpy_down(tmp_path, start_method):
    """In a multiprocessing worker of every start method, closing the last env neither deletes the
    DDS participant nor shuts rclpy down (workarounds.participant_deletion_hang: deleting it while
    the other workers close can spin for minutes in Fast DDS 2.14), and the worker ends without DDS
    teardown with the exit code it would have had (0, sys.exit(3), 1 on an exception; a spawn
    worker's end goes through the workaround's os._exit); elsewhere rclpy is shut down when the
    last env closes, so that the process may fork afterwards."""
    out = run_script(
        tmp_path, f"keeps_participant_{start_method}", KEEPS_ITS_PARTICIPANT, [BASIC, start_method], timeout=240
    )
    kept = {"rclpy_ok": True, "anchor": True}
    assert out == {
        "workers": {
            "0": {"after_close": kept, "exit_code": 0},
            "3": {"after_close": kept, "exit_code": 3},
            "exception": {"after_close": kept, "exit_code": 1},
        },
        "parent_after_close": {"rclpy_ok": False, "anchor": False},
    }


# --------------------------------------------------------------------------------------------
# action masks


def test_action_masks_on_every_env_face():
    """All actions valid today, in the shape each consumer expects; asking starts nothing."""
    single = gymnasium.make(ADVANCED, setup="B")
    vector = SortingLineVectorEnv(num_envs=3, variant="basic")
    try:
        assert np.array_equal(single.unwrapped.action_masks(), np.ones(30, dtype=bool))
        assert vector.action_masks().shape == (3, 10) and vector.action_masks().all()
    finally:
        single.close()
        vector.close()


def test_maskable_ppo_trains_2048_steps_on_4_envs():
    from sb3_contrib import MaskablePPO
    from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported

    vec = SortingLineSB3VecEnv(num_envs=4, setup="B", variant="advanced", seed=7)
    try:
        assert is_masking_supported(vec)
        masks = get_action_masks(vec)
        assert masks.shape == (4, 30) and masks.all()
        model = MaskablePPO("MlpPolicy", vec, n_steps=256, batch_size=256, n_epochs=2, seed=7, device="cpu")
        model.learn(2048)
        assert model.num_timesteps >= 2048
    finally:
        vec.close()


# --------------------------------------------------------------------------------------------
# RL Baselines3 Zoo


def test_rl_zoo_trains_with_our_conf_file_and_enjoy_replays_the_model(tmp_path):
    env = script_environment()
    common = [
        "--algo",
        "ppo",
        "--env",
        "SortingLine-v0",
        "--gym-packages",
        "sorting_line_gym",
        "-f",
        str(tmp_path / "logs"),
    ]
    train = [
        sys.executable,
        "-m",
        "rl_zoo3.train",
        *common,
        "--conf-file",
        "sorting_line_gym.zoo.ppo",
        "-n",
        "512",
        "--seed",
        "3",
        "--eval-freq",
        "-1",
        "-params",
        "n_steps:256",
        "batch_size:64",
        "n_epochs:1",
    ]
    r = subprocess.run(train, capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
    assert r.returncode == 0, f"rl_zoo3.train failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    assert "'gamma', 0.85" in r.stdout and "'max_episode_steps': 250" in r.stdout, r.stdout[-3000:]
    model = tmp_path / "logs" / "ppo" / "SortingLine-v0_1" / "SortingLine-v0.zip"
    assert model.is_file(), f"no model at {model}: {sorted(p.name for p in (tmp_path / 'logs').rglob('*'))}"
    enjoy = [sys.executable, "-m", "rl_zoo3.enjoy", *common, "-n", "260", "--no-render", "--deterministic"]
    r = subprocess.run(enjoy, capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
    assert r.returncode == 0, f"rl_zoo3.enjoy failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    assert "Episode Length 250" in r.stdout, r.stdout[-3000:]
