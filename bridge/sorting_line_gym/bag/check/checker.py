"""`sorting-line-bag check`: does a controller still answer a recorded line as it did, and is it no
worse? A verdict that CI can read (:class:`~.verdict.Verdict`: exit code, summary, JSON,
JUnit XML), from the command line or from Python through :func:`check_controller`.

- Open loop (the default, :mod:`.open_loop`): the bag's node side is played tick by tick and the
  controller's commands are compared with the bag's, tick by tick.
- Closed loop (:mod:`.closed_loop`): a fresh lock-step node with the bag's options, reset as the
  bag was, driven by the controller; its episodes are compared with the bag's (reward, accuracy,
  purity, speed changes, where the trajectories part) within tolerances.
- ``controller``: a command (a shell-like string or a list) that the check starts with
  ``--ros-args -r __ns:=<namespace>`` appended and stops at the end; without it the check waits
  (``wait`` seconds) for a controller already running in the namespace.

Exit codes: 0 pass, 1 the verdict failed, 2 bad input (the bag, a flag, a controller command
that does not exist), 3 the run failed (the controller died: its exit code and last output
lines; the node failed; nobody answered at all).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from itertools import pairwise
from pathlib import Path

from rclpy.exceptions import InvalidNamespaceException
from rclpy.validate_namespace import validate_namespace

from ...line.errors import BridgeError
from ...line.topics import SORT_MODE_CMD, SPEED_CMD, STATE
from ..format.errors import BagError
from ..format.options import NodeOverrides
from ..format.topics import LINE_TYPES
from ..storage.reader import Bag, open_bag
from ..storage.schema import stamp_ns
from ..transport.replay_plan import line_namespace
from .closed_loop import run_closed_loop
from .controller_process import ControllerProcess
from .open_loop import expected_commands, run_open_loop
from .options import RunOptions
from .verdict import EXIT_BAD_INPUT, EXIT_RUN_FAILED, Tolerance, Verdict

#: How long to wait for a controller by default: one we start (Python and rclpy start-up on a
#: busy machine) or one already running.
WAIT_STARTED, WAIT_RUNNING = 60.0, 10.0
#: The figures closed loop compares, with their tolerance flags.
FIGURES = ("reward", "accuracy", "purity")


def check_controller(
    bag: str | Path,
    *,
    namespace: str | None = None,
    controller: str | Sequence[str] | None = None,
    closed_loop: bool = False,
    record: str | Path | None = None,
    answer_timeout: float = 5.0,
    wait: float | None = None,
    max_reward_drop: str | float | None = None,
    max_accuracy_drop: str | float | None = None,
    max_purity_drop: str | float | None = None,
    overrides: NodeOverrides | None = None,
    progress: bool = False,
    stop: Callable[[], bool] = lambda: False,
) -> Verdict:
    """Checks a controller against the bag at ``bag`` and returns the verdict (the one
    `sorting-line-bag check` prints; ``verdict.passed``, ``verdict.exit_code``,
    ``verdict.summary()``, ``verdict.to_json()``, ``verdict.to_junit()``). Never raises for a bad
    bag, a failed run or a failed verdict: those are verdicts (exit codes 2, 3, 1).

    ``namespace``: where the line is played (open loop) or the fresh node serves it (closed loop);
    default the bag's line namespace. ``controller``: a command to start (see the module's
    docstring). ``answer_timeout``: longest wait for one tick's answer (s). ``wait``: longest wait
    for the controller to appear (default 60 s for one started here, 10 s for one running).
    ``max_*_drop``: closed loop, how much worse than the bag's an episode's figure may be
    (``0.5`` absolute, ``"5%"`` of the bag's; default 0: equal or better). ``overrides``: closed
    loop, node options the bag lacks (as `replay`'s flags). ``record``: closed loop, a bag
    directory to record the run into."""
    verdict = Verdict(str(bag), closed_loop=closed_loop, namespace=namespace or "")
    started = time.monotonic()
    try:
        drops = (max_reward_drop, max_accuracy_drop, max_purity_drop)
        tolerances = {f: Tolerance.parse(v, f"--max-{f}-drop") for f, v in zip(FIGURES, drops, strict=True)}
        verdict.tolerances = {f: str(t) for f, t in tolerances.items()} if closed_loop else {}
        _check_options(closed_loop, record, answer_timeout)
        loaded = usable_bag(bag, closed_loop)
        verdict.namespace = valid_namespace(namespace or line_namespace(loaded))
    except (BagError, ValueError) as e:
        return _ended(verdict, EXIT_BAD_INPUT, str(e), started)
    process = None
    try:
        if controller is not None:
            process = ControllerProcess(controller, verdict.namespace)
            verdict.controller = process.command
        wait = wait if wait is not None else (WAIT_STARTED if process else WAIT_RUNNING)
        run = RunOptions(answer_timeout, wait, process, stop, progress)
        if closed_loop:
            run_closed_loop(loaded, verdict, tolerances, run, overrides=overrides, record=record)
        else:
            run_open_loop(loaded, verdict, run, namespace=namespace, period_ns=tick_period_ns(loaded))
    except (FileNotFoundError, ValueError, BagError) as e:
        return _ended(verdict, EXIT_BAD_INPUT, str(e), started, process)
    except (BridgeError, TimeoutError) as e:
        return _ended(verdict, EXIT_RUN_FAILED, str(e), started, process)
    return _ended(verdict, None, None, started, process)


def _check_options(closed_loop: bool, record: str | Path | None, answer_timeout: float) -> None:
    """ValueError naming the flag, for options that contradict each other or are out of range."""
    if answer_timeout <= 0:
        raise ValueError(f"--answer-timeout {answer_timeout}: must be > 0 (seconds)")
    if record is not None and not closed_loop:
        raise ValueError("--record records the closed-loop run: add --closed-loop")
    if record is not None and Path(record).exists():
        raise ValueError(f"--record {record}: exists already: choose a new output directory")


def _ended(
    verdict: Verdict, code: int | None, error: str | None, started: float, process: ControllerProcess | None = None
) -> Verdict:
    """Stops the controller, and decides: a controller that died on its own during the run
    failed it (exit 3), whatever its answers were."""
    if process is not None:
        died = not process.alive()
        if died and code is None and process.process.returncode != 0:
            code, error = EXIT_RUN_FAILED, process.death_notice()
        exit_code = process.stop()
        if not died:
            verdict.notes.append(f"controller stopped at the end (exit code {exit_code})")
    if code is not None:
        verdict.exit_code, verdict.error = code, error
    verdict.seconds = verdict.seconds or time.monotonic() - started
    verdict.decide()
    return verdict


def usable_bag(path: str | Path, closed_loop: bool) -> Bag:
    """The bag, if a check can use it; BagError saying what is wrong otherwise."""
    bag = open_bag(path)
    if not bag.messages:
        raise BagError(f"{bag.path}: the bag is empty (no messages): record a line with a controller driving it")
    if LINE_TYPES[STATE] not in bag.types.values():
        listed = ", ".join(f"{t} ({ty})" for t, ty in sorted(bag.types.items()))
        raise BagError(
            f"{bag.path}: not a bag of a sorting line: no topic of type {LINE_TYPES[STATE]} (it has {listed})"
        )
    if not closed_loop and not expected_commands(bag):
        raise BagError(
            f"{bag.path}: the bag has no commands (no {SPEED_CMD} or {SORT_MODE_CMD} of its line): open "
            "loop compares the controller's answers with the bag's commands, so it needs a bag "
            "recorded while a controller drove the line (or use --closed-loop, which compares "
            "episodes instead)"
        )
    return bag


def valid_namespace(namespace: str) -> str:
    """``namespace`` if ROS takes it as a namespace; ValueError saying why not otherwise."""
    try:
        validate_namespace(namespace)
    except InvalidNamespaceException as e:
        reason = str(e).splitlines()[0].rstrip(":")
        raise ValueError(f"--namespace {namespace!r} is not a valid ROS namespace ({reason})") from None
    return namespace


def tick_period_ns(bag: Bag) -> int:
    """ns per tick: the node option the bag stores, else the smallest step between its states."""
    period = (bag.info.node if bag.info else {}).get("tick_period")
    if period:
        return round(float(period) * 1e9)
    stamps = sorted({stamp_ns(m.plain) for m in bag.messages if m.msgtype == LINE_TYPES[STATE]})
    gaps = [b - a for a, b in pairwise(stamps) if b > a]
    return min(gaps) if gaps else 1_000_000_000
