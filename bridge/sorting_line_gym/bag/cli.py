"""`sorting-line-bag`: record, replay, play and describe ROS 2 bags of a sorting line.

    sorting-line-bag record --namespace /plant -o run1            # until Ctrl-C
    sorting-line-bag replay run1                                  # exit 0 identical, 1 differs
    sorting-line-bag play run1 --namespace /test --rate 2         # the sensors, twice as fast
    sorting-line-bag play run1 --namespace /test --lockstep       # tick by tick, after each answer
    sorting-line-bag info run1
    sorting-line-bag check run1 --controller 'my_controller --setup D'   # 0 pass, 1 fail (see check --help)
    sorting-line-bag record --namespace /plant -o run2 --compression zstd --max-bag-size 100000000
    sorting-line-bag reindex run2                                 # after the recorder was killed

Exit codes: 0 done (replay: identical), 1 replay found a difference, 2 bad input (a missing or
corrupt bag, an unknown topic, an existing or unwritable output, a bad option, a bag replay cannot
use), 3 the graph, the replay node or the disk failed (a wait timed out, the node died, the disk
filled while recording). SIGINT/SIGTERM end `record` and `play` cleanly (the bag is closed with
its metadata); a recorder killed outright leaves a bag `reindex` recovers, with everything received
up to about half a second before the kill (docs/reliability.md, "Recording").

Each subcommand is one function here, a front for a library function (record, replay, play,
check_controller) that it calls with ``call_with_flags``: the function's keyword-only parameters
take the flags of the same name, the call names the rest. The verbs that talk to a ROS graph
(record, replay, play, check) import their tool when they run: those import rclpy (most of a
second to start), which ``info`` and ``reindex``, reading bags from disk, do without.
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path
from typing import get_args, get_type_hints

from ..line.errors import BridgeError
from ..line.flags import call_with_flags
from ..line.topics import BATCH_CMD, CLOCK, DIAGNOSTICS, RESET_EVENT, SORT_MODE_CMD, SPEED_CMD
from ..line.vocabulary import SETUPS
from .format.errors import BagError, BagWriteError
from .format.options import (
    MIN_SPLIT_DURATION,
    MIN_SPLIT_SIZE,
    NodeOverrides,
    WriteOptions,
    check_compression,
    check_max_bag_duration,
    check_max_bag_size,
)
from .storage.reader import describe, open_bag
from .storage.recovery import reindex

EXIT_DIFFERENT, EXIT_BAD_INPUT, EXIT_FAILED = 1, 2, 3


class _Stop:
    """SIGINT/SIGTERM set a flag the tool's loop checks (rclpy's own handlers would shut the
    context down under a running callback)."""

    def __init__(self):
        self.signal: str | None = None
        self._previous = {sig: signal.signal(sig, self._on) for sig in (signal.SIGINT, signal.SIGTERM)}

    def __enter__(self) -> _Stop:
        return self

    def __exit__(self, *_exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def _on(self, signum, _frame):
        self.signal = signal.Signals(signum).name

    def __call__(self) -> bool:
        return self.signal is not None


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sorting-line-bag",
        description=__doc__.split("\n\n")[0],
        epilog="docs/bags.md describes what a bag contains.",
    )
    sub = p.add_subparsers(dest="command", required=True)
    _record_parser(sub)
    _replay_parser(sub)
    _play_parser(sub)
    i = sub.add_parser("info", help="the topics, types, counts and line description of a bag")
    i.add_argument("bag", help="the bag directory")
    _check_parser(sub)
    x = sub.add_parser(
        "reindex",
        help="recover a bag whose recorder was killed: rebuild metadata.yaml (and the "
        "MCAP summary of a cut file) from what is on disk, as `ros2 bag reindex`",
    )
    x.add_argument("bag", help="the bag directory")
    return p


def _record_parser(sub) -> None:
    r = sub.add_parser(
        "record", help="record a running line's topics into a bag directory", description=RECORD_DESCRIPTION
    )
    r.add_argument("--namespace", required=True, help="the line's namespace (e.g. /plant or /plant/line_2)")
    r.add_argument("-o", "--output", required=True, help="the bag directory to create (must not exist)")
    r.add_argument(
        "--topic",
        action="append",
        dest="topics",
        metavar="TOPIC",
        help="record this topic (absolute, or relative to the namespace); repeatable. Default: "
        f"the line's topics, its commands, its resets ({RESET_EVENT}) and {CLOCK}",
    )
    r.add_argument("--diagnostics", action="store_true", help=f"also record {DIAGNOSTICS} (wall-clock, not replayed)")
    r.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    r.add_argument("--max-ticks", type=int, default=None, help="stop once this many states were recorded")
    r.add_argument("--wait", type=float, default=10.0, help="how long to wait for the line to show up (s)")
    _add_write_options(r)


def _replay_parser(sub) -> None:
    rp = sub.add_parser("replay", help="replay a bag's resets and commands into a fresh lock-step node and compare")
    rp.add_argument("bag", help="the bag directory to replay")
    _add_node_options(rp, "")
    rp.add_argument("--step-timeout", type=float, default=5.0, help="longest wait for one tick or reset (s)")
    rp.add_argument("--no-progress", action="store_true", help="no progress bar")


def _play_parser(sub) -> None:
    pl = sub.add_parser("play", help="publish a bag's recorded node data again, with its timing")
    pl.add_argument("bag", help="the bag directory to play")
    pl.add_argument("--rate", type=float, default=1.0, help="speed factor: 2 = twice as fast, 0 = no waiting")
    pl.add_argument("--namespace", default=None, help="publish the line's topics in this namespace instead")
    pl.add_argument(
        "--topic",
        action="append",
        dest="topics",
        metavar="TOPIC",
        help="play only this topic (absolute or relative to the recorded line); repeatable",
    )
    pl.add_argument(
        "--wait-for",
        action="append",
        default=None,
        metavar="TOPIC",
        help="wait for a subscriber on this topic before playing (default: the line's input)",
    )
    pl.add_argument("--no-wait", action="store_true", help="do not wait for subscribers")
    pl.add_argument("--wait", type=float, default=10.0, help="how long to wait for subscribers (s)")
    pl.add_argument(
        "--lockstep",
        action="store_true",
        help="tick by tick instead of by time: each tick after the controller answered the previous one "
        f"on {SPEED_CMD} (when the bag shows an answer), as a lock-step node would",
    )
    pl.add_argument("--answer-timeout", type=float, default=5.0, help="--lockstep: longest wait for an answer (s)")


def _check_parser(sub) -> None:
    c = sub.add_parser(
        "check",
        help="test a controller against a bag: a verdict (exit 0 pass, 1 fail, 2 bad input, "
        "3 the run failed), as text, JSON and JUnit XML",
        description="Does a controller still answer a recorded line as it did, and is it no worse? "
        "Tests it against a bag at topic level.",
        epilog=CHECK_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    c.add_argument("bag", help="the bag directory to check against")
    c.add_argument(
        "--namespace",
        default=None,
        help="where the line is played (open loop) or served (closed loop); default: the bag's line namespace",
    )
    c.add_argument(
        "--controller",
        default=None,
        metavar="CMD",
        help="start this command (a shell-like string, e.g. 'sorting-line-controller --setup D') with "
        "'--ros-args -r __ns:=<namespace>' appended, and stop it at the end; default: wait for a "
        "controller already running in the namespace",
    )
    c.add_argument(
        "--closed-loop",
        action="store_true",
        help="a fresh lock-step node with the bag's options, reset as the bag was, driven by the "
        "controller; its episodes are compared with the bag's",
    )
    c.add_argument("--record", default=None, metavar="OUT", help="--closed-loop: record the run into bag directory OUT")
    c.add_argument("--json", default=None, metavar="FILE", help="write the verdict as JSON to FILE")
    c.add_argument(
        "--junit",
        default=None,
        metavar="FILE",
        help="write the verdict as JUnit XML to FILE (a test case per episode, one for missing answers)",
    )
    _add_check_limits(c)
    _add_node_options(c, "--closed-loop: ")
    c.add_argument("--no-progress", action="store_true", help="no progress bar (there is none when stderr is no tty)")


def _add_check_limits(c: argparse.ArgumentParser) -> None:
    """check's waits and closed-loop tolerances."""
    c.add_argument(
        "--answer-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="longest wait for the controller's answer to one tick (s); the run goes on without it",
    )
    c.add_argument(
        "--wait",
        type=float,
        default=None,
        metavar="S",
        help="longest wait for the controller to appear (s; default 60 with --controller, else 10)",
    )
    for figure in ("reward", "accuracy", "purity"):
        c.add_argument(
            f"--max-{figure}-drop",
            default=None,
            metavar="X|X%",
            help=f"--closed-loop: how much lower than the bag's an episode's {figure} may be, absolute "
            "or as a percentage of the bag's (default 0: equal or better)",
        )


#: Node options a fresh node for a bag takes from flags (replay, closed-loop check), named as
#: `sorting_line node` names them, each with its type: NodeOverrides' fields but ``setup``.
NODE_OPTIONS = [
    (name.replace("_", "-"), next(t for t in get_args(hint) if t is not type(None)))
    for name, hint in get_type_hints(NodeOverrides).items()
    if name != "setup"
]


def _add_node_options(parser, scope: str) -> None:
    """The node options and --setup, for a bag that does not store them (or to override them)."""
    for name, kind in NODE_OPTIONS:
        parser.add_argument(
            f"--{name}",
            type=kind,
            default=None,
            help=f"{scope}the node option, overriding the bag's (needed if the bag does not store it)",
        )
    parser.add_argument(
        "--setup",
        choices=list(SETUPS),
        default=None,
        help=f"{scope}the paper's setup of the recorded line: its input, obs-noise, action-penalty and "
        "threshold (for a bag that does not store them; the flags above override it)",
    )


def _node_options(args) -> NodeOverrides:
    return NodeOverrides(**{k: getattr(args, k) for k in get_type_hints(NodeOverrides)})


CHECK_EPILOG = f"""\
open loop (default): the bag's node side is played tick by tick (as play --lockstep); each tick the
  bag shows a command for waits for the controller's answer ({SPEED_CMD}, {SORT_MODE_CMD}, or {BATCH_CMD})
  and compares it with the bag's: the first difference by tick, topic and field, counts of
  matching, differing and missing answers, answer latency p50/p99/max. Passes when every answer
  matches and none is missing.
closed loop: episode reward, mean accuracy, purity, speed changes and the first tick where the
  trajectories part, per episode of the bag; equal or better passes (tolerances: --max-*-drop).
exit codes: 0 pass, 1 the verdict failed, 2 bad input, 3 the run failed (the controller died,
  the node failed, nobody answered).
examples:
  sorting-line-bag check run1 --controller 'sorting-line-controller --setup D' --junit check.xml
  sorting-line-bag check run1 --closed-loop --max-reward-drop 5% --controller './my_node'
"""


RECORD_DESCRIPTION = f"""\
Records a running line into a ROS 2 bag (metadata.yaml + MCAP) as it goes: whatever arrived more
than about half a second ago is on disk, so a recorder killed outright (SIGKILL, the OOM killer, a
pulled plug) leaves a bag that `sorting-line-bag reindex BAG` recovers. At the end it compares what
it received with the node's own {DIAGNOSTICS} counters and says how many messages it missed, and on
which topics (also shown by `info`). A full disk stops it with exit code 3 and a readable bag."""


def _option(check, kind):
    """An argparse type from a writer check: the check's message names the value and the allowed range."""

    def parse(text: str):
        try:
            return check(kind(text))
        except ValueError:
            what = "whole number" if kind is int else "number"
            raise argparse.ArgumentTypeError(f"{text!r} is not a {what}") from None
        except BagError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    return parse


def _add_write_options(r: argparse.ArgumentParser) -> None:
    splits = (
        (
            "--max-bag-size",
            _option(check_max_bag_size, int),
            0,
            "BYTES",
            f"start a new MCAP file in the bag once the current one holds this many bytes (0: never, "
            f"the default; else >= {MIN_SPLIT_SIZE}), as `ros2 bag record --max-bag-size`",
        ),
        (
            "--max-bag-duration",
            _option(check_max_bag_duration, float),
            0.0,
            "S",
            f"start a new MCAP file once the current one spans this many seconds (0: never, the "
            f"default; else >= {MIN_SPLIT_DURATION:g})",
        ),
    )
    for flag, kind, default, metavar, text in splits:
        r.add_argument(flag, type=kind, default=default, metavar=metavar, help=text)
    r.add_argument(
        "--compression",
        type=_option(check_compression, str),
        default="none",
        help="compress each MCAP chunk: zstd (as rosbag2's zstd presets; rosbags, mcap and Foxglove "
        "read it), lz4, or none (the default)",
    )


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(sys.argv[1:] if argv is None else argv)
    run = COMMANDS.get(args.command)
    if run is None:
        raise AssertionError(f"unhandled command {args.command}")
    try:
        return run(args)
    except (BagError, BridgeError, TimeoutError) as e:
        print(f"sorting-line-bag {args.command}: {e}", file=sys.stderr)
        # A bag that cannot be written (a full disk) failed the run; any other BagError is bad input.
        return EXIT_BAD_INPUT if isinstance(e, BagError) and not isinstance(e, BagWriteError) else EXIT_FAILED


def _say(text: str) -> None:
    """What a subcommand reports while it runs (ready, waiting for ...), at once."""
    print(text, flush=True)


def _progress(args) -> bool:
    """A progress bar unless --no-progress, and only on a terminal."""
    return not args.no_progress and sys.stderr.isatty()


def _info(args) -> int:
    print(describe(open_bag(args.bag)))
    return 0


def _reindex(args) -> int:
    print(reindex(args.bag).summary())
    return 0


def _record(args) -> int:
    from .transport.record import record  # rclpy: see the module's docstring

    options = WriteOptions(args.max_bag_size, args.max_bag_duration, args.compression)
    with _Stop() as stop:
        result = call_with_flags(
            record, args, args.namespace, args.output, args.topics, stop=stop, on_ready=_say, options=options
        )
    print(("stopped by " + stop.signal + ": " if stop.signal else "") + result.summary(), flush=True)
    return 0


def _replay(args) -> int:
    from .transport.replay import replay  # rclpy: see the module's docstring

    result = call_with_flags(replay, args, args.bag, _node_options(args), progress=_progress(args))
    print(result.report(), flush=True)
    return 0 if result.identical else EXIT_DIFFERENT


def _play(args) -> int:
    from .transport.play import play  # rclpy: see the module's docstring

    wait_for = [] if args.no_wait else args.wait_for
    with _Stop() as stop:
        result = call_with_flags(play, args, args.bag, wait_for=wait_for, stop=stop, on_ready=_say)
    print(result.summary(), flush=True)
    return 0


def _check(args) -> int:
    from .check.checker import check_controller  # rclpy: see the module's docstring

    overrides = _node_options(args)
    with _Stop() as stop:
        verdict = call_with_flags(
            check_controller, args, args.bag, overrides=overrides, stop=stop, progress=_progress(args)
        )
    print(verdict.summary(), flush=True)
    if verdict.error:
        print(f"sorting-line-bag check: {verdict.error}", file=sys.stderr, flush=True)
    for path, text in ((args.json, verdict.to_json), (args.junit, verdict.to_junit)):
        if path:
            Path(path).write_text(text())
    return verdict.exit_code


#: What each subcommand runs: its exit code (errors that end it are main's).
COMMANDS = {"info": _info, "reindex": _reindex, "record": _record, "replay": _replay, "check": _check, "play": _play}

if __name__ == "__main__":
    sys.exit(main())
