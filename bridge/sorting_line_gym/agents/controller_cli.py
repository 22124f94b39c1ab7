"""`sorting-line-controller`: a rule-based agent or a learned policy as an rclpy node that drives a
line live (the node: ``controller``).

    sorting_line node --setup B --variant advanced --mode realtime --rate 10 --ros-args -r __ns:=/plant &
    sorting-line-controller --namespace /plant --setup B --variant advanced --agent rba-hold
    sorting-line-controller --namespace /plant --policy policy.onnx          # a learned policy (ONNX)
    sorting-line-controller --namespace /plant --policy ppo_B_advanced_seed42.zip   # SB3, if installed

``--policy FILE``: an ONNX file of `sorting-line-export` (run by onnxruntime; torch is never
imported) or an SB3 model zip (with the training record beside it). The line it was trained for
(its metadata) must be the line the controller drives: the line node's parameters are read at
start (``line_parameters``; ``--line-timeout`` seconds, else ``--setup``/``--variant`` stand for
them) and a policy trained for another variant, setup or evolution schedule is refused, naming
both, unless ``--allow-mismatch``. ``--fallback rba-hold``: a tick the policy cannot answer (its
runtime fails, a reading is not a number) is answered by rba-hold, logged and counted on
``/diagnostics``; without it the controller says why and stops.

Several lines (``--lines N`` on the node): one controller per line, each with ``--namespace
<ns>/line_<k>`` (or a ``__ns`` remap); the launch file starts one for a one-line node.

Exit codes: 0 stopped by SIGINT/SIGTERM, 1 the policy failed on a tick (no fallback), 2 bad input
(a flag, a file that is no usable policy, a policy for another line, a missing package).
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from ..line.errors import BridgeError
from ..line.policy_card import PolicyCard
from ..line.vocabulary import SETUP_SPAN, SETUPS, VARIANT_CHOICE, VARIANTS
from ..ros.context import check_domain_id
from .controller import SPIN_PERIOD, ControllerNode
from .learned_policy import LearnedAgent, PolicyFileError, load_learned_policy
from .line_parameters import LineDescription, mismatches, read_line
from .policies import RuleBasedAgent

PROG = "sorting-line-controller"


class Refused(Exception):
    """A usage error: the message is printed, the exit code is 2."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description=__doc__.split("\n\n")[0],
        epilog="ROS arguments go after --ros-args (e.g. --ros-args -r __ns:=/plant).",
    )
    p.add_argument(
        "--namespace", default=None, help="the line's namespace (the node's, or <node ns>/line_<k> with --lines N > 1)"
    )
    p.add_argument(
        "--setup", choices=list(SETUPS), help=f"the setup of the node's line ({SETUP_SPAN}; --agent needs it)"
    )
    p.add_argument("--variant", choices=VARIANTS, help=f"{VARIANT_CHOICE} line (default: the policy's, else basic)")
    who = p.add_mutually_exclusive_group()
    who.add_argument("--agent", choices=["rba", "rba-hold"], help="a rule-based policy (default rba)")
    who.add_argument("--policy", type=Path, metavar="FILE", help="a learned policy: POLICY.onnx or an SB3 MODEL.zip")
    p.add_argument("--fallback", choices=["rba-hold"], help="answers the ticks the policy cannot (--policy)")
    p.add_argument(
        "--allow-mismatch", action="store_true", help="run a policy trained for another line (or without metadata)"
    )
    p.add_argument(
        "--line-timeout", type=float, default=5.0, help="seconds to find the line node's parameters (default 5)"
    )
    p.add_argument("--node-name", default="sorting_line_controller", help="this ROS node's name (default %(default)s)")
    p.add_argument(
        "--decision-log",
        default=None,
        metavar="FILE",
        help="write one JSON line per decision (readings, decision, latency) to FILE",
    )
    return p


def rule_agent(setup: str | None, variant: str, name: str) -> RuleBasedAgent:
    if setup is None:
        raise Refused(f"--agent {name} needs --setup (the table depends on the line's setup)")
    try:
        return RuleBasedAgent(setup, variant, hold=name == "rba-hold")
    except Exception as e:  # noqa: BLE001 - reported as a usage error
        raise Refused(f"cannot load the rule table: {e}") from None


def flags_line(args, card: PolicyCard | None) -> LineDescription:
    """The line as the flags describe it (the policy's card fills what they leave out)."""
    variant = args.variant or (card.variant if card else "basic")
    setup = args.setup or (card.setup if card else None)
    return LineDescription(setup, variant, card.evolution if card else "", "the command line")


def check_fit(policy, line: LineDescription, allow: bool, log) -> None:
    """Refuses (Refused) a policy whose training line is not ``line``, unless ``allow``."""
    if policy.card is None:
        if not allow:
            raise Refused(
                f"{policy.path}: it has no sorting_line metadata (not written by sorting-line-export), so what it "
                "was trained for is unknown; --allow-mismatch runs it anyway"
            )
        wrong = [] if policy.variant == line.variant else [f"variant {policy.variant} vs {line.variant}"]
    else:
        wrong = mismatches(policy.card, line)
    if policy.variant != line.variant:
        # Shapes that do not fit cannot run at all, whatever --allow-mismatch says.
        raise Refused(f"{policy.path}: its shapes are the {policy.variant} line's; the line is {line.variant}")
    if wrong:
        text = (
            f"the policy was trained for {policy.card.describe() if policy.card else policy.variant}, "
            f"the line is {line.describe()} ({line.source}): {'; '.join(wrong)}"
        )
        if not allow:
            raise Refused(text + "; --allow-mismatch runs it anyway")
        log.warning(text + " (--allow-mismatch)")


def make_agents(args, node, executor):
    """(agent, fallback, line) for the flags; a policy is checked against the line first."""
    if args.policy is None:
        line = flags_line(args, None)
        return rule_agent(line.setup, line.variant, args.agent or "rba"), None, line
    policy = args.loaded_policy
    found = read_line(node, executor, node.get_namespace(), args.line_timeout)
    line = found or flags_line(args, policy.card)
    if found is None:
        node.get_logger().warning(
            f"no line node with parameters in {node.get_namespace()} within {args.line_timeout} s: "
            f"taking the line to be {line.describe()} (from the command line and the policy)"
        )
    elif args.setup or args.variant:
        check_fit(policy, flags_line(args, policy.card), args.allow_mismatch, node.get_logger())
    check_fit(policy, line, args.allow_mismatch, node.get_logger())
    agent = LearnedAgent(policy)
    fallback = rule_agent(line.setup, line.variant, args.fallback) if args.fallback else None
    node.get_logger().info(f"policy: {policy.describe()}; line: {line.describe()} ({line.source})")
    return agent, fallback, line


def run(args, full: list[str]) -> int:
    # Our own SIGINT/SIGTERM handling: the signal only sets a flag, and the loop below ends at the
    # next wake-up (at most SPIN_PERIOD later), with the context still up. rclpy's handlers would
    # shut the context down from another thread while a callback may be taking or publishing a
    # message, which then fails at random.
    stop: list[str] = []
    rclpy.init(args=full, signal_handler_options=SignalHandlerOptions.NO)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: stop.append(signal.Signals(signum).name))
    executor = SingleThreadedExecutor()
    node = probe = log = None
    try:
        probe = rclpy.create_node(f"{args.node_name}_line_check", namespace=args.namespace)
        executor.add_node(probe)
        agent, fallback, line = make_agents(args, probe, executor)
        executor.remove_node(probe)
        log = open(args.decision_log, "w") if args.decision_log else None  # noqa: SIM115 - closed below
        node = ControllerNode(
            agent,
            line.variant,
            namespace=args.namespace,
            node_name=args.node_name,
            decision_log=log,
            fallback=fallback,
            evolving=bool(line.evolution),
        )
        executor.add_node(node)
        while not stop and rclpy.ok() and node.failure is None:
            executor.spin_once(timeout_sec=SPIN_PERIOD)
        why = stop[0] if stop else ("policy failed" if node.failure else "shutdown")
        node.get_logger().info(f"{why}: stopping: {node.summary()}")
        return 1 if node.failure else 0
    finally:
        executor.shutdown(timeout_sec=1.0)
        for n in (node, probe):
            if n is not None:
                n.destroy_node()
        rclpy.try_shutdown()
        if log is not None:
            log.close()


def main(argv: list[str] | None = None) -> int:
    full = [PROG, *(sys.argv[1:] if argv is None else argv)]
    args = build_parser().parse_args(remove_ros_args(full)[1:])
    if args.fallback and args.policy is None:
        print(f"{PROG}: --fallback goes with --policy (a rule-based agent needs none)", file=sys.stderr)
        return 2
    if args.line_timeout < 0:
        print(f"{PROG}: --line-timeout = {args.line_timeout} is not valid: allowed 0 or more", file=sys.stderr)
        return 2
    try:
        check_domain_id()  # rmw_fastrtps would end the process without a word
    except BridgeError as e:
        print(f"{PROG}: {e}", file=sys.stderr)
        return 2
    if args.policy is not None:
        # A bad file fails before anything joins the graph.
        try:
            args.loaded_policy = load_learned_policy(args.policy)
        except PolicyFileError as e:
            print(f"{PROG}: {e}", file=sys.stderr)
            return 2
    try:
        return run(args, full)
    except (Refused, PolicyFileError) as e:
        print(f"{PROG}: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
