"""Closed-loop `sorting-line-bag check`: the controller drives a fresh lock-step node that has the
bag's options (setup, seed, evolution schedule: what `replay` starts,
:func:`..transport.replay_plan.lockstep_node`), reset as the bag's ``events/reset`` say (seeded, or
carrying the streams on), and each episode is compared with the bag's: episode reward, mean
accuracy, purity, speed changes, and the first tick where the two trajectories part. Tolerances
decide; equal or better passes.

- The node serves the check's namespace, with ``/clock`` and ``/diagnostics`` as any node has
  them (a controller may read the simulated clock; ``--record`` records the run as
  `sorting-line-bag record` records any line).
- No handshake reset: a controller answers every tick it sees, so it would drive a handshake
  episode and move the random streams on. Instead the check waits until the node's topics and the
  controller are in the graph, lets them match, and starts with the bag's first reset. When the
  first tick of a seeded episode gets no answer (the controller's first answer can be lost while
  endpoints still match), the seeded reset is repeated, which is the same episode again.
- Each episode runs until the node's state reaches the bag's last step of that episode (the
  controller runs on in lock-step; what comes after that step is not compared) or ends. A tick
  the controller does not answer within ``answer_timeout`` (the node refused its answer, with the
  reason in the node's log, or it sent none) stalls the episode: a missing answer, and the check
  goes on with the next reset.
"""

from __future__ import annotations

import tempfile
import threading
import time
from pathlib import Path

from ...line.errors import BridgeTimeout
from ...line.topics import DIAGNOSTICS, INPUT, RESET, RESET_EVENT, SPEED_CMD, STATE
from ...ros.links import LineLink
from ...workarounds.late_matching import repeated_while_unanswered
from ..format.options import NodeOverrides
from ..format.topics import LINE_TYPES, join
from ..storage.reader import Bag
from ..storage.schema import decode, stamp_ns
from ..transport.compare import first_field_difference, show_ns
from ..transport.progress import progress_bar
from ..transport.record import record as record_line
from ..transport.replay_plan import ReplayPlan, lockstep_node, plan_replay
from ..transport.rosnode import InputMatches, ToolNode, controller_seen
from .options import RunOptions
from .verdict import Answer, EpisodeResult, Figures, Tolerance, Verdict

#: Longest wait for the fresh node's endpoints (its start on a busy machine).
STARTUP_TIMEOUT = 30.0
#: How long the node and the controller are given to match each other once both are in the graph
#: (the node's own word that it matched the controller's input reader comes first).
SETTLE = 1.0
RESET_ATTEMPTS = 3
#: State fields that differ between two runs of the same trajectory (when, and which episode).
NOT_TRAJECTORY = ("header", "episode")


class Watch:
    """The node and the controller, watched together by the check's waits (either dying ends them)."""

    def __init__(self, *processes):
        self.processes = [p for p in processes if p is not None]

    def alive(self) -> bool:
        return all(p.alive() for p in self.processes)

    def death_notice(self) -> str:
        return "; ".join(p.death_notice() for p in self.processes if not p.alive())


def run_closed_loop(
    bag: Bag,
    verdict: Verdict,
    tolerances: dict[str, Tolerance],
    run_options: RunOptions,
    *,
    overrides: NodeOverrides | None = None,
    record=None,
) -> None:
    """Runs the closed loop (see the module's docstring) and fills ``verdict.episodes``. Raises
    BagError for a bag it cannot use, BridgeError when the node or the controller fails."""
    plan = plan_replay(bag, overrides)
    scratch = tempfile.TemporaryDirectory(prefix="sorting_line_check_")
    o = run_options
    watch = Watch(o.process)
    tool = ToolNode("sorting_line_bag_check", watch)
    run = recorder = None
    try:
        run = _Run(plan, verdict, tool, watch, Path(scratch.name), o.answer_timeout, o.wait, o.stop)
        run.start_node()
        if record is not None:
            speed = join(verdict.namespace, SPEED_CMD)
            recorder = CheckRecorder(verdict.namespace, record, o.wait, {speed: tool.node.count_publishers(speed)})
        started = time.monotonic()
        run.drive(o.progress)
        verdict.seconds = time.monotonic() - started
        verdict.ticks = len(run.states)
    finally:
        if recorder is not None:
            verdict.recorded = recorder.stop()
        tool.close()
        if run is not None:
            run.stop_node()
        scratch.cleanup()
    _judge(plan, verdict, run, tolerances)


class _Run:
    """The drive phase: a fresh node, the bag's resets, each followed by the controller's episode."""

    def __init__(
        self,
        plan: ReplayPlan,
        verdict: Verdict,
        tool: ToolNode,
        watch: Watch,
        scratch: Path,
        answer_timeout: float,
        wait: float,
        stop,
    ):
        self.plan, self.verdict, self.tool, self.watch, self.scratch = plan, verdict, tool, watch, scratch
        self.answer_timeout, self.wait, self.stop = answer_timeout, wait, stop
        self.namespace = verdict.namespace
        self.node = None
        self.link = LineLink(tool.node, self.namespace, advanced=False)
        self.states: list[dict] = []
        self.newest: dict[int, tuple[int, bool]] = {}  # run episode -> (newest step, ended)
        self.state_sub = tool.raw_subscription(join(self.namespace, STATE), LINE_TYPES[STATE], self._on_state)
        self.resets = plan.rel_msgs.get(RESET_EVENT, [])
        self.episodes: dict[int, int] = {}  # bag episode -> run episode

    def start_node(self) -> None:
        self.node = lockstep_node(self.plan, self.namespace, self.scratch)
        self.watch.processes.append(self.node)
        self.wait_for_graph(self.wait)

    def stop_node(self) -> None:
        if self.node is not None:
            self.watch.processes.remove(self.node)
            self.node.stop()
            self.node = None

    def restart_node(self) -> None:
        """A fresh node again: the only way to repeat a first reset without a seed exactly."""
        self.stop_node()
        self.states.clear()
        self.newest.clear()
        self.start_node()
        self.verdict.notes.append(
            "the controller did not answer the first tick (its first answer can be lost "
            "while endpoints still match): the node was restarted and the run began again"
        )

    def _on_state(self, data: bytes, _received: int) -> None:
        s = decode(data, LINE_TYPES[STATE])
        self.states.append(s)
        step, _ = self.newest.get(s["episode"], (-1, False))
        self.newest[s["episode"]] = (max(step, s["step"]), bool(s["terminated"] or s["truncated"]))

    def wait_for_graph(self, wait: float) -> None:
        ns, node = self.namespace, self.tool.node
        self.tool.until(
            lambda: self.link.endpoints_matched(node) and self.state_sub.get_publisher_count() > 0,
            STARTUP_TIMEOUT,
            f"the check's node serving {ns} (its reset service and topics)",
        )

        try:  # (the check's own link writes cmd/speed too)
            self.tool.until(
                lambda: controller_seen(node, ns, own_speed_writers=1),
                wait,
                f"a controller in {ns} (a reader of {INPUT}, a writer of {SPEED_CMD})",
            )
        except BridgeTimeout as e:
            raise BridgeTimeout(f"{e}: start one there, or pass --controller CMD") from None
        # Seen by this process is not matched by the node, which sends a tick's input only to the
        # readers it has matched: wait for its word (/diagnostics), then for the controller's side.
        matches = InputMatches(node)
        self.tool.until(
            lambda: matches.all_matched(ns),
            STARTUP_TIMEOUT,
            f"the check's node serving {ns} to match every reader of its {INPUT} (input_readers on {DIAGNOSTICS})",
        )
        self.tool.spin_for(SETTLE)

    def bag_target(self, reset) -> int:
        """The bag's last step of the episode ``reset`` started."""
        episode = reset.plain["episode"]
        return max((s["step"] for s in self.plan.bag_states.values() if s["episode"] == episode), default=0)

    def drive(self, progress: bool) -> None:
        targets = [self.bag_target(r) for r in self.resets]
        bar = progress_bar(sum(targets), progress, "check", "tick")
        try:
            for reset, target in zip(self.resets, targets, strict=True):
                if self.stop():
                    break
                self._episode(reset.plain, target, bar)
        finally:
            bar.close()

    def _episode(self, recorded: dict, target: int, bar) -> None:
        seed = int(recorded["seed"]) if recorded.get("seeded", True) else None
        first_act = not self.episodes  # the bag's first reset: the node's first act

        def attempt(_k: int) -> tuple[int, int | None]:
            self.link.send_reset(seed)
            self.tool.until(
                self.link.reset_done, max(5.0, self.answer_timeout), f"the reply of {self.namespace}/{RESET}"
            )
            episode = self.link.finish_reset().episode
            self.episodes[int(recorded["episode"])] = episode
            return episode, self._follow(episode, target, bar)

        # A first tick without an answer may be the controller still matching the node: a seeded
        # reset again is the same episode again; the node's first reset without a seed needs a
        # fresh node; a later unseeded reset cannot be repeated.
        episode, stalled = repeated_while_unanswered(
            attempt,
            lambda result: result[1] == 0,
            RESET_ATTEMPTS if seed is not None or first_act else 1,
            before_repeat=(lambda _result: self.restart_node()) if seed is None else None,
        )
        if stalled is not None:
            self._stalled(recorded, episode, stalled)

    def _follow(self, episode: int, target: int, bar) -> int | None:
        """Waits while the controller drives ``episode`` to step ``target`` (or its end): None
        then, else the step at which no answer came."""
        while True:
            step, ended = self.newest.get(episode, (-1, False))
            if step >= target or ended or self.stop():
                return None
            try:
                self.tool.until(
                    lambda step=step: self.newest.get(episode, (-1, False))[0] > step or self.stop(),
                    self.answer_timeout,
                    lambda step=step: f"an answer to step {max(step, 0)} of episode {episode}",
                )
            except BridgeTimeout:
                return max(step, 0)
            bar.update(max(0, min(target, self.newest[episode][0]) - max(step, 0)))

    def _stalled(self, recorded: dict, episode: int, step: int) -> None:
        state = next((s for s in reversed(self.states) if s["episode"] == episode and s["step"] == step), None)
        stamp = stamp_ns(state) if state else 0
        refusals = [line for line in self.node.log_tail(40).splitlines() if ": rejected " in line]
        a = Answer(
            stamp // self.plan.period,
            stamp,
            SPEED_CMD,
            "speed",
            None,
            episode=int(recorded["episode"]),
            step=step,
            reason=refusals[-1].strip() if refusals else None,
        )
        self.verdict.answers.append(a)
        self.verdict.notes.append(
            f"episode {recorded['episode']}: no answer to step {step} within "
            f"{self.answer_timeout:g} s" + (f" (the node: {a.reason})" if a.reason else "")
        )


class CheckRecorder:
    """`sorting-line-bag record` of the check's line, in a thread of its own, until ``stop()``."""

    def __init__(self, namespace: str, out, wait: float, writers: dict[str, int]):
        """``writers``: command topic -> how many writers it has (the check sees them): the
        recorder is ready once it has matched them all, so the run's first commands are in the bag."""
        self._stop, self._ready = threading.Event(), threading.Event()
        self.error: BaseException | None = None
        self.result = None
        self.matched: dict[str, int] = {}

        def on_ready(text: str) -> None:
            if text.startswith("matched "):
                name, count = text[len("matched ") :].rsplit(": ", 1)
                self.matched[name] = int(count.split()[0])
            elif text.startswith("recording"):
                self._ready.set()

        def run() -> None:
            try:
                self.result = record_line(namespace, out, stop=self._stop.is_set, wait=wait, on_ready=on_ready)
            except BaseException as e:  # noqa: BLE001 - handed to the caller's thread
                self.error = e
                self._ready.set()

        self.thread = threading.Thread(target=run, name="sorting_line_check_record", daemon=True)
        self.thread.start()
        if not self._ready.wait(wait + 30) or self.error is not None:
            self.stop()
            raise self.error or BridgeTimeout(f"--record: the recorder did not start within {wait + 30:g} s")
        deadline = time.monotonic() + wait
        while any(self.matched.get(t, 0) < n for t, n in writers.items()) and time.monotonic() < deadline:
            time.sleep(0.05)

    def stop(self) -> str | None:
        self._stop.set()
        self.thread.join(30)
        return self.result.summary() if self.result is not None else None


def _strip(state: dict) -> dict:
    return {k: v for k, v in state.items() if k not in NOT_TRAJECTORY}


def _parted(bag_states: list[dict], run_states: list[dict], period: int) -> str | None:
    """The first tick where the run's states leave the bag's, described (None: they do not)."""
    for b, r in zip(bag_states, run_states, strict=False):
        found = first_field_difference(_strip(b), _strip(r))
        if found:
            field, was, now = found
            return (
                f"tick {stamp_ns(b) // period} (stamp {show_ns(stamp_ns(b))} s, step {b['step']}), field "
                f"{field}: bag {was!r}, run {now!r}"
            )
    if len(run_states) < len(bag_states):
        b = bag_states[len(run_states)]
        return f"tick {stamp_ns(b) // period} (step {b['step']}): the run has no state there (it stopped)"
    return None


def _judge(plan: ReplayPlan, verdict: Verdict, run: _Run, tolerances: dict[str, Tolerance]) -> None:
    def by_step(states):
        return sorted(states, key=lambda s: s["step"])

    for reset in run.resets:
        episode = int(reset.plain["episode"])
        bag_states = by_step(s for s in plan.bag_states.values() if s["episode"] == episode)
        if not bag_states:
            verdict.notes.append(f"episode {episode}: the bag has no state of it (the recording ended): not compared")
            continue
        target = bag_states[-1]["step"]
        ours = run.episodes.get(episode)
        run_states = by_step(s for s in run.states if s["episode"] == ours and s["step"] <= target)
        result = EpisodeResult(episode, Figures.of(bag_states), Figures.of(run_states) if run_states else None)
        result.parted = _parted(bag_states, run_states, plan.period)
        result.judge(tolerances)
        verdict.episodes.append(result)
