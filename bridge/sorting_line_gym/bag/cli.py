"""`sorting-line-bag`: record, replay, play and describe ROS 2 bags of a sorting line.

    sorting-line-bag record --namespace /plant -o run1            # until Ctrl-C
    sorting-line-bag replay run1                                  # exit 0 identical, 1 differs
    sorting-line-bag play run1 --namespace /test --rate 2         # the sensors, twice as fast
    sorting-line-bag play run1 --namespace /test --lockstep       # tick by tick, after each answer
    sorting-line-bag info run1

Exit codes: 0 done (replay: identical), 1 replay found a difference, 2 bad input (a missing or
corrupt bag, an unknown topic, an existing output, a bag replay cannot use), 3 the graph or the
replay node failed (a wait timed out, the node died). SIGINT/SIGTERM end `record` and `play`
cleanly (the bag is closed with its metadata).
"""

from __future__ import annotations

import argparse
import signal
import sys

from ..line.errors import BridgeError
from ..line.vocabulary import SETUPS
from .bagfile import BagError, describe, open_bag

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
    p = argparse.ArgumentParser(prog="sorting-line-bag", description=__doc__.split("\n\n")[0],
                                epilog="README, section 'Recorded bags', describes what a bag contains.")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("record", help="record a running line's topics into a bag directory")
    r.add_argument("--namespace", required=True, help="the line's namespace (e.g. /plant or /plant/line_2)")
    r.add_argument("-o", "--output", required=True, help="the bag directory to create (must not exist)")
    r.add_argument("--topic", action="append", dest="topics", metavar="TOPIC",
                   help="record this topic (absolute, or relative to the namespace); repeatable. Default: "
                        "the line's topics, its commands, its resets (events/reset) and /clock")
    r.add_argument("--diagnostics", action="store_true", help="also record /diagnostics (wall-clock, not replayed)")
    r.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    r.add_argument("--max-ticks", type=int, default=None, help="stop once this many states were recorded")
    r.add_argument("--wait", type=float, default=10.0, help="how long to wait for the line to show up (s)")

    rp = sub.add_parser("replay", help="replay a bag's resets and commands into a fresh lock-step node and compare")
    rp.add_argument("bag")
    for name, kind in [("variant", str), ("input", str), ("obs-noise", float), ("action-penalty", float),
                       ("threshold", float), ("max-steps", int), ("seed", int), ("tick-period", float)]:
        rp.add_argument(f"--{name}", type=kind, default=None,
                        help="override the node option the bag stores (needed if the bag does not store it)")
    rp.add_argument("--setup", choices=list(SETUPS), default=None,
                    help="the paper's setup of the recorded line: its input, obs-noise, action-penalty and threshold "
                         "(for a bag that does not store them; the flags above override it)")
    rp.add_argument("--step-timeout", type=float, default=5.0, help="longest wait for one tick or reset (s)")
    rp.add_argument("--no-progress", action="store_true", help="no progress bar")

    pl = sub.add_parser("play", help="publish a bag's recorded node data again, with its timing")
    pl.add_argument("bag")
    pl.add_argument("--rate", type=float, default=1.0, help="speed factor: 2 = twice as fast, 0 = no waiting")
    pl.add_argument("--namespace", default=None, help="publish the line's topics in this namespace instead")
    pl.add_argument("--topic", action="append", dest="topics", metavar="TOPIC",
                    help="play only this topic (absolute or relative to the recorded line); repeatable")
    pl.add_argument("--wait-for", action="append", default=None, metavar="TOPIC",
                    help="wait for a subscriber on this topic before playing (default: the line's input)")
    pl.add_argument("--no-wait", action="store_true", help="do not wait for subscribers")
    pl.add_argument("--wait", type=float, default=10.0, help="how long to wait for subscribers (s)")
    pl.add_argument("--lockstep", action="store_true",
                    help="tick by tick instead of by time: each tick after the controller answered the previous one "
                         "on cmd/speed (when the bag shows an answer), as a lock-step node would")
    pl.add_argument("--answer-timeout", type=float, default=5.0, help="--lockstep: longest wait for an answer (s)")

    i = sub.add_parser("info", help="the topics, types, counts and line description of a bag")
    i.add_argument("bag")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        if args.command == "info":
            print(describe(open_bag(args.bag)))
            return 0
        if args.command == "record":
            from .record import record

            with _Stop() as stop:
                result = record(args.namespace, args.output, args.topics, duration=args.duration,
                                max_ticks=args.max_ticks, wait=args.wait, stop=stop,
                                on_ready=lambda s: print(s, flush=True), diagnostics=args.diagnostics)
            print(("stopped by " + stop.signal + ": " if stop.signal else "") + result.summary(), flush=True)
            return 0
        if args.command == "replay":
            from .replay import replay

            overrides = {k: getattr(args, k) for k in ("variant", "input", "obs_noise", "action_penalty", "threshold",
                                                       "max_steps", "seed", "tick_period", "setup")}
            result = replay(args.bag, overrides, step_timeout=args.step_timeout,
                            progress=not args.no_progress and sys.stderr.isatty())
            print(result.report(), flush=True)
            return 0 if result.identical else EXIT_DIFFERENT
        if args.command == "play":
            from .play import play

            with _Stop() as stop:
                result = play(args.bag, rate=args.rate, topics=args.topics, namespace=args.namespace,
                              wait_for=[] if args.no_wait else args.wait_for, wait=args.wait, stop=stop,
                              on_ready=lambda s: print(s, flush=True), lockstep=args.lockstep,
                              answer_timeout=args.answer_timeout)
            print(result.summary(), flush=True)
            return 0
    except BagError as e:
        print(f"sorting-line-bag {args.command}: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (BridgeError, TimeoutError) as e:
        print(f"sorting-line-bag {args.command}: {e}", file=sys.stderr)
        return EXIT_FAILED
    raise AssertionError(f"unhandled command {args.command}")


if __name__ == "__main__":
    sys.exit(main())
