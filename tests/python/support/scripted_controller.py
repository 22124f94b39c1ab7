"""A small controller script for test_bag_check: answers each tick of a line with the commands a
bag recorded for it, except where told to misbehave. Written as a user's rclpy node would be
(relative topic names; the namespace comes from ``--ros-args -r __ns:=...``).

    python scripted_controller.py --bag tests/data/bags/basic_d --speed-at 60=0.7 --ros-args -r __ns:=/x

Misbehaviours (TICK = stamp in whole tick periods): ``--speed-at TICK=SPEED`` answers that tick
with SPEED; ``--stamp-shift-at TICK=S`` answers it with its stamp moved by S seconds; ``--skip
TICK`` (repeatable) or ``--skip-all`` does not answer; ``--skip-once TICK`` does not answer
it the first time it comes; ``--exit-at TICK=CODE`` writes a line on stderr and exits with CODE
when that tick comes. ``--batch`` answers on ``batch/cmd`` (one entry) instead of the line's topics.
"""

from __future__ import annotations

import argparse
import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from sorting_line_interfaces.msg import LineCommands, MaterialInput, SortModeCommand, SpeedCommand
from std_msgs.msg import Header

from sorting_line_gym.bag import open_bag
from sorting_line_gym.bag.storage.schema import stamp_ns
from sorting_line_gym.line.topics import BATCH_CMD, INPUT, SORT_MODE_CMD, SPEED_CMD

QOS = QoSProfile(
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
    history=HistoryPolicy.KEEP_LAST,
)


def _pairs(items: list[str], kind) -> dict[int, object]:
    return {int(k): kind(v) for k, v in (i.split("=", 1) for i in items)}


def _arguments() -> argparse.Namespace:
    p = argparse.ArgumentParser()
    p.add_argument("--bag", required=True)
    p.add_argument("--period", type=float, default=1.0, help="the line's tick period (s)")
    p.add_argument("--speed-at", action="append", default=[])
    p.add_argument("--stamp-shift-at", action="append", default=[])
    p.add_argument("--skip", action="append", type=int, default=[])
    p.add_argument("--skip-all", action="store_true")
    p.add_argument("--skip-once", action="append", type=int, default=[])
    p.add_argument("--exit-at", action="append", default=[])
    p.add_argument("--batch", action="store_true", help=f"answer on {BATCH_CMD} (entry 0) instead")
    return p.parse_args(remove_ros_args(sys.argv)[1:])


def _recorded_commands(bag: str) -> dict[int, dict[str, dict]]:
    """stamp -> topic -> the bag's first command of that kind for the tick."""
    commands: dict[int, dict[str, dict]] = {}
    for rel, msgs in open_bag(bag).by_relative_topic().items():
        if rel in (SPEED_CMD, SORT_MODE_CMD):
            for m in msgs:
                commands.setdefault(stamp_ns(m.plain), {}).setdefault(rel, m.plain)
    return commands


def main() -> int:
    args = _arguments()
    speeds, shifts, exits = _pairs(args.speed_at, float), _pairs(args.stamp_shift_at, float), _pairs(args.exit_at, int)
    commands = _recorded_commands(args.bag)
    period_ns = round(args.period * 1e9)

    rclpy.init(args=sys.argv)
    node = rclpy.create_node("scripted_controller")
    speed_pub = node.create_publisher(SpeedCommand, SPEED_CMD, QOS)
    mode_pub = node.create_publisher(SortModeCommand, SORT_MODE_CMD, QOS)
    batch_pub = node.create_publisher(LineCommands, BATCH_CMD, QOS) if args.batch else None
    exit_code: list[int] = []

    def on_input(msg: MaterialInput) -> None:
        stamp = msg.header.stamp
        key = stamp.sec * 1_000_000_000 + stamp.nanosec
        tick = key // period_ns
        if tick in exits:
            print(
                f"scripted_controller: exiting with {exits[tick]} at tick {tick}, as told", file=sys.stderr, flush=True
            )
            exit_code.append(exits[tick])
            return
        recorded = commands.get(key, {})
        if tick in args.skip_once:
            args.skip_once.remove(tick)
            return
        if args.skip_all or tick in args.skip or SPEED_CMD not in recorded:
            return
        if tick in shifts:
            moved = key + round(shifts[tick] * 1e9)
            stamp.sec, stamp.nanosec = moved // 1_000_000_000, moved % 1_000_000_000
        mode = recorded[SORT_MODE_CMD]["mode"] if SORT_MODE_CMD in recorded else None
        speed = float(speeds.get(tick, recorded[SPEED_CMD]["speed"]))
        if batch_pub is not None:
            batch_pub.publish(
                LineCommands(
                    stamp_sec=[stamp.sec],
                    stamp_nanosec=[stamp.nanosec],
                    speeds=[speed],
                    modes=[] if mode is None else [mode],
                )
            )
            return
        if mode is not None:
            mode_pub.publish(SortModeCommand(header=Header(stamp=stamp), mode=mode))
        speed_pub.publish(SpeedCommand(header=Header(stamp=stamp), speed=speed))

    node.create_subscription(MaterialInput, INPUT, on_input, QOS)
    try:
        while rclpy.ok() and not exit_code:
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return exit_code[0] if exit_code else 0


if __name__ == "__main__":
    sys.exit(main())
