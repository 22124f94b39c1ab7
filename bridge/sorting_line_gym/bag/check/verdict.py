"""The verdict of `sorting-line-bag check`: what a controller answered against what a bag recorded,
as one object that the command line prints, writes as JSON and as JUnit XML, and that the Python
API (:func:`~sorting_line_gym.bag.check.checker.check_controller`) returns. No ROS here.

- Open loop: one :class:`Answer` per tick the bag shows a command for (matching, differing or
  missing), plus the controller's commands that answered no tick (a wrong stamp);
- closed loop: one :class:`EpisodeResult` per episode of the bag (the bag's figures against the
  run's, and the tolerances' judgement);
- exit codes: 0 pass, 1 the verdict failed, 2 bad input, 3 the run failed.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any
from xml.etree import ElementTree as ET

from ...line.vocabulary import MODES, SPEEDS
from ..transport.compare import show_ns

EXIT_PASS, EXIT_FAILED_VERDICT, EXIT_BAD_INPUT, EXIT_RUN_FAILED = 0, 1, 2, 3

_MODES = [f"{number} ({name})" for name, number in MODES.items()]

#: Why the node refuses a command, by the key it counts it under on /diagnostics (the node's own
#: rules, src/ros/protocol.rs ``Rejection``): the reasons a check can name without a node.
NODE_REASONS = {
    "invalid_speed": f"speed is not one of {SPEEDS[0]}, {SPEEDS[1]}, ..., {SPEEDS[-1]}",
    "unknown_mode": f"sort mode is not {', '.join(_MODES[:-1])} or {_MODES[-1]}",
    "mode_on_basic_line": "the basic line has no sort mode",
    "stale": "stamp names a tick the line has already left",
    "unknown_tick": "stamp names no current tick (ahead of the line or between ticks)",
}


def node_reason(key: str | None) -> str | None:
    """``key: explanation`` as the node logs a refusal, or None."""
    return f"{key}: {NODE_REASONS[key]}" if key else None


@dataclass
class Answer:
    """The controller's answer to one tick, on one command topic, against the bag's."""

    tick: int
    stamp_ns: int
    topic: str  # cmd/speed, cmd/sort_mode or batch/cmd
    field: str  # speed, mode, header.stamp (batch/cmd: speeds[k], modes[k])
    recorded: Any
    answered: Any = None  # None: no answer
    status: str = "missing"  # matching, differing, missing
    episode: int | None = None
    step: int | None = None
    latency_ms: float | None = None
    late: bool = False  # answered, but after the answer timeout
    reason: str | None = None  # the node's refusal, when the node would refuse the answer

    def where(self) -> str:
        text = f"tick {self.tick} (stamp {show_ns(self.stamp_ns)} s"
        if self.episode is not None:
            text += f", episode {self.episode} step {self.step}"
        return text + ")"

    def __str__(self) -> str:
        if self.status == "missing":
            return f"{self.topic} at {self.where()}: no answer" + (" in time (it came late)" if self.late else "")
        text = (
            f"{self.topic} at {self.where()}, field {self.field}: bag {_show(self.recorded)}, "
            f"controller {_show(self.answered)}"
        )
        return text + (f" (the node refuses it: {self.reason})" if self.reason else "")


def _show(value: Any) -> str:
    """A value as the summary shows it: a stamp as seconds, anything else as its repr."""
    if isinstance(value, dict) and set(value) == {"sec", "nanosec"}:
        return show_ns(int(value["sec"]) * 1_000_000_000 + int(value["nanosec"])) + " s"
    return repr(value)


@dataclass
class Figures:
    """An episode's figures: reward, mean accuracy over its steps, final purity, speed changes."""

    steps: int
    reward: float
    accuracy: float
    purity: float
    speed_changes: int

    @classmethod
    def of(cls, states: list[dict]) -> Figures:
        """From the states of one episode in step order (step 0, the reset's, first)."""
        stepped = [s for s in states if s["step"] > 0]
        last = states[-1]
        accuracy = sum(float(s["accuracy"]) for s in stepped) / len(stepped) if stepped else 0.0
        return cls(
            int(last["step"]),
            float(last["cumulative_reward"]),
            accuracy,
            float(last["purity"]),
            int(last["speed_changes"]),
        )


@dataclass
class Tolerance:
    """How much worse than the bag a figure may be: absolute, or ``percent`` of the bag's value."""

    value: float = 0.0
    percent: bool = False

    @classmethod
    def parse(cls, text: str | float | None, name: str) -> Tolerance:
        """``0.5`` or ``5%`` (ValueError naming the flag and the value otherwise)."""
        if text is None:
            return cls()
        raw = str(text).strip()
        percent = raw.endswith("%")
        try:
            value = float(raw[:-1] if percent else raw)
        except ValueError:
            value = float("nan")
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"{name} {text!r}: expected a number >= 0, or a percentage such as 5%")
        return cls(value, percent)

    def allowed(self, bag_value: float) -> float:
        # (a tiny margin: the run's sums and the bag's are the same float operations, but a
        # figure printed and parsed back may be off in the last bit)
        return (abs(bag_value) * self.value / 100 if self.percent else self.value) + 1e-9

    def __str__(self) -> str:
        return f"{self.value:g}%" if self.percent else f"{self.value:g}"


@dataclass
class EpisodeResult:
    """One episode of a closed-loop check: the bag's figures against the run's."""

    episode: int  # the bag's episode number
    bag: Figures
    run: Figures | None  # None: the run never got to this episode
    parted: str | None = None  # the first tick where the trajectories part, described
    failures: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.failures

    def judge(self, tolerances: dict[str, Tolerance]) -> None:
        """Equal or better passes; worse passes within the tolerance of that figure."""
        if self.run is None:
            self.failures.append("the run did not complete this episode")
            return
        if self.run.steps < self.bag.steps:
            self.failures.append(f"the run stopped at step {self.run.steps} of {self.bag.steps} (no answer)")
        for name, tol in tolerances.items():
            was, now = getattr(self.bag, name), getattr(self.run, name)
            if was - now > tol.allowed(was):
                self.failures.append(
                    f"{name} {now:.6g} is worse than the bag's {was:.6g} by {was - now:.6g} (allowed: {tol})"
                )

    def describe(self) -> str:
        b, r = self.bag, self.run
        if r is None:
            return f"episode {self.episode}: not run"
        return (
            f"episode {self.episode}: reward {r.reward:.4g} (bag {b.reward:.4g}), accuracy {r.accuracy:.4f} "
            f"(bag {b.accuracy:.4f}), purity {r.purity:.4f} (bag {b.purity:.4f}), speed changes "
            f"{r.speed_changes} (bag {b.speed_changes}); "
            + (f"trajectories part at {self.parted}" if self.parted else "same trajectory")
            + ("" if self.passed else " -> FAILED: " + "; ".join(self.failures))
        )


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(len(ordered) * q))]


@dataclass
class Verdict:
    """The outcome of one check. ``passed`` / ``exit_code`` decide; ``summary()`` says why."""

    bag: str
    closed_loop: bool = False
    namespace: str = ""
    controller: list[str] | None = None
    exit_code: int = EXIT_PASS
    error: str | None = None  # bad input (2) or the run failed (3): what happened
    answers: list[Answer] = field(default_factory=list)  # open loop: one per expected command
    wrong_stamps: list[Answer] = field(default_factory=list)  # commands that answered no tick of the bag
    episodes: list[EpisodeResult] = field(default_factory=list)  # closed loop
    tolerances: dict[str, str] = field(default_factory=dict)
    ticks: int = 0  # ticks played (open loop) or run (closed loop)
    seconds: float = 0.0
    notes: list[str] = field(default_factory=list)
    recorded: str | None = None  # --record: the run's bag

    @property
    def passed(self) -> bool:
        return self.exit_code == EXIT_PASS

    # -- what is counted -----------------------------------------------------------------------
    def count(self, status: str) -> int:
        return sum(1 for a in self.answers if a.status == status)

    @property
    def differences(self) -> list[Answer]:
        """Differing answers and wrong stamps, in tick order (a wrong stamp after the others)."""
        found = [a for a in self.answers if a.status == "differing"] + self.wrong_stamps
        return sorted(found, key=lambda a: (a.stamp_ns, a.field == "header.stamp"))

    @property
    def first_difference(self) -> Answer | None:
        return next(iter(self.differences), None)

    def latency(self) -> dict[str, float] | None:
        """Answer latency (ms, from the tick's publication to the command) over answered ticks."""
        values = [a.latency_ms for a in self.answers if a.latency_ms is not None]
        if not values:
            return None
        return {
            "p50": _percentile(values, 0.5),
            "p99": _percentile(values, 0.99),
            "max": max(values),
            "count": len(values),
        }

    def decide(self) -> None:
        """Sets exit_code from what was found (bad input and run failures are set where they happen)."""
        if self.exit_code in (EXIT_BAD_INPUT, EXIT_RUN_FAILED):
            return
        failed = bool(self.differences) or self.count("missing") > 0
        failed = failed or any(not e.passed for e in self.episodes)
        self.exit_code = EXIT_FAILED_VERDICT if failed else EXIT_PASS

    # -- output --------------------------------------------------------------------------------
    def summary(self) -> str:
        """The human summary the command line prints."""
        kind = "closed loop" if self.closed_loop else "open loop"
        head = f"check {self.bag} ({kind}, namespace {self.namespace or '?'})"
        if self.controller:
            head += f", controller: {' '.join(self.controller)}"
        lines = [head]
        if self.error:
            what = "bad input" if self.exit_code == EXIT_BAD_INPUT else "the run failed"
            lines.append(f"{what}: {self.error}")
        if (self.answers or self.wrong_stamps) and not self.closed_loop:
            lines.append(
                f"{self.ticks} ticks played in {self.seconds:.1f} s; answers: {self.count('matching')} "
                f"matching, {self.count('differing')} differing, {self.count('missing')} missing "
                f"({sum(a.late for a in self.answers)} of them late), {len(self.wrong_stamps)} with a "
                "stamp of no expected tick"
            )
            lat = self.latency()
            if lat:
                lines.append(
                    f"answer latency: p50 {lat['p50']:.2f} ms, p99 {lat['p99']:.2f} ms, "
                    f"max {lat['max']:.2f} ms ({lat['count']} answers)"
                )
            differences = self.differences
            if differences:
                lines.append(f"first difference: {differences[0]}")
                lines += [f"  then: {d}" for d in differences[1:10]]
                if len(differences) > 10:
                    lines.append(f"  ... {len(differences) - 10} more (--json lists them)")
            missing = [a for a in self.answers if a.status == "missing"]
            if missing:
                shown = ", ".join(str(a.tick) for a in missing[:10]) + (" ..." if len(missing) > 10 else "")
                lines.append(f"no answer in time ({len(missing)}): ticks {shown}; first: {missing[0]}")
        if self.episodes:
            lines.append(
                f"{self.ticks} ticks run in {self.seconds:.1f} s; tolerances: "
                + ", ".join(f"{k} {v}" for k, v in self.tolerances.items())
            )
            lines += [e.describe() for e in self.episodes]
        lines += self.notes
        if self.recorded:
            lines.append(f"recorded the run: {self.recorded}")
        lines.append("PASSED" if self.passed else f"FAILED (exit {self.exit_code})")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        counts = {s: self.count(s) for s in ("matching", "differing", "missing")}
        counts.update(late=sum(a.late for a in self.answers), wrong_stamp=len(self.wrong_stamps))
        first = self.first_difference
        return {
            "bag": self.bag,
            "closed_loop": self.closed_loop,
            "namespace": self.namespace,
            "controller": self.controller,
            "passed": self.passed,
            "exit_code": self.exit_code,
            "error": self.error,
            "ticks": self.ticks,
            "seconds": round(self.seconds, 3),
            "answers": counts,
            "first_difference": asdict(first) | {"message": str(first)} if first else None,
            "differences": [asdict(a) | {"message": str(a)} for a in self.differences[:100]],
            "missing_ticks": [a.tick for a in self.answers if a.status == "missing"],
            "latency_ms": self.latency(),
            "tolerances": self.tolerances,
            "episodes": [asdict(e) | {"passed": e.passed} for e in self.episodes],
            "notes": self.notes,
            "recorded": self.recorded,
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, default=str)

    def to_junit(self) -> str:
        """JUnit XML: one test case per episode of the bag, one for missing or late answers (and
        one for the run itself when it failed), as CI systems and ``colcon test-result`` read it."""
        return _junit(self)


def _case(suite: ET.Element, name: str, failure: str | None = None, kind: str = "failure") -> None:
    case = ET.SubElement(suite, "testcase", classname="sorting_line_bag_check", name=name, time="0")
    if failure:
        ET.SubElement(case, kind, message=failure.splitlines()[0][:500]).text = failure


def _episode_cases(v: Verdict, suite: ET.Element) -> None:
    if v.closed_loop:
        for e in v.episodes:
            _case(suite, f"episode {e.episode}", None if e.passed else e.describe())
        return
    by_episode: dict[Any, list[Answer]] = {}
    for a in v.answers + v.wrong_stamps:
        by_episode.setdefault(a.episode, []).append(a)
    for episode in sorted(by_episode, key=lambda e: -1 if e is None else e):
        wrong = sorted(
            (a for a in by_episode[episode] if a.status == "differing" or a in v.wrong_stamps), key=lambda a: a.stamp_ns
        )
        text = "\n".join(str(a) for a in wrong[:20]) + (f"\n... {len(wrong) - 20} more" if len(wrong) > 20 else "")
        _case(
            suite,
            f"episode {episode}" if episode is not None else "before the first episode",
            f"{len(wrong)} differing answers:\n{text}" if wrong else None,
        )


def _junit(v: Verdict) -> str:
    suite = ET.Element("testsuite", name=f"sorting-line-bag check {v.bag}", time=f"{v.seconds:.3f}")
    if v.error:
        _case(suite, "run", v.error, "error")
    _episode_cases(v, suite)
    missing = [a for a in v.answers if a.status == "missing"]
    text = "\n".join(str(a) for a in missing[:50]) + (f"\n... {len(missing) - 50} more" if len(missing) > 50 else "")
    _case(
        suite,
        "missing or late answers",
        f"{len(missing)} ticks without an answer in time:\n{text}" if missing else None,
    )
    cases = suite.findall("testcase")
    suite.set("tests", str(len(cases)))
    suite.set("failures", str(sum(1 for c in cases if c.find("failure") is not None)))
    suite.set("errors", str(sum(1 for c in cases if c.find("error") is not None)))
    root = ET.Element("testsuites")
    root.append(suite)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"
