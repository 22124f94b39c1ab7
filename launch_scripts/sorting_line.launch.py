"""Launch the sorting line node with `ros2 launch` (ROS 2 Jazzy's launch and launch_ros).

Installed by colcon (docs/ros-package.md) as share/sorting_line/sorting_line.launch.py:

    ros2 launch sorting_line sorting_line.launch.py namespace:=/plant lines:=4 \
        params_file:=my_line.yaml variant:=advanced

or from a clone, by path: `ros2 launch launch_scripts/sorting_line.launch.py ...`.

The node binary is the `sorting_line_bin` argument if given; else, installed, the package's
executable (lib/sorting_line/sorting_line, found through the ament index as `ros2 run` finds it),
and in a clone, the clone's release build (target/release/sorting_line). Parameters given here
override the params file, as on the command line; the params file may be flat or in the
`/**: ros__parameters:` form (share/sorting_line/sorting_line.yaml lists them all with their defaults).

A controller beside the node, in the same namespace (one per line with `lines:=N`, in
`<namespace>/line_<k>`): `policy:=POLICY.onnx` (a learned policy, `sorting-line-export`; or an SB3
MODEL.zip) or `agent:=rba|rba-hold` (the rule-based agent, for the line's `setup` and `variant`),
run by `sorting-line-controller` (the `controller_bin` argument; default: in a clone, the clone's
.venv/bin/sorting-line-controller; else the one on PATH). docs/deploying-a-policy.md:

    ros2 launch sorting_line sorting_line.launch.py setup:=B variant:=advanced mode:=realtime policy:=policy.onnx
"""

import os
import shutil

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch_ros.actions import Node

PACKAGE = "sorting_line"
# A clone has this file in launch_scripts/ beside Cargo.toml; an install has it in share/sorting_line/.
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IN_CLONE = os.path.isfile(os.path.join(REPO, "Cargo.toml"))
DEFAULT_BIN = os.path.join(REPO, "target", "release", PACKAGE) if IN_CLONE else ""
# The controller is a console script of the bridge (sorting_line_gym): the clone's .venv, else PATH.
CLONE_CONTROLLER = os.path.join(REPO, ".venv", "bin", "sorting-line-controller")

# Launch arguments that become node parameters when given (empty = the node's default).
PARAMETERS = [
    ("setup", "the paper's setup A..D (input, obs_noise, action_penalty; those given override it)"),
    ("variant", "basic or advanced"),
    ("input", "random, seasonal or seasonal3"),
    ("obs_noise", "relative input-sensor noise, 0.0..1.0"),
    ("action_penalty", "reward subtracted per belt-speed change, 0.0..10.0"),
    ("threshold", "accuracy threshold of the reward, 0.0..<1.0"),
    ("max_steps", "episode length in ticks"),
    ("seed", "seed of line 0 (line k uses seed + k)"),
    ("mode", "lockstep or realtime"),
    ("rate", "realtime ticks per second"),
    ("lines", "number of lines hosted by the node"),
    ("tick_period", "simulated seconds per tick"),
    ("evolution_file", "an evolution schedule (YAML) the lines follow; see docs/evolving.md"),
    ("foxglove", "[ADDR:]PORT of the Foxglove live view (off when empty); see docs/foxglove.md"),
]


def _typed(text):
    """Launch arguments are strings; give the node ints and floats where they look like them."""
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def _node(context):
    def value(name):
        return context.launch_configurations.get(name, "")

    parameters = []
    if value("params_file"):
        parameters.append(value("params_file"))
    overrides = {name: _typed(value(name)) for name, _ in PARAMETERS if value(name)}
    if overrides:
        parameters.append(overrides)
    binary = value("sorting_line_bin")
    # Installed: the package's executable, which launch_ros looks up in the ament index.
    where = {"executable": binary} if binary else {"package": PACKAGE, "executable": PACKAGE}
    return [
        Node(
            **where,
            name=value("node_name"),
            namespace=value("namespace"),
            # launch_ros appends --ros-args -r __node:= -r __ns:= --params-file ...; the binary
            # needs its subcommand first.
            arguments=["node"],
            parameters=parameters,
            output="screen",
            emulate_tty=True,
        )
    ]


def _controllers(context):
    """`sorting-line-controller` for each line, when `policy` or `agent` is given."""
    value = context.launch_configurations.get
    policy, agent = value("policy", ""), value("agent", "")
    if not policy and not agent:
        return []
    if policy and agent:
        raise RuntimeError("policy:= and agent:= are two controllers for one line: give one of them")
    if agent and agent not in ("rba", "rba-hold"):
        raise RuntimeError(f"agent:={agent} is not valid: allowed rba, rba-hold")
    binary = value("controller_bin", "") or (
        CLONE_CONTROLLER if IN_CLONE and os.path.isfile(CLONE_CONTROLLER) else shutil.which("sorting-line-controller")
    )
    if not binary:
        raise RuntimeError(
            "sorting-line-controller not found (controller_bin:= empty, no .venv in the clone, not on PATH): "
            "install the bridge (bash launch_scripts/setup.sh, or pip install ./bridge) or give controller_bin:=PATH"
        )
    flags = ["--policy", os.path.abspath(policy)] if policy else ["--agent", agent]
    for name in ("setup", "variant"):
        if value(name, ""):
            flags += [f"--{name}", value(name)]
    namespace = "/" + value("namespace", "/").strip("/")
    lines = int(value("lines", "") or 1)
    spaces = [namespace] if lines == 1 else [f"{namespace.rstrip('/')}/line_{k}" for k in range(lines)]
    return [
        ExecuteProcess(
            cmd=[
                binary,
                *flags,
                "--node-name",
                f"sorting_line_controller_{k}" if lines > 1 else "sorting_line_controller",
                "--ros-args",
                "-r",
                f"__ns:={ns}",
            ],
            name=f"controller_{k}",
            output="screen",
            emulate_tty=True,
        )
        for k, ns in enumerate(spaces)
    ]


def generate_launch_description():
    arguments = [
        DeclareLaunchArgument("namespace", default_value="/", description="namespace of the node"),
        DeclareLaunchArgument("node_name", default_value="sorting_line"),
        DeclareLaunchArgument("params_file", default_value="", description="YAML parameter file"),
        DeclareLaunchArgument(
            "sorting_line_bin",
            default_value=DEFAULT_BIN,
            description="node binary (empty: the installed package's executable)",
        ),
        DeclareLaunchArgument("policy", default_value="", description="a learned policy (ONNX or SB3 zip) to run"),
        DeclareLaunchArgument("agent", default_value="", description="a rule-based controller: rba or rba-hold"),
        DeclareLaunchArgument(
            "controller_bin",
            default_value="",
            description="sorting-line-controller (empty: the clone's .venv, else PATH)",
        ),
    ]
    arguments += [DeclareLaunchArgument(name, default_value="", description=text) for name, text in PARAMETERS]
    return LaunchDescription(arguments + [OpaqueFunction(function=_node), OpaqueFunction(function=_controllers)])
